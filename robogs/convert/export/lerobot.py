"""``robogs export lerobot DATASET OUT``: a LeRobot dataset, format v3.0, as a folder::

    OUT/meta/info.json                                   fps, features, path templates, totals
    OUT/meta/stats.json                                  min/max/mean/std/count/quantiles
    OUT/meta/tasks.parquet                               task string (pandas index) -> task_index
    OUT/meta/episodes/chunk-000/file-000.parquet         one row per episode (lengths, offsets)
    OUT/data/chunk-000/file-000.parquet                  one row per frame, every episode
    OUT/videos/observation.images.<cam>/chunk-000/file-000.mp4   every episode, one after another

Layout pinned from the ``lerobot`` package, version 0.4.4 (``CODEBASE_VERSION = "v3.0"``;
``lerobot/datasets/utils.py``: ``DEFAULT_DATA_PATH``, ``DEFAULT_VIDEO_PATH``,
``DEFAULT_EPISODES_PATH``, ``DEFAULT_TASKS_PATH``, ``DEFAULT_FEATURES``;
``lerobot_dataset.py``: ``LeRobotDatasetMetadata.save_episode``, ``_query_videos``). What a
reader relies on:

* ``info.json`` ``features``: ``{dtype, shape, names}`` per column; videos have dtype ``video``,
  shape ``[H, W, 3]``, names ``["height", "width", "channels"]`` and a ``video.*`` info dict.
* Every frame row holds ``timestamp`` (float32 s since the episode start), ``frame_index``,
  ``episode_index``, ``index`` (global row) and ``task_index`` (int64).
* A video frame is found by time: the reader decodes ``from_timestamp + timestamp`` of the
  episode's row in ``meta/episodes`` (tolerance 1e-4 s). The MP4s are constant-rate, so the
  ``timestamp`` of frame k must be ``k / fps``: **the format forces a fixed rate**.

Real stamps. robogs stamps are irregular (sensor jitter, drops), so this exporter resamples
every episode onto the regular grid ``t_k = t_start + k / fps`` (ns, dataset clock), which
makes ``timestamp = k / fps`` true rather than assumed:

* joint positions and commands are interpolated **linearly** at ``t_k``; EE poses (``--state
  ee``) linearly in position and by slerp in rotation;
* each camera contributes its **nearest** recorded frame (and panoptic label image) to ``t_k``;
  the stamp of that frame is kept in ``observation.images.<cam>.stamp_ns`` and the grid stamp
  in ``observation.stamp_ns`` (int64 ns, dataset clock), and the report says how far apart
  they are.

``t_start`` is the latest first frame of the episode's cameras, the grid ends at the earliest
last frame; ``fps`` is the first camera's nominal rate (rounded), or ``fps=``.

State and action: ``state="joints"`` (default) gives ``observation.state`` = the URDF's
actuated joint positions and ``action`` = the commanded positions (``actions`` stream, linear
interpolation; without it, the next grid sample of the state, and the report says so).
``state="ee"`` gives the end-effector pose ``[x, y, z, qw, qx, qy, qz]`` (m, world frame) of the
``ee_link``: the recorded ``ee_poses`` stream for the state (forward kinematics of the joint
states without it) and forward kinematics of the commands for the action.

Cameras: intrinsics and ``T_world_cam`` (OpenCV axes, world z up) go into ``info.json`` under
``robogs.cameras``. With ``labels=True`` the panoptic labels become image features
``observation.images.<cam>.panoptic`` (16-bit PNG of label ids, in the ``{bytes, path}`` struct of
Hugging Face images) and a rendered depth stream (``robogs render``) becomes
``observation.images.<cam>.depth`` (16-bit PNG, mm). Episodes that ``robogs render`` produced
are marked ``rendered`` in ``meta/episodes`` (column ``robogs/source``) and in ``info.json``.

Limits: one data file and one video file per camera (chunk 0, file 0) hold every episode; the
sizes LeRobot's writer would split at (100 MB / 200 MB) are not enforced. Videos are MPEG-4
part 2 (OpenCV's ``mp4v``), which LeRobot's PyAV and torchcodec decoders read.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from robogs.format import Dataset
from robogs.format.dataset import Episode
from robogs.format.errors import FormatError, InputError
from robogs.format.images import VideoWriter, encode_label_png
from robogs.format.interp import interp_linear, interp_pose
from robogs.format.tables import family_columns

from . import ExportReport, register_exporter

__all__ = [
    "export_lerobot",
    "CODEBASE_VERSION",
    "DATA_PATH",
    "VIDEO_PATH",
    "EPISODES_PATH",
    "TASKS_PATH",
    "resample_grid",
    "nearest_frames",
]

#: LeRobot dataset format written (lerobot 0.4.4, ``lerobot.datasets.lerobot_dataset``)
CODEBASE_VERSION = "v3.0"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
TASKS_PATH = "meta/tasks.parquet"
_CHUNKS_SIZE = 1000
_QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
_IMAGE_STAT_FRAMES = 32


def resample_grid(start_ns: int, end_ns: int, fps: int) -> np.ndarray:
    """Regular stamps ``start_ns + round(k * 1e9 / fps)`` (int64 ns) up to ``end_ns`` inclusive."""
    n = int(math.floor((end_ns - start_ns) * fps / 1e9 + 1e-9)) + 1
    k = np.arange(max(n, 0), dtype=np.int64)
    return start_ns + np.round(k * (1e9 / fps)).astype(np.int64)


def nearest_frames(grid_ns: np.ndarray, frame_ns: np.ndarray) -> np.ndarray:
    """Index into ``frame_ns`` (increasing) of the frame nearest each grid stamp (ties: earlier)."""
    i = np.searchsorted(frame_ns, grid_ns)
    i = np.clip(i, 1, len(frame_ns) - 1) if len(frame_ns) > 1 else np.zeros_like(i)
    if len(frame_ns) > 1:
        later = np.abs(frame_ns[i] - grid_ns) < np.abs(grid_ns - frame_ns[i - 1])
        i = np.where(later, i, i - 1)
    return i.astype(np.int64)


@dataclass
class _Stream:
    """One camera of one episode: recorded stamps and where its files are."""

    name: str
    key: str
    stamps: np.ndarray
    frame_index: np.ndarray
    width: int
    height: int


@dataclass
class _EpisodePlan:
    episode: Episode
    grid: np.ndarray
    cams: list[_Stream]
    task: str
    rendered: bool
    picks: dict[str, np.ndarray] = field(default_factory=dict)


def _camera_streams(ds: Dataset, ep: Episode) -> list[_Stream]:
    out = []
    for cam in sorted(ep.camera_streams):
        fr = ep.frames(cam)
        t = fr.column("t_ns").to_numpy().astype(np.int64)
        idx = fr.column("frame_index").to_numpy().astype(np.int64)
        if len(t) == 0:
            continue
        if np.any(np.diff(t) <= 0):
            raise FormatError(
                f"camera {cam!r} has non-increasing frame stamps",
                path=ds.manifest_path,
                where=f"episodes/{ep.id}/camera/{cam}",
                hint="run robogs-validate; the time checks name the frames",
            )
        model = ds.camera(cam)
        out.append(_Stream(cam, f"observation.images.{cam}", t, idx, model.width, model.height))
    return out


def _rendered_ids(ds: Dataset) -> set[str]:
    prov = ds.manifest.get("provenance") or {}
    rendered = prov.get("rendered") or {}
    return set(rendered.get("episodes", {}) if isinstance(rendered, dict) else [])


def _table_values(ep: Episode, stream: str, prefix: str, names: list[str]) -> tuple[Any, Any]:
    tab = ep.table(stream)
    have = family_columns(tab.column_names, prefix)
    missing = [n for n in names if n not in have]
    if missing:
        raise FormatError(
            f"{stream} lacks {', '.join(prefix + n for n in missing)}",
            path=ep.table_path(stream),
            hint="record every actuated joint of the URDF",
        )
    t = tab.column("t_ns").to_numpy().astype(np.int64)
    v = np.stack([tab.column(prefix + n).to_numpy().astype(np.float64) for n in names], -1)
    return t, v


def _interp(grid: np.ndarray, t: np.ndarray, v: np.ndarray, what: str, path: Path) -> np.ndarray:
    if len(t) == 0:
        raise FormatError(f"{what} is empty", path=path)
    if grid[0] < t[0] or grid[-1] > t[-1]:
        raise FormatError(
            f"{what} covers {t[0]}..{t[-1]} ns, the camera frames {grid[0]}..{grid[-1]} ns",
            path=path,
            hint="the export samples every stream at the camera frames; trim the episode",
        )
    return np.asarray(interp_linear(grid, t, v, outside="raise"), np.float64)


def _ee_link(ds: Dataset) -> str:
    link = (ds.manifest.get("robot") or {}).get("ee_link")
    if not link:
        raise InputError(
            "--state ee needs robot.ee_link in the manifest",
            path=ds.manifest_path,
            where="robot/ee_link",
        )
    return str(link)


def _fk_pose(chain: Any, link: str, q: np.ndarray) -> np.ndarray:
    """[N, 7] ``T_world_link`` as (x, y, z, qw, qx, qy, qz) for joint vectors [N, J]."""
    import torch

    from robogs.format.frames import matrix_to_quat

    T = chain.forward(torch.as_tensor(q, dtype=torch.float64))[:, chain.link_index(link)]
    quat = matrix_to_quat(T[:, :3, :3])
    quat = torch.where(quat[:, :1] < 0, -quat, quat)  # one hemisphere: w >= 0
    return torch.cat([T[:, :3, 3], quat], -1).numpy()


def _ee_state(ep: Episode, link: str, grid: np.ndarray) -> np.ndarray | None:
    if not ep.has("ee_poses"):
        return None
    tab = ep.table("ee_poses")
    m = np.asarray(tab.column("link").to_pylist()) == link
    if not m.any():
        return None
    cols = {c: tab.column(c).to_numpy()[m] for c in ("t_ns", "x", "y", "z", "qw", "qx", "qy", "qz")}
    t = cols["t_ns"].astype(np.int64)
    if grid[0] < t[0] or grid[-1] > t[-1]:
        return None
    p = np.stack([cols["x"], cols["y"], cols["z"]], -1)
    q = np.stack([cols["qw"], cols["qx"], cols["qy"], cols["qz"]], -1)
    pos, quat = interp_pose(grid, t, p, q, outside="raise")
    quat = np.where(quat[:, :1] < 0, -quat, quat)
    return np.concatenate([pos, quat], -1)


def _stats(x: np.ndarray) -> dict[str, list]:
    """LeRobot's per-feature statistics of rows [N, D] (``compute_stats._compute_basic_stats``)."""
    x = np.asarray(x, np.float64).reshape(len(x), -1)
    out = {
        "min": x.min(0).tolist(),
        "max": x.max(0).tolist(),
        "mean": x.mean(0).tolist(),
        "std": x.std(0).tolist(),
        "count": [len(x)],
    }
    for q in _QUANTILES:
        out[f"q{round(q * 100):02d}"] = np.quantile(x, q, axis=0).tolist()
    return out


