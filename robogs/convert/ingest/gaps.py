"""``--split-at-gaps``: cut a converted episode into several where every stream pauses.

Runs once, for every converter, in :func:`robogs.convert.ingest.convert.convert_path` after the
converter has read its source and before the dataset is committed: the episode's tables are
in the writer's temp folder, each is sliced by ``t_ns`` into ``<episode>_000``, ``_001``, ...
A camera's frames are re-encoded into one video per piece (``frame_index`` restarts at 0, as
``T009`` asks), its labels follow their frames.

A *pause* is an interval longer than the gap in which no stream of the episode has a sample:
the gaps of the sorted union of all stamps. The cut lies at the middle of the pause. The
default gap is 10x the median sample period of the densest stream (the one with the shortest
median period), so a short dropout of one sensor never cuts, and a hand reset between pushes
(seconds with nothing recorded) does.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from robogs.format.errors import InputError, output_error
from robogs.format.images import VideoWriter, iter_video_frames
from robogs.format.writer import DatasetWriter

__all__ = ["GAP_FACTOR", "Cut", "SplitPlan", "plan_split", "split_episodes"]

#: default gap = GAP_FACTOR x the median period of the densest stream
GAP_FACTOR = 10.0
#: stream fields that name a stamped table (sliced by ``t_ns``)
_STAMPED = ("path", "frames", "extrinsics")


@dataclass(frozen=True)
class Cut:
    """One pause where every stream is silent: last sample before, first after, the cut (ns)."""

    before_ns: int
    after_ns: int
    cut_ns: int

    @property
    def pause_s(self) -> float:
        """Length of the pause (s)."""
        return (self.after_ns - self.before_ns) * 1e-9


@dataclass(frozen=True)
class SplitPlan:
    """Where an episode is cut.

    Attributes:
        gap_ns: the pause length that cuts (ns).
        derived: True when ``gap_ns`` came from the data (no SECONDS given).
        densest: the stream whose median period set the derived gap ('' when given).
        median_period_ns: that stream's median period (ns; 0 when given).
        cuts: the pauses, in time order.
    """

    gap_ns: int
    derived: bool
    densest: str
    median_period_ns: int
    cuts: tuple[Cut, ...]


def plan_split(stamps: dict[str, np.ndarray], gap_s: float | None) -> SplitPlan:
    """The cuts of one episode from its streams' stamps.

    Args:
        stamps: stream name -> int64 stamps (ns), any order.
        gap_s: the pause (s) that cuts; None: :data:`GAP_FACTOR` x the median period of the
            densest stream.

    Raises:
        InputError: no gap given and no stream has two distinct stamps.
    """
    densest, period = "", 0
    if gap_s is None:
        for name, t in sorted(stamps.items()):
            d = np.diff(np.unique(t))
            if d.size and (not period or int(np.median(d)) < period):
                densest, period = name, int(np.median(d))
        if not period:
            raise InputError(
                "--split-at-gaps cannot derive a gap: no stream has two distinct stamps",
                where="--split-at-gaps",
                hint="pass the gap in seconds: --split-at-gaps 2.0",
            )
        gap_ns = int(GAP_FACTOR * period)
    else:
        gap_ns = int(round(gap_s * 1e9))
    every = np.unique(np.concatenate([np.asarray(t, np.int64) for t in stamps.values()]))
    k = np.flatnonzero(np.diff(every) > gap_ns)
    cuts = tuple(
        Cut(
            int(every[i]),
            int(every[i + 1]),
            int(every[i]) + (int(every[i + 1]) - int(every[i])) // 2,
        )
        for i in k
    )
    return SplitPlan(gap_ns, gap_s is None, densest, period, cuts)


def _read(writer: DatasetWriter, rel: str, columns: list[str] | None = None) -> pa.Table:
    return pq.read_table(writer.tmp / rel, columns=columns)


def _write(writer: DatasetWriter, rel: str, table: pa.Table) -> None:
    """Write ``table`` at ``rel`` in the temp folder (atomic rename, the original schema).

    Raises:
        OutputError: the disk refused it (full, read-only, ...).
    """
    final = writer.path(rel)
    part = final.with_name(final.name + ".part")
    try:
        pq.write_table(table, part, compression="zstd", row_group_size=1 << 16)
        os.replace(part, final)
    except OSError as exc:
        raise output_error(exc, path=writer.target, action="cutting at gaps") from None


def _stream_stamps(writer: DatasetWriter, streams: dict[str, Any]) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for name, st in streams.items():
        for key in _STAMPED:
            rel = st.get(key)
            path = writer.tmp / rel if isinstance(rel, str) else None
            if path is not None and path.is_file() and "t_ns" in pq.read_schema(path).names:
                t = _read(writer, rel, ["t_ns"]).column("t_ns").to_numpy().astype(np.int64)
                out[f"{name}:{key}" if key != "path" else name] = t
    return out


def _windows(cuts: tuple[Cut, ...]) -> Iterator[tuple[int, int]]:
    """[lo, hi) stamp windows between the cuts (the first and last open-ended)."""
    i64 = np.iinfo(np.int64)
    edges = [int(i64.min), *(c.cut_ns for c in cuts), int(i64.max)]
    yield from zip(edges[:-1], edges[1:], strict=True)


def _slice(
    table: pa.Table, lo: int, hi: int, kept: dict[str, list[np.ndarray]], k: int
) -> pa.Table | None:
    """Rows of piece ``k`` (``lo <= t_ns < hi``; an unstamped table whole); a table of
    ``camera, frame_index`` rows (2-D boxes) gets the piece's new frame indexes. None: empty."""
    if "t_ns" not in table.column_names:
        return table
    t = table.column("t_ns")
    piece = table.filter(pc.and_(pc.greater_equal(t, lo), pc.less(t, hi)))
    if not piece.num_rows:
        return None
    if {"camera", "frame_index"} <= set(piece.column_names):
        cams = piece.column("camera").to_pylist()
        old = piece.column("frame_index").to_numpy()
        new = np.full(old.size, -1, np.int64)
        for cam in set(cams):
            rows = np.array([c == cam for c in cams])
            idx = kept[cam][k] if cam in kept else np.empty(0, np.int64)
            if not idx.size:
                continue  # that camera has no frame in this piece: its boxes go
            pos = np.searchsorted(idx, old[rows])
            hit = (pos < idx.size) & (idx[np.minimum(pos, idx.size - 1)] == old[rows])
            new[np.flatnonzero(rows)[hit]] = pos[hit]
        piece = piece.filter(pa.array(new >= 0))
        j = piece.schema.get_field_index("frame_index")
        piece = piece.set_column(j, piece.schema.field(j), pa.array(new[new >= 0]))
    return piece


