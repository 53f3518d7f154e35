"""LeRobot v3.0 dataset folder -> robogs dataset (``robogs convert LEROBOT_DIR OUT``).

Reads the layout that :mod:`robogs.convert.export.lerobot` writes (lerobot 0.4.4,
``CODEBASE_VERSION = "v3.0"``): ``meta/info.json``, ``meta/episodes/*/*.parquet``,
``data/*/*.parquet`` and one MP4 per camera, with pyarrow and OpenCV. Every LeRobot episode
becomes a robogs episode (id: the ``robogs/episode_id`` column of ``meta/episodes`` when the
export was ours, else ``ep<index:03d>``; segment: its first task).

Per episode:

* ``observation.state`` / ``action`` with joint names become ``joint_states`` (``position.<name>``)
  and ``actions`` (``command.<name>``, position commands); with the names ``x y z qw qx qy qz``
  they are end-effector poses (``ee_poses`` of ``robogs.ee_link``, or ``ee``; an EE action has no
  robogs table and is noted, not converted). Actions that our exporter *derived* (next state) are
  not written back.
* Stamps (int64 ns, dataset clock): ``observation.stamp_ns`` where present (the export's regular
  grid, ``stamp_source: derived`` as it was resampled); otherwise ``round(timestamp * 1e9)``
  (also ``derived``; the episode starts at 0 ns; ``timestamp`` is float32, so these stamps are
  good to about 1e-7 of the time since the episode start).
* Each ``video`` feature ``observation.images.<cam>`` becomes camera ``<cam>``: the episode's
  frames are decoded at ``from_timestamp + timestamp`` (frame ``round(· * fps)`` of the
  constant-rate file). Where ``observation.images.<cam>.stamp_ns`` holds the recorded stamp of
  each picked frame, that stamp is used (``stamp_source: sidecar``) and a frame picked twice by
  the exporter's nearest-frame resampling is written once; else the row's stamp.
* Intrinsics and ``T_world_cam`` come from ``info.json`` ``robogs.cameras`` when present
  (otherwise the camera has no model and a note says so); ``.panoptic`` image features become
  label images, ``.depth`` features a ``depth/<cam>`` stream (16-bit PNG, mm).
* Episodes marked ``rendered`` (``robogs/source``) are listed in ``provenance.rendered``.

The robot (URDF) is not part of a LeRobot dataset: pass ``--urdf``.
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from robogs.format.cameras import CameraModel
from robogs.format.errors import FormatError, InputError

from ..registry import register_converter
from .context import IngestContext
from .roles import safe_name
from .sinks import median_rate_hz

__all__ = ["detect_lerobot", "convert_lerobot", "EE_NAMES"]

#: names of an end-effector pose feature (m, world frame; quaternion w, x, y, z)
EE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz")
_IMAGE_PREFIX = "observation.images."


def _info(src: Path) -> dict[str, Any] | None:
    p = src / "meta" / "info.json"
    if not p.is_file():
        return None
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def detect_lerobot(path: Path) -> bool:
    """A folder with ``meta/info.json`` of ``codebase_version`` v3.x."""
    if not path.is_dir():
        return False
    info = _info(path)
    return bool(info) and str(info.get("codebase_version", "")).startswith("v3")


def _names(feature: dict[str, Any]) -> list[str]:
    """Feature names as a flat list (LeRobot also writes ``{"motors": [...]}``)."""
    names = feature.get("names")
    if isinstance(names, dict):
        names = [n for v in names.values() for n in (v if isinstance(v, list) else [v])]
    if not isinstance(names, list):
        size = int(np.prod(feature.get("shape") or [0]))
        names = [f"dim{i}" for i in range(size)]
    return [safe_name(str(n)) for n in names]


def _read_parquets(src: Path, pattern: str, what: str) -> pa.Table:
    files = sorted(src.glob(pattern))
    if not files:
        raise InputError(f"no {what} files ({pattern})", path=src, hint="a LeRobot v3 folder")
    try:
        return pa.concat_tables([pq.read_table(f) for f in files], promote_options="default")
    except (pa.ArrowException, OSError) as exc:
        raise InputError(f"unreadable {what} ({str(exc)[:200]})", path=src) from None


def _vectors(tab: pa.Table, col: str, dim: int, path: Path) -> np.ndarray:
    """A fixed-size list (or list) column as [N, dim] float64."""
    arr = tab.column(col).combine_chunks()
    flat = pc.list_flatten(arr).to_numpy(zero_copy_only=False).astype(np.float64)
    if flat.size != len(tab) * dim:
        raise FormatError(f"{col} rows are not {dim} values long", path=path, where=col)
    return flat.reshape(len(tab), dim)


def _camera_model(name: str, meta: dict[str, Any] | None) -> CameraModel | None:
    if not meta or meta.get("fx") is None:
        return None
    T = meta.get("T_world_cam")
    return CameraModel.from_dict(
        {
            "name": name,
            "width": int(meta["width"]),
            "height": int(meta["height"]),
            "fx": float(meta["fx"]),
            "fy": float(meta["fy"]),
            "cx": float(meta["cx"]),
            "cy": float(meta["cy"]),
            "distortion_model": meta.get("distortion_model") or "none",
            "distortion": list(meta.get("distortion") or []),
            **({"T_world_cam": T} if T is not None else {}),
        }
    )


def _copy_frames(video: Path, wanted: np.ndarray, out: Path, fps: int) -> None:
    """Decode ``video`` once and write its frames at file positions ``wanted`` (increasing) to
    the MP4 ``out``, one at a time (memory: one frame)."""
    from robogs.format.images import VideoWriter, iter_video_frames

    k, writer = 0, None
    try:
        for i, img in enumerate(iter_video_frames(video)):
            if k == len(wanted):
                break
            if i != int(wanted[k]):
                continue
            if writer is None:
                writer = VideoWriter(out, img.shape[1], img.shape[0], fps)
            writer.write(img)
            k += 1
    finally:
        if writer is not None:
            writer.close()
    if k < len(wanted):
        raise FormatError(
            f"video has no frame {int(wanted[k])} ({len(wanted) - k} frames missing)",
            path=video,
            hint="the episode's from_timestamp / length point past the end of the file",
        )


def _image_bytes(tab: pa.Table, col: str) -> list[bytes | None]:
    return [None if r is None else r.get("bytes") for r in tab.column(col).to_pylist()]


def convert_lerobot(src: Path, ctx: IngestContext) -> None:
    """Write every episode of the LeRobot v3 dataset ``src`` (see the module docstring).

    Raises:
        InputError: not a v3 folder, missing files.
        FormatError: inconsistent metadata (a column of the wrong width, a video too short).
    """
    info = _info(src)
    if info is None:
        raise InputError("no readable meta/info.json", path=src, hint="a LeRobot v3 folder")
    version = str(info.get("codebase_version", ""))
    if not version.startswith("v3"):
        raise InputError(
            f"LeRobot codebase_version {version!r} is not v3",
            path=src / "meta" / "info.json",
            hint="convert v2.x datasets with lerobot's own v3 converter first",
        )
    fps = int(info["fps"])
    feats: dict[str, Any] = info.get("features") or {}
    ours: dict[str, Any] = info.get("robogs") or {}
    video_path = str(info.get("video_path") or "")
    data_path = str(info.get("data_path") or "")
    if "observation.state" not in feats:
        raise InputError("no observation.state feature", path=src / "meta" / "info.json")
    state_names = _names(feats["observation.state"])
    ee = tuple(state_names) == EE_NAMES
    action_names = _names(feats["action"]) if "action" in feats else []
    cams = {
        k[len(_IMAGE_PREFIX) :] if k.startswith(_IMAGE_PREFIX) else k: k
        for k, f in feats.items()
        if f.get("dtype") == "video"
    }
    episodes = _read_parquets(src, "meta/episodes/*/*.parquet", "episode metadata")
    episodes = episodes.sort_by("episode_index").to_pylist()
    derived_action = set(ours.get("derived_action") or [])
    prov = ctx.provenance
    models: dict[str, CameraModel | None] = {}
    for cam in cams:
        name = safe_name(cam)
        models[cam] = _camera_model(name, (ours.get("cameras") or {}).get(cam))
        if models[cam] is not None:
            ctx.writer.set_camera(models[cam])  # type: ignore[arg-type]
        else:
            prov.note(f"camera {name}: no intrinsics in info.json (robogs.cameras); none written")
    rendered: dict[str, dict[str, Any]] = {}
    data_cache: dict[str, pa.Table] = {}
    ee_link = str(ours.get("ee_link") or "ee")
    for row in episodes:
        e_idx = int(row["episode_index"])
        ep_id = safe_name(str(row.get("robogs/episode_id") or f"ep{e_idx:03d}"))
        e = f"episodes/{ep_id}"
        rel = data_path.format(
            chunk_index=int(row.get("data/chunk_index") or 0),
            file_index=int(row.get("data/file_index") or 0),
        )
        if rel not in data_cache:
            if not (src / rel).is_file():
                raise InputError("data file missing", path=src / rel, where=f"episode {e_idx}")
            data_cache[rel] = pq.read_table(src / rel)
        tab = data_cache[rel]
        tab = tab.filter(pc.equal(tab.column("episode_index"), e_idx)).sort_by("frame_index")
        n = len(tab)
        if n == 0 or n != int(row.get("length", n)):
            raise FormatError(
                f"episode {e_idx} has {n} data rows, meta/episodes says {row.get('length')}",
                path=src / rel,
            )
        ts = tab.column("timestamp").to_numpy().astype(np.float64)
        if "observation.stamp_ns" in tab.column_names:
            t = tab.column("observation.stamp_ns").to_numpy().astype(np.int64)
            t_src = "observation.stamp_ns (the export's regular grid)"
        else:
            t = np.round(ts * 1e9).astype(np.int64)
            t_src = "timestamp column, s -> ns (episode starts at 0)"
        if np.any(np.diff(t) <= 0):
            i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
            raise FormatError(
                f"episode {e_idx}: stamps do not increase at frame_index {i}", path=src / rel
            )
        stamp = {"stamp_source": "derived", "offset_ns": 0, "nominal_rate_hz": float(fps)}
        streams: dict[str, dict[str, Any]] = {}
        state = _vectors(tab, "observation.state", len(state_names), src / rel)
        if ee:
            cols: dict[str, Any] = {"t_ns": t, "link": pa.array([ee_link] * n, pa.string())}
            cols.update({c: state[:, i] for i, c in enumerate(EE_NAMES)})
            ctx.writer.write_table(f"{e}/ee_poses.parquet", pa.table(cols), kind="ee_poses")
            streams["ee_poses"] = {
                "kind": "ee_poses",
                "path": f"{e}/ee_poses.parquet",
                "source": f"observation.state; stamps: {t_src}",
                **stamp,
            }
        else:
            cols = {"t_ns": t} | {f"position.{nm}": state[:, i] for i, nm in enumerate(state_names)}
            ctx.writer.write_table(f"{e}/joint_states.parquet", pa.table(cols), kind="joint_states")
            streams["joint_states"] = {
                "kind": "joint_states",
                "path": f"{e}/joint_states.parquet",
                "source": f"observation.state; stamps: {t_src}",
                **stamp,
            }
        if action_names and ep_id not in derived_action:
            if tuple(action_names) == EE_NAMES:
                prov.note("action is an end-effector pose: robogs has no EE command table; skipped")
            else:
                act = _vectors(tab, "action", len(action_names), src / rel)
                cols = {"t_ns": t} | {
                    f"command.{nm}": act[:, i] for i, nm in enumerate(action_names)
                }
                ctx.writer.write_table(f"{e}/actions.parquet", pa.table(cols), kind="actions")
                streams["actions"] = {
                    "kind": "actions",
                    "path": f"{e}/actions.parquet",
                    "command_kind": "position",
                    "source": f"action; stamps: {t_src}",
                    **stamp,
                }
        start, end = int(t[0]), int(t[-1])
        for cam, key in cams.items():
            name = safe_name(cam)
            vrel = video_path.format(
                video_key=key,
                chunk_index=int(row.get(f"videos/{key}/chunk_index") or 0),
                file_index=int(row.get(f"videos/{key}/file_index") or 0),
            )
            t0 = float(row.get(f"videos/{key}/from_timestamp") or 0.0)
            pos = np.round((t0 + ts) * fps).astype(np.int64)
            if f"{key}.stamp_ns" in tab.column_names:
                t_cam = tab.column(f"{key}.stamp_ns").to_numpy().astype(np.int64)
                cam_src = f"{key}.stamp_ns (recorded stamp of each picked frame)"
                stamp_source = "sidecar"
            else:
                t_cam, cam_src, stamp_source = t, t_src, "derived"
            # keep a frame only when its stamp is after the last kept one: nearest-frame
            # resampling repeats a recorded frame where the grid is denser than the camera
            keep = np.ones(n, bool)
            last = None
            for k in range(n):
                if last is not None and t_cam[k] <= last:
                    keep[k] = False
                else:
                    last = t_cam[k]
            if not keep.all():
                prov.note(
                    f"camera {name}: {int((~keep).sum())} repeated frames (the same recorded "
                    "frame picked twice by the resampling) written once"
                )
            cdir = f"{e}/cameras/{name}"
            _copy_frames(src / vrel, pos[keep], ctx.writer.path(f"{cdir}/rgb.mp4"), fps)
            tk = t_cam[keep]
            idx = np.arange(len(tk), dtype=np.int64)
            ctx.writer.write_table(
                f"{cdir}/frames.parquet",
                pa.table({"t_ns": tk, "frame_index": idx}),
                kind="camera_frames",
            )
            entry: dict[str, Any] = {
                "kind": "camera",
                "camera": name,
                "frames": f"{cdir}/frames.parquet",
                "video": f"{cdir}/rgb.mp4",
                "stamp_source": stamp_source,
                "offset_ns": 0,
                "nominal_rate_hz": median_rate_hz(tk),
                "source": f"{vrel}; stamps: {cam_src}",
            }
            if f"{key}.panoptic" in tab.column_names:
                pngs = [
                    b for b, k in zip(_image_bytes(tab, f"{key}.panoptic"), keep, strict=True) if k
                ]
                if all(b is not None for b in pngs):
                    ctx.writer.write_table(
                        f"{cdir}/labels.parquet",
                        pa.table({"frame_index": idx, "png": pa.array(pngs, pa.binary())}),
                        kind="camera_labels",
                    )
                    entry["labels"] = f"{cdir}/labels.parquet"
            if f"{key}.depth" in tab.column_names:
                dep = [b for b, k in zip(_image_bytes(tab, f"{key}.depth"), keep, strict=True) if k]
                if all(b is not None for b in dep):
                    ctx.writer.write_table(
                        f"{cdir}/depth.parquet",
                        pa.table(
                            {"t_ns": tk, "frame_index": idx, "png": pa.array(dep, pa.binary())}
                        ),
                        kind="generic",
                    )
                    streams[f"depth/{name}"] = {
                        "kind": "generic",
                        "path": f"{cdir}/depth.parquet",
                        "stamp_source": stamp_source,
                        "offset_ns": 0,
                        "nominal_rate_hz": median_rate_hz(tk),
                        "source": f"{key}.depth, mm, 16-bit PNG (0: nothing)",
                    }
            streams[f"camera/{name}"] = entry
            start, end = min(start, int(tk[0])), max(end, int(tk[-1]))
            rec = prov.topic(key, "LeRobot video", "camera_image")
            rec.messages += n
            rec.written += int(keep.sum())
        tasks = row.get("tasks") or []
        ctx.writer.add_episode(
            ep_id,
            start_ns=start,
            end_ns=end,
            streams=streams,
            segment=str(tasks[0]) if tasks else None,
        )
        if row.get("robogs/source") == "rendered":
            rendered[ep_id] = {"lerobot_episode_index": e_idx}
    if rendered:
        prov.extra["rendered"] = {"source": src.name, "episodes": rendered}
    grid = ours.get("resampling")
    if grid:
        prov.note(
            f"the LeRobot export resampled every stream to {fps} fps ({grid.get('joints')} "
            "joints, nearest recorded images): joint stamps are the grid, camera stamps the "
            "recorded ones"
        )
    counts = defaultdict(int)
    for row in episodes:
        counts["frames"] += int(row.get("length") or 0)
    prov.note(f"{len(episodes)} episodes, {counts['frames']} frames at {fps} fps")


register_converter(
    "lerobot",
    detect_lerobot,
    convert_lerobot,
    description="LeRobot dataset v3.0 folder (meta/info.json, parquet, MP4 per camera)",
    priority=20,
)