def _image_stats(frames: list[np.ndarray]) -> dict[str, list]:
    """Per-channel statistics of RGB frames in [0, 1], shaped [3, 1, 1] as LeRobot keeps them."""
    px = np.concatenate([f.reshape(-1, 3) for f in frames]).astype(np.float64) / 255.0
    s = _stats(px)
    return {k: v if k == "count" else [[[c]] for c in v] for k, v in s.items()} | {
        "count": [len(frames)]
    }


def _tasks_table(tasks: list[str]) -> pa.Table:
    """``task_index`` with the task strings as the pandas index (what ``pd.read_parquet`` and
    LeRobot's ``meta.tasks.loc[task]`` expect)."""
    tab = pa.table(
        {
            "task_index": pa.array(range(len(tasks)), pa.int64()),
            "__index_level_0__": pa.array(tasks, pa.string()),
        }
    )
    pandas_meta = {
        "index_columns": ["__index_level_0__"],
        "column_indexes": [],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {
                "name": None,
                "field_name": "__index_level_0__",
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": None,
            },
        ],
        "creator": {"library": "robogs", "version": "1"},
        "pandas_version": "2.2.0",
    }
    return tab.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})


def _read_labels(ep: Episode, cam: str, wanted: np.ndarray) -> dict[int, np.ndarray]:
    from robogs.format.rerender import read_label_frames

    return dict(read_label_frames(ep.labels_path(cam), sorted(set(int(i) for i in wanted))))