def _moved(rel: str, base: str, new: str) -> str:
    """Where piece ``new`` keeps its slice of ``rel``: in its own episode folder (a file
    outside ``episodes/<base>/`` is never overwritten, its slices go under the piece)."""
    return f"episodes/{new}/{rel.removeprefix(f'episodes/{base}/')}"


def _split_camera(
    writer: DatasetWriter,
    st: dict[str, Any],
    base: str,
    windows: list[tuple[int, int]],
    ids: list[str],
) -> tuple[list[dict[str, Any] | None], list[np.ndarray]]:
    """Slice a camera stream: frames, video (re-encoded per piece), labels, extrinsics.

    Returns:
        Per piece: its stream entry (None when no frame falls in it), and the source frame
        indexes it kept (in order; the new index of a frame is its position there).
    """
    frames = _read(writer, st["frames"])
    t = frames.column("t_ns").to_numpy()
    fi = frames.column("frame_index").to_numpy()
    video = st.get("video")
    labels = _read(writer, st["labels"]) if isinstance(st.get("labels"), str) else None
    out: list[dict[str, Any]] = []
    pieces: list[tuple[dict[str, Any], np.ndarray]] = []
    for (lo, hi), eid in zip(windows, ids, strict=True):
        sel = (t >= lo) & (t < hi)
        entry = {
            k: (
                _moved(v, base, eid)
                if k in ("frames", "video", "labels", "extrinsics") and isinstance(v, str)
                else v
            )
            for k, v in st.items()
        }
        idx = fi[sel]
        pieces.append((entry, idx))
        if not idx.size:  # the camera saw nothing in this piece: no stream there
            out.append(None)
            continue
        renumber = pa.array(np.arange(idx.size, dtype=np.int64))
        piece = frames.filter(pa.array(sel)).set_column(
            frames.schema.get_field_index("frame_index"),
            frames.schema.field("frame_index"),
            renumber,
        )
        _write(writer, entry["frames"], piece)
        if labels is not None:
            li = labels.column("frame_index").to_numpy()
            keep = np.isin(li, idx)
            lab = labels.filter(pa.array(keep))
            new_index = np.searchsorted(idx, li[keep]).astype(np.int64)
            lab = lab.set_column(
                lab.schema.get_field_index("frame_index"),
                lab.schema.field("frame_index"),
                pa.array(new_index),
            )
            _write(writer, entry["labels"], lab)
        if isinstance(st.get("extrinsics"), str):
            ext = _read(writer, st["extrinsics"])
            et = ext.column("t_ns")
            _write(
                writer,
                entry["extrinsics"],
                ext.filter(pc.and_(pc.greater_equal(et, lo), pc.less(et, hi))),
            )
        out.append(entry)
    if isinstance(video, str) and (writer.tmp / video).is_file():
        _split_video(writer, writer.tmp / video, fi, pieces, st.get("nominal_rate_hz") or 30.0)
    return out, [idx for _, idx in pieces]