def _depth_frames(ep: Episode, cam: str, wanted: np.ndarray) -> dict[int, bytes] | None:
    """16-bit PNGs (mm) of a rendered depth stream ``depth/<cam>``, by frame index."""
    name = f"depth/{cam}"
    if not ep.has(name):
        return None
    tab = ep.table(name, columns=["frame_index", "png"])
    want = set(int(i) for i in wanted)
    idx = tab.column("frame_index").to_numpy()
    blobs = tab.column("png")
    return {int(i): blobs[k].as_py() for k, i in enumerate(idx) if int(i) in want}


def export_lerobot(
    ds: Dataset,
    out: Path,
    *,
    episode: str | None = None,
    state: str = "joints",
    fps: int | None = None,
    labels: bool = False,
) -> ExportReport:
    """Write a LeRobot v3.0 dataset of every episode (or ``episode``) into the folder ``out``.

    Args:
        ds: the dataset.
        out: the (temporary) output folder.
        episode: only this episode id (default: all, in manifest order).
        state: ``"joints"`` or ``"ee"`` (see the module docstring).
        fps: the frame rate of the regular grid, Hz (default: the first camera's nominal rate).
        labels: add panoptic label (and rendered depth) image features.

    Raises:
        InputError: bad option, no camera, no joint states.
        FormatError: a stream does not cover the camera frames, or lacks joints.
    """
    if state not in ("joints", "ee"):
        raise InputError(f"unknown state {state!r}", where="--state", hint="joints or ee")
    if fps is not None and (not isinstance(fps, int) or fps <= 0):
        raise InputError(f"fps must be a positive integer, got {fps!r}", where="--fps")
    from robogs.format.kinematics import Chain, dataset_fitted_chain

    chain, _ = dataset_fitted_chain(ds, Chain.from_urdf(ds.urdf(load_meshes=False)))
    joints = list(chain.joint_names)
    episodes = [ds.episode(episode)] if episode is not None else ds.episodes
    if not episodes:
        raise InputError("dataset has no episodes", path=ds.manifest_path)
    rendered = _rendered_ids(ds)
    notes: list[str] = []
    plans: list[_EpisodePlan] = []
    for ep in episodes:
        cams = _camera_streams(ds, ep)
        if not cams:
            raise InputError(
                f"episode {ep.id!r} has no camera frames",
                path=ds.manifest_path,
                where=f"episodes/{ep.id}",
                hint="LeRobot datasets are indexed by camera frames",
            )
        if fps is None:
            rate = ep.streams[_stream_name(ep, cams[0].name)].get("nominal_rate_hz")
            if not rate:
                rate = 1e9 / float(np.median(np.diff(cams[0].stamps)))
            fps = max(1, int(round(float(rate))))
        start = max(int(c.stamps[0]) for c in cams)
        end = min(int(c.stamps[-1]) for c in cams)
        grid = resample_grid(start, end, fps)
        if len(grid) < 2:
            raise InputError(f"episode {ep.id!r}: the cameras overlap for fewer than 2 frames")
        plans.append(_EpisodePlan(ep, grid, cams, ep.segment, ep.id in rendered))
    assert fps is not None
    tasks = sorted({p.task for p in plans})
    task_of = {t: i for i, t in enumerate(tasks)}
    cam_names = sorted({c.name for p in plans for c in p.cams})
    first_cams = [c.name for c in plans[0].cams]
    if any([c.name for c in p.cams] != first_cams for p in plans):
        raise InputError(
            "episodes have different cameras",
            hint="export them separately with --episode",
        )
    models = {c: ds.camera(c) for c in cam_names}
    ee = _ee_link(ds) if state == "ee" else None
    names = ["x", "y", "z", "qw", "qx", "qy", "qz"] if ee else joints
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("state", "action", "stamp", "ep", "fi")}
    cam_stamp: dict[str, list[np.ndarray]] = {c: [] for c in cam_names}
    panoptic: dict[str, list[bytes]] = {c: [] for c in cam_names}
    depth: dict[str, list[bytes]] = {c: [] for c in cam_names}
    has_depth = {c: labels for c in cam_names}
    ep_rows: list[dict[str, Any]] = []
    worst_ms = 0.0
    derived_action = []
    sample_frames: dict[str, list[np.ndarray]] = {c: [] for c in cam_names}
    writers = {}
    for c in cam_names:
        rel = VIDEO_PATH.format(video_key=f"observation.images.{c}", chunk_index=0, file_index=0)
        (out / rel).parent.mkdir(parents=True, exist_ok=True)
        writers[c] = VideoWriter(out / rel, models[c].width, models[c].height, fps)
    total = 0
    try:
        for e_idx, plan in enumerate(plans):
            ep, grid = plan.episode, plan.grid
            n = len(grid)
            t_js, q_js = _table_values(ep, "joint_states", "position.", joints)
            q = _interp(grid, t_js, q_js, "joint_states", ep.table_path("joint_states"))
            if ep.has("actions"):
                t_a, q_a = _table_values(ep, "actions", "command.", joints)
                kind = ep.streams["actions"].get("command_kind", "position")
                if kind != "position":
                    raise InputError(
                        f"episode {ep.id!r}: actions are {kind} commands; the export "
                        "writes joint positions",
                        where=f"episodes/{ep.id}/streams/actions",
                    )
                cmd = _interp(grid, t_a, q_a, "actions", ep.table_path("actions"))
            else:
                cmd = np.concatenate([q[1:], q[-1:]])
                derived_action.append(ep.id)
            if ee is not None:
                st = _ee_state(ep, ee, grid)
                st = _fk_pose(chain, ee, q) if st is None else st
                act = _fk_pose(chain, ee, cmd)
            else:
                st, act = q, cmd
            rows["state"].append(st)
            rows["action"].append(act)
            rows["stamp"].append(grid)
            rows["ep"].append(np.full(n, e_idx, np.int64))
            rows["fi"].append(np.arange(n, dtype=np.int64))
            entry: dict[str, Any] = {
                "episode_index": e_idx,
                "tasks": [plan.task],
                "length": n,
                "data/chunk_index": 0,
                "data/file_index": 0,
                "dataset_from_index": total,
                "dataset_to_index": total + n,
                "meta/episodes/chunk_index": 0,
                "meta/episodes/file_index": 0,
                "robogs/episode_id": ep.id,
                "robogs/source": "rendered" if plan.rendered else "recorded",
            }
            for cam in plan.cams:
                pick = nearest_frames(grid, cam.stamps)
                plan.picks[cam.name] = pick
                worst_ms = max(worst_ms, float(np.abs(cam.stamps[pick] - grid).max()) / 1e6)
                cam_stamp[cam.name].append(cam.stamps[pick])
                key = cam.key
                entry[f"videos/{key}/chunk_index"] = 0
                entry[f"videos/{key}/file_index"] = 0
                entry[f"videos/{key}/from_timestamp"] = writers[cam.name].count / fps
                entry[f"videos/{key}/to_timestamp"] = (writers[cam.name].count + n) / fps
                wanted = cam.frame_index[pick]
                _write_video(ep, cam, wanted, writers[cam.name], sample_frames[cam.name])
                if labels:
                    has = "labels" in _stream_of(ep, cam.name)
                    labs = _read_labels(ep, cam.name, wanted) if has else None
                    if labs is None or any(int(i) not in labs for i in wanted):
                        raise FormatError(
                            f"camera {cam.name!r} of episode {ep.id!r} lacks label images",
                            path=ds.manifest_path,
                            hint="export without --with-labels",
                        )
                    panoptic[cam.name] += [encode_label_png(labs[int(i)]) for i in wanted]
                    dep = _depth_frames(ep, cam.name, wanted)
                    if dep is None or any(int(i) not in dep for i in wanted):
                        has_depth[cam.name] = False
                    else:
                        depth[cam.name] += [dep[int(i)] for i in wanted]
            ep_rows.append(entry)
            total += n
    finally:
        for w in writers.values():
            w.close()
    # -- frames table ---------------------------------------------------------------------
    state_arr = np.concatenate(rows["state"]).astype(np.float32)
    action_arr = np.concatenate(rows["action"]).astype(np.float32)
    stamp = np.concatenate(rows["stamp"])
    ep_idx = np.concatenate(rows["ep"])
    fidx = np.concatenate(rows["fi"])
    d = state_arr.shape[1]
    cols: dict[str, pa.Array] = {
        "observation.state": pa.FixedSizeListArray.from_arrays(
            pa.array(state_arr.ravel(), pa.float32()), d
        ),
        "action": pa.FixedSizeListArray.from_arrays(
            pa.array(action_arr.ravel(), pa.float32()), action_arr.shape[1]
        ),
        "observation.stamp_ns": pa.array(stamp, pa.int64()),
    }
    for c in cam_names:
        cols[f"observation.images.{c}.stamp_ns"] = pa.array(
            np.concatenate(cam_stamp[c]), pa.int64()
        )
    image_struct = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    for c in cam_names:
        if labels:
            cols[f"observation.images.{c}.panoptic"] = pa.array(
                [{"bytes": b, "path": None} for b in panoptic[c]], image_struct
            )
        if labels and has_depth[c]:
            cols[f"observation.images.{c}.depth"] = pa.array(
                [{"bytes": b, "path": None} for b in depth[c]], image_struct
            )
    cols["timestamp"] = pa.array((fidx / fps).astype(np.float32), pa.float32())
    cols["frame_index"] = pa.array(fidx, pa.int64())
    cols["episode_index"] = pa.array(ep_idx, pa.int64())
    cols["index"] = pa.array(np.arange(total, dtype=np.int64), pa.int64())
    cols["task_index"] = pa.array(
        np.concatenate([np.full(p.grid.size, task_of[p.task], np.int64) for p in plans]),
        pa.int64(),
    )
    data_rel = DATA_PATH.format(chunk_index=0, file_index=0)
    (out / data_rel).parent.mkdir(parents=True)
    pq.write_table(pa.table(cols), out / data_rel)
    # -- features, stats, episodes, tasks, info ---------------------------------------------
    vec = {"dtype": "float32", "shape": [d], "names": names}
    features: dict[str, Any] = {
        "observation.state": vec,
        "action": {**vec, "shape": [action_arr.shape[1]]},
        "observation.stamp_ns": {"dtype": "int64", "shape": [1], "names": None},
    }
    for c in cam_names:
        m = models[c]
        features[f"observation.images.{c}"] = {
            "dtype": "video",
            "shape": [m.height, m.width, 3],
            "names": ["height", "width", "channels"],
            "info": {
                "video.height": m.height,
                "video.width": m.width,
                "video.codec": "mpeg4",
                "video.pix_fmt": "yuv420p",
                "video.is_depth_map": False,
                "video.fps": fps,
                "video.channels": 3,
                "has_audio": False,
            },
        }
        features[f"observation.images.{c}.stamp_ns"] = {
            "dtype": "int64",
            "shape": [1],
            "names": None,
        }
        img = {"dtype": "image", "names": ["height", "width", "channels"]}
        if labels:
            features[f"observation.images.{c}.panoptic"] = {**img, "shape": [m.height, m.width, 1]}
        if labels and has_depth[c]:
            features[f"observation.images.{c}.depth"] = {**img, "shape": [m.height, m.width, 1]}
    for k in ("timestamp",):
        features[k] = {"dtype": "float32", "shape": [1], "names": None}
    for k in ("frame_index", "episode_index", "index", "task_index"):
        features[k] = {"dtype": "int64", "shape": [1], "names": None}
    numeric = {
        "observation.state": state_arr,
        "action": action_arr,
        "timestamp": (fidx / fps)[:, None],
        "frame_index": fidx[:, None],
        "episode_index": ep_idx[:, None],
        "index": np.arange(total)[:, None],
    }
    stats: dict[str, Any] = {k: _stats(v) for k, v in numeric.items()}
    for c in cam_names:
        if sample_frames[c]:
            stats[f"observation.images.{c}"] = _image_stats(sample_frames[c])
    (out / "meta").mkdir()
    (out / "meta" / "stats.json").write_text(json.dumps(stats, indent=2))
    for entry in ep_rows:
        lo, hi = entry["dataset_from_index"], entry["dataset_to_index"]
        for k in ("observation.state", "action"):
            for s, v in _stats(numeric[k][lo:hi]).items():
                entry[f"stats/{k}/{s}"] = v
    ep_rel = EPISODES_PATH.format(chunk_index=0, file_index=0)
    (out / ep_rel).parent.mkdir(parents=True)
    pq.write_table(pa.Table.from_pylist(ep_rows), out / ep_rel)
    pq.write_table(_tasks_table(tasks), out / TASKS_PATH)
    cameras = {}
    for c in cam_names:
        m = models[c]
        cameras[c] = {
            "width": m.width,
            "height": m.height,
            "fx": m.fx,
            "fy": m.fy,
            "cx": m.cx,
            "cy": m.cy,
            "distortion_model": m.distortion_model,
            "distortion": list(m.distortion),
            "T_world_cam": None
            if m.T_world_cam is None
            else np.asarray(m.T_world_cam, np.float64).tolist(),
            "axes": "opencv (x right, y down, z forward)",
        }
    info = {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": _robot_name(ds),
        "total_episodes": len(plans),
        "total_frames": total,
        "total_tasks": len(tasks),
        "chunks_size": _CHUNKS_SIZE,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "fps": fps,
        "splits": {"train": f"0:{len(plans)}"},
        "data_path": DATA_PATH,
        "video_path": VIDEO_PATH,
        "features": features,
        "robogs": {
            "source": ds.name,
            "state": state,
            "ee_link": ee,
            "world_frame": "z up, origin at the robot base, metres",
            "quaternion_order": "wxyz",
            "cameras": cameras,
            "resampling": {
                "grid": "t_k = t_start + k / fps, t_start = latest first camera frame",
                "joints": "linear",
                "ee_poses": "linear position, slerp rotation",
                "images": "nearest recorded frame",
                "max_image_offset_ms": round(worst_ms, 3),
            },
            "episodes": {
                p.episode.id: {
                    "index": i,
                    "source": "rendered" if p.rendered else "recorded",
                    "start_ns": int(p.grid[0]),
                }
                for i, p in enumerate(plans)
            },
            "derived_action": derived_action,
        },
    }
    (out / "meta" / "info.json").write_text(json.dumps(info, indent=2))
    notes.append(
        f"resampled to a regular {fps} fps grid (LeRobot v3 needs timestamp = k / fps): joints "
        f"linear, images nearest recorded frame (at most {worst_ms:.2f} ms away; real stamps "
        "kept in *.stamp_ns)"
    )
    if derived_action:
        notes.append(f"no actions stream in {', '.join(derived_action)}: action = next state")
    if rendered & {p.episode.id for p in plans}:
        notes.append(f"rendered episodes marked: {', '.join(sorted(rendered))}")
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    return ExportReport(
        out=out,
        files=files,
        notes=notes,
        facts={
            "fps": fps,
            "episodes": len(plans),
            "frames": total,
            "cameras": cam_names,
            "state": state,
            "max_image_offset_ms": worst_ms,
        },
    )