def _split_video(
    writer: DatasetWriter,
    src: Path,
    frame_index: np.ndarray,
    pieces: list[tuple[dict[str, Any], np.ndarray]],
    fps: float,
) -> None:
    """Re-encode the frames of each piece into its own video (frames in file order)."""
    owner = np.full(int(frame_index.max(initial=-1)) + 1, -1, dtype=np.int64)
    for k, (_, idx) in enumerate(pieces):
        owner[idx] = k
    writers: dict[int, VideoWriter] = {}
    try:
        for i, rgb in enumerate(iter_video_frames(src)):
            k = int(owner[i]) if i < owner.size else -1
            if k < 0:
                continue
            if k not in writers:
                h, w = rgb.shape[:2]
                writers[k] = VideoWriter(writer.path(pieces[k][0]["video"]), w, h, fps)
            writers[k].write(rgb)
    finally:
        for vw in writers.values():
            vw.close()


def split_episodes(writer: DatasetWriter, gap_s: float | None) -> list[dict[str, Any]]:
    """Cut every episode of ``writer`` at the pauses of all its streams.

    Args:
        writer: the dataset being written (its episodes declared, not committed).
        gap_s: the pause (s) that cuts; None derives it per episode (:func:`plan_split`).

    Returns:
        One record per source episode: ``episode``, ``gap_s``, ``derived``, ``densest``,
        ``median_period_s``, ``cuts`` (``before_ns``, ``after_ns``, ``cut_ns``, ``pause_s``)
        and ``episodes`` (``id``, ``start_ns``, ``end_ns``) - the cut table.
    """
    records: list[dict[str, Any]] = []
    for ep in list(writer.manifest.get("episodes", [])):
        base, streams = ep["id"], ep["streams"]
        stamps = _stream_stamps(writer, streams)
        if not stamps:
            continue
        plan = plan_split(stamps, gap_s)
        rec: dict[str, Any] = {
            "episode": base,
            "gap_s": plan.gap_ns * 1e-9,
            "derived": plan.derived,
            "densest": plan.densest,
            "median_period_s": plan.median_period_ns * 1e-9,
            "cuts": [
                {
                    "before_ns": c.before_ns,
                    "after_ns": c.after_ns,
                    "cut_ns": c.cut_ns,
                    "pause_s": c.pause_s,
                }
                for c in plan.cuts
            ],
            "episodes": [],
        }
        records.append(rec)
        if not plan.cuts:
            rec["episodes"].append({"id": base, "start_ns": ep["start_ns"], "end_ns": ep["end_ns"]})
            continue
        windows = list(_windows(plan.cuts))
        ids = [f"{base}_{k:03d}" for k in range(len(windows))]
        taken = {e["id"] for e in writer.manifest.get("episodes", [])} - {base}
        clash = sorted(set(ids) & taken)
        if clash:
            raise InputError(
                f"--split-at-gaps would write episode {clash[0]}, which exists",
                where="--split-at-gaps",
                hint="choose another --episode",
            )
        new_streams: list[dict[str, Any]] = [{} for _ in ids]
        kept: dict[str, list[np.ndarray]] = {}  # camera -> source frame indexes per piece
        for name, st in streams.items():
            if st.get("kind") == "camera" and isinstance(st.get("frames"), str):
                entries, kept[str(st.get("camera", name))] = _split_camera(
                    writer, st, base, windows, ids
                )
                for k, entry in enumerate(entries):
                    if entry is not None:
                        new_streams[k][name] = entry
        for name, st in streams.items():
            if st.get("kind") == "camera" and isinstance(st.get("frames"), str):
                continue
            rel = st.get("path")
            table = _read(writer, rel) if isinstance(rel, str) else None
            for k, ((lo, hi), eid) in enumerate(zip(windows, ids, strict=True)):
                entry = dict(st)
                if table is not None:
                    piece = _slice(table, lo, hi, kept, k)
                    if piece is None:
                        continue
                    entry["path"] = _moved(rel, base, eid)
                    _write(writer, entry["path"], piece)
                new_streams[k][name] = entry
        _copy_unreferenced(writer, base, ids, streams)
        writer.remove(f"episodes/{base}")
        writer.manifest["episodes"] = [e for e in writer.manifest["episodes"] if e["id"] != base]
        every = np.unique(np.concatenate(list(stamps.values())))
        for (lo, hi), eid, ss in zip(windows, ids, new_streams, strict=True):
            inside = every[(every >= lo) & (every < hi)]
            start, end = (int(inside[0]), int(inside[-1])) if inside.size else (lo, lo)
            writer.add_episode(eid, start_ns=start, end_ns=end, streams=ss, segment=eid)
            rec["episodes"].append({"id": eid, "start_ns": start, "end_ns": end})
    return records


def _copy_unreferenced(
    writer: DatasetWriter, base: str, ids: list[str], streams: dict[str, Any]
) -> None:
    """Files of the episode folder that no stream names go to every piece unchanged."""
    folder = writer.tmp / "episodes" / base
    named = {v for st in streams.values() for v in st.values() if isinstance(v, str)}
    for p in sorted(folder.rglob("*")) if folder.is_dir() else []:
        rel = p.relative_to(writer.tmp).as_posix()
        if p.is_file() and rel not in named:
            for eid in ids:
                writer.copy_file(_moved(rel, base, eid), p)