def _stream_name(ep: Episode, cam: str) -> str:
    for name, s in ep.streams.items():
        if s.get("kind") == "camera" and s.get("camera") == cam:
            return name
    raise FormatError(f"no stream for camera {cam!r}")  # pragma: no cover - checked before


def _stream_of(ep: Episode, cam: str) -> dict[str, Any]:
    return ep.streams[_stream_name(ep, cam)]


def _robot_name(ds: Dataset) -> str | None:
    try:
        return str(ds.urdf(load_meshes=False).robot.name)
    except Exception:  # a robot name is only a label here
        return None


def _write_video(
    ep: Episode, cam: _Stream, wanted: np.ndarray, writer: VideoWriter, samples: list[np.ndarray]
) -> None:
    """Append the recorded frames ``wanted`` (non-decreasing file indices, repeats allowed)."""
    from robogs.format.images import iter_video_frames

    order = np.asarray(wanted, np.int64)  # frame_index is the frame's position in the file
    every = max(1, len(order) // _IMAGE_STAT_FRAMES)
    k = 0
    for i, img in enumerate(iter_video_frames(ep.video_path(cam.name))):
        while k < len(order) and order[k] == i:
            writer.write(img)
            if k % every == 0:
                samples.append(img[::4, ::4])
            k += 1
        if k == len(order):
            break
    if k < len(order):
        raise FormatError(
            f"video of camera {cam.name!r} has fewer frames than its frame table "
            f"(needed frame {int(order[k])})",
            path=ep.video_path(cam.name),
            hint="run robogs-validate",
        )


register_exporter(
    "lerobot",
    export_lerobot,
    output="folder",
    help="LeRobot dataset v3.0: parquet frames, MP4 per camera, meta (fps grid, stated)",
)
