"""Render a commanded joint trajectory through the binding into a new robogs dataset.

The bound Gaussians of a dataset are posed at every frame stamp by forward kinematics of the
*commanded* joints (``x(t) = T_L(q(t)) · T_L(q0)⁻¹ · x0``, :class:`robogs.format.binding.Binding`)
and objects follow the source episode's pose stream (replayed, clamped at its ends) or poses
given by the caller (``object_poses``: the CLI's ``--simulate`` rolls them out with a physics
engine; this module does not import :mod:`robogs.physics`). Each frame
is rendered by :class:`robogs.format.rerender.SceneRerenderer`, the validator's re-renderer,
with one label channel per bound target, which gives per frame:

* RGB (the Gaussians' colour, black background), uint8;
* panoptic labels: the label id of the most probable channel, 0 where "nothing" wins — the
  rule the validator's comparison uses, so the labels match FK of the commanded joints by
  construction and ``robogs-validate`` checks that end to end;
* depth: the median depth (m, camera z) where a label is drawn, stored as a 16-bit PNG in mm
  (0: none) in the generic stream ``depth/<cam>``;
* 2-D boxes of every label (pixel edges, max exclusive);
* optionally (``normals=True``) surface normals in the camera frame (OpenCV axes, facing the
  camera): the renderer's blended splat normals (``RenderOutput.normals``: a 2DGS surfel's own
  normal, a 3DGS Gaussian's shortest axis) renormalised, where a label is drawn; stored as
  8-bit RGB PNGs ``n * 0.5 + 0.5`` (0, 0, 0: none; :func:`encode_normals_png`) in the generic
  stream ``normals/<cam>``.

The output is a dataset (:func:`render_dataset`) that shares the source's robot, assets,
physics and cameras (hard links where the file system allows, copies otherwise) and holds one
new episode, marked in ``provenance.rendered``. Frames are rendered one at a time (the
per-frame cost is the renderer's, ``bench/render.py``).
"""

from __future__ import annotations

import csv
import math
import os
import shutil
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import torch

from .binding import Binding
from .cameras import CameraModel
from .dataset import Dataset, Episode
from .errors import FormatError, InputError
from .frames import matrix_to_quat
from .images import VideoWriter, encode_label_png
from .interp import interp_pose

__all__ = [
    "JointTrajectory",
    "read_joint_trajectory",
    "episode_trajectory",
    "parse_edits",
    "orbit_poses",
    "label_boxes",
    "encode_normals_png",
    "decode_normals_png",
    "RenderedFrame",
    "TrajectoryRenderer",
    "RenderSummary",
    "PoseStreams",
    "render_dataset",
    "resolve_backend",
]


@dataclass(frozen=True)
class JointTrajectory:
    """Commanded joint positions.

    Attributes:
        t_ns: [N] strictly increasing stamps, int64 ns, dataset clock.
        q: [N, J] positions (rad or m) in ``joint_names`` order.
        joint_names: the URDF's actuated joints.
        source: where it came from (file, or episode and edits), for provenance.
    """

    t_ns: np.ndarray
    q: np.ndarray
    joint_names: list[str]
    source: str


def _check(traj: JointTrajectory, chain: Any, path: str | Path | None, rows: np.ndarray) -> None:
    """Refuse non-increasing stamps, non-finite values and positions outside the limits.

    ``rows`` are the row numbers to report (1-based data rows of the file).
    """
    t, q = traj.t_ns, traj.q
    if len(t) < 2:
        raise InputError("a trajectory needs at least 2 rows", path=path)
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise InputError(
            f"stamps are not increasing at row {int(rows[i])} "
            f"(t_ns {int(t[i])} after {int(t[i - 1])})",
            path=path,
            where=f"row {int(rows[i])}",
            hint="sort the rows by t_ns and remove duplicates",
        )
    finite = np.isfinite(q).all(1)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise InputError(f"row {int(rows[i])} has a non-finite position", path=path)
    lo, hi = np.asarray(chain.joint_lower), np.asarray(chain.joint_upper)
    out = (q < lo - 1e-9) | (q > hi + 1e-9)
    if out.any():
        i, j = (int(x) for x in np.argwhere(out)[0])
        raise InputError(
            f"row {int(rows[i])}: {traj.joint_names[j]} = {q[i, j]:.6g} is outside its limits "
            f"[{lo[j]:.6g}, {hi[j]:.6g}] ({int(out.any(1).sum())} rows out of limits)",
            path=path,
            where=f"row {int(rows[i])}",
            hint="keep the trajectory inside the URDF joint limits",
        )


def _read_table(path: Path) -> dict[str, np.ndarray]:
    if path.suffix.lower() == ".parquet":
        try:
            tab = pq.read_table(path)
        except (pa.ArrowException, OSError) as exc:
            raise InputError(f"unreadable parquet ({str(exc)[:200]})", path=path) from None
        return {n: tab.column(n).to_numpy(zero_copy_only=False) for n in tab.column_names}
    if path.suffix.lower() != ".csv":
        raise InputError("joint trajectory must be .parquet or .csv", path=path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            body = [r for r in reader if r]
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    if not header:
        raise InputError("empty CSV", path=path)
    cols: dict[str, list[str]] = {h.strip(): [] for h in header}
    names = list(cols)
    for k, r in enumerate(body, start=2):
        if len(r) != len(names):
            raise InputError(f"line {k} has {len(r)} fields, the header {len(names)}", path=path)
        for n, v in zip(names, r, strict=True):
            cols[n].append(v.strip())
    out: dict[str, np.ndarray] = {}
    for n, vals in cols.items():
        try:
            out[n] = (
                np.array([int(v) for v in vals], np.int64)
                if n == "t_ns"
                else np.array([float(v) for v in vals], np.float64)
            )
        except ValueError:
            bad = next(
                i for i, v in enumerate(vals) if not _parses(v, int if n == "t_ns" else float)
            )
            raise InputError(
                f"line {bad + 2}: {n} = {vals[bad]!r} is not a number", path=path
            ) from None
    return out


def _parses(v: str, typ: type) -> bool:
    try:
        typ(v)
    except ValueError:
        return False
    return True


def read_joint_trajectory(path: str | Path, chain: Any) -> JointTrajectory:
    """Read ``t_ns, position.<joint>`` rows from a Parquet or CSV file.

    Every actuated joint of ``chain`` must have a column; a ``position.`` column naming no
    joint of the robot is refused. Rows are numbered from 1 (the first data row).

    Raises:
        InputError: unreadable file, missing ``t_ns``, unknown or missing joints, stamps that do
            not increase, or positions outside the joint limits (the row is named).
    """
    path = Path(path)
    cols = _read_table(path)
    if "t_ns" not in cols:
        raise InputError(
            "no t_ns column (int64 ns)", path=path, hint="columns: t_ns, position.<joint>"
        )
    t = np.asarray(cols["t_ns"])
    if t.dtype.kind not in "iu":
        raise InputError(f"t_ns must be integer nanoseconds, got {t.dtype}", path=path)
    names = list(chain.joint_names)
    given = [n[len("position.") :] for n in cols if n.startswith("position.")]
    unknown = [g for g in given if g not in names]
    if unknown:
        raise InputError(
            f"unknown joint(s) {', '.join(unknown)} (column position.{unknown[0]})",
            path=path,
            hint=f"the robot's joints: {', '.join(names)}",
        )
    missing = [n for n in names if n not in given]
    if missing:
        raise InputError(
            f"missing joint(s) {', '.join(missing)}",
            path=path,
            hint="give position.<joint> for every actuated joint",
        )
    q = np.stack([np.asarray(cols[f"position.{n}"], np.float64) for n in names], -1)
    traj = JointTrajectory(t.astype(np.int64), q, names, f"file {path.name}")
    _check(traj, chain, path, np.arange(1, len(t) + 1))
    return traj


def parse_edits(edits: Sequence[str], joint_names: Sequence[str]) -> dict[str, float]:
    """``["elbow_joint=+0.1", ...]`` -> ``{joint: offset}`` (rad or m)."""
    out: dict[str, float] = {}
    for e in edits:
        name, sep, val = e.partition("=")
        name = name.strip()
        if not sep:
            raise InputError(
                f"edit {e!r} is not JOINT=OFFSET", where="--edit", hint="e.g. elbow_joint=+0.1"
            )
        if name not in joint_names:
            raise InputError(
                f"--edit names unknown joint {name!r}",
                where="--edit",
                hint=f"the robot's joints: {', '.join(joint_names)}",
            )
        try:
            out[name] = out.get(name, 0.0) + float(val)
        except ValueError:
            raise InputError(f"edit {e!r}: {val!r} is not a number", where="--edit") from None
    return out


def episode_trajectory(ep: Episode, chain: Any, edits: dict[str, float]) -> JointTrajectory:
    """The recorded joint states of ``ep`` plus constant ``edits`` (rad or m per joint)."""
    tab = ep.table("joint_states")
    names = list(chain.joint_names)
    missing = [n for n in names if f"position.{n}" not in tab.column_names]
    if missing:
        raise FormatError(
            f"joint_states lacks position.{missing[0]}", path=ep.table_path("joint_states")
        )
    q = np.stack([tab.column(f"position.{n}").to_numpy().astype(np.float64) for n in names], -1)
    q = q + np.array([edits.get(n, 0.0) for n in names])
    desc = ", ".join(f"{k}{v:+g}" for k, v in edits.items())
    traj = JointTrajectory(
        tab.column("t_ns").to_numpy().astype(np.int64),
        q,
        names,
        f"episode {ep.id}" + (f" with {desc}" if desc else ""),
    )
    _check(traj, chain, ep.table_path("joint_states"), np.arange(1, len(q) + 1))
    return traj


def orbit_poses(
    eye: np.ndarray, target: np.ndarray, turns: float, t_ns: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Camera poses circling ``target`` about the world z axis (``turns`` revolutions).

    The eye starts at ``eye`` and keeps its height and horizontal distance; the camera looks at
    ``target`` (OpenCV axes, image y down towards world -z).

    Returns:
        positions [F, 3] (m) and quaternions [F, 4] (w, x, y, z) of ``T_world_cam``.
    """
    eye, target = np.asarray(eye, np.float64), np.asarray(target, np.float64)
    rel = eye - target
    r, phi0 = math.hypot(rel[0], rel[1]), math.atan2(rel[1], rel[0])
    s = (t_ns - t_ns[0]) / max(float(t_ns[-1] - t_ns[0]), 1.0)
    phi = phi0 + 2.0 * math.pi * turns * s
    pos = np.stack(
        [target[0] + r * np.cos(phi), target[1] + r * np.sin(phi), np.full_like(phi, eye[2])], -1
    )
    R = np.zeros((len(s), 3, 3))
    for k, p in enumerate(pos):
        z = target - p
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x = x / np.linalg.norm(x) if np.linalg.norm(x) > 1e-9 else np.array([1.0, 0.0, 0.0])
        R[k] = np.stack([x, np.cross(z, x), z], -1)
    quat = matrix_to_quat(torch.as_tensor(R)).numpy()
    return pos, quat


def label_boxes(labels: np.ndarray) -> list[tuple[int, int, int, int, int]]:
    """(label, x_min, y_min, x_max, y_max) per non-zero label: pixel edges, max exclusive."""
    out = []
    for lab in np.unique(labels):
        if lab == 0:
            continue
        rows = np.flatnonzero((labels == lab).any(1))
        cols = np.flatnonzero((labels == lab).any(0))
        out.append((int(lab), int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1))
    return out


def encode_normals_png(normals: np.ndarray) -> bytes:
    """[H, W, 3] unit normals (zero: none) -> 8-bit RGB PNG of ``round((n * 0.5 + 0.5) * 255)``;
    pixels without a normal are (0, 0, 0), which no unit normal encodes to."""
    import cv2

    n = np.asarray(normals, np.float64)
    rgb = np.clip(np.round((n * 0.5 + 0.5) * 255.0), 0, 255).astype(np.uint8)
    rgb[~np.any(n != 0, -1)] = 0
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise FormatError("PNG encoding failed")
    return buf.tobytes()


def decode_normals_png(blob: bytes) -> np.ndarray:
    """Inverse of :func:`encode_normals_png`: [H, W, 3] float32 normals, renormalised, zero where
    none (the 8-bit encoding is good to about 0.5 degrees)."""
    import cv2

    img = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise FormatError("normals image is not a decodable PNG")
    rgb = img[..., ::-1].astype(np.float64)
    n = rgb / 255.0 * 2.0 - 1.0
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(rgb.any(-1, keepdims=True), n / np.maximum(norm, 1e-12), 0.0)
    return n.astype(np.float32)


def resolve_backend(name: str, device: str = "cpu") -> str:
    """The render backend ``name`` stands for: ``auto`` is the compiled forward-only ``numba``
    backend on CPU when it is installed (about 1.5x the torch backend's frame rate on a 104k
    surfel, 10-label frame at 640x480: ``bench/render.py --only fps``), else ``torch``."""
    if name != "auto":
        return name
    from .render import available_backends

    return "numba" if device == "cpu" and "numba" in available_backends() else "torch"


class _CommandedBinding(Binding):
    """A binding whose links follow a given joint trajectory instead of ``joint_states``."""

    def __init__(self, dataset: Dataset, episode: str | None, traj: JointTrajectory, **kw: Any):
        super().__init__(dataset, episode, **kw)
        self._joint_stream = (
            torch.as_tensor(traj.t_ns),
            torch.as_tensor(traj.q, dtype=torch.float64),
        )
        if list(self.chain.joint_names) != list(traj.joint_names):
            raise InputError("trajectory joints are not the robot's", where="render")


@dataclass
class RenderedFrame:
    """One rendered frame: RGB uint8 [H, W, 3], labels uint16 [H, W], depth m float32 [H, W],
    unit normals float32 [H, W, 3] (camera frame, OpenCV axes; 0 where no label is drawn) when
    asked for, else None."""

    rgb: np.ndarray
    labels: np.ndarray
    depth: np.ndarray
    normals: np.ndarray | None = None


class TrajectoryRenderer:
    """Renders the bound Gaussians posed by a joint trajectory into one camera.

    Args:
        dataset: the source dataset (splats, URDF, segments, object poses).
        episode: the source episode (objects are replayed from it; its segments label the
            targets).
        traj: the commanded joints.
        camera: the camera model; ``pose_of`` gives time-varying ``T_world_cam``.
        backend: render backend (``auto``: see :func:`resolve_backend`).
    """

    def __init__(
        self,
        dataset: Dataset,
        episode: Episode,
        traj: JointTrajectory,
        camera: CameraModel,
        *,
        pose_of: Callable[[int], np.ndarray] | None = None,
        backend: str = "auto",
        binding: Binding | None = None,
    ) -> None:
        from .rerender import SceneRerenderer, label_channels

        self.binding = binding or _CommandedBinding(dataset, episode.id, traj)
        backend = resolve_backend(backend, self.binding.rest.means.device.type)
        self.channels = label_channels(self.binding, episode.table("segments"))
        self.rr = SceneRerenderer(
            self.binding, camera, self.channels, backend=backend, pose_of=pose_of
        )
        self._ids = np.concatenate([[0], self.channels.label_ids]).astype(np.uint16)

    def frame(self, t_ns: int, *, normals: bool = False) -> RenderedFrame:
        """Render at ``t_ns`` (dataset clock); ``normals``: also the unit splat normals."""
        with torch.no_grad():
            out = self.rr.render(int(t_ns))
        p = self.rr.probabilities(out)
        labels = self._ids[p.argmax(-1)]
        rgb = (out.rgb.clamp(0.0, 1.0) * 255.0).round().to(torch.uint8).cpu().numpy()
        depth = out.depth_median.cpu().numpy().astype(np.float32)
        depth = np.where(labels > 0, depth, 0.0).astype(np.float32)
        if not normals:
            return RenderedFrame(rgb, labels, depth)
        n = out.normals.double().cpu().numpy()
        norm = np.linalg.norm(n, axis=-1, keepdims=True)
        ok = (labels > 0)[..., None] & (norm > 1e-6)
        n = np.where(ok, n / np.where(ok, norm, 1.0), 0.0).astype(np.float32)
        return RenderedFrame(rgb, labels, depth, n)


@dataclass
class RenderSummary:
    """What :func:`render_dataset` wrote."""

    out: Path
    episode: str
    frames: dict[str, int]
    empty_frames: dict[str, int]
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _link_or_copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def _rate(t: np.ndarray) -> float | None:
    return float(1e9 / np.median(np.diff(t))) if len(t) > 1 else None


#: object name -> (t_ns [N] int64, position [N, 3] m, quaternion [N, 4] wxyz), T_world_object
PoseStreams = dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]


def _object_table(ep: Episode, t: np.ndarray, given: PoseStreams | None = None) -> pa.Table | None:
    """Object poses sampled at ``t`` (interpolated, clamped at the ends): ``given`` streams
    where named, the source episode's recorded ones otherwise."""
    given = given or {}
    streams: PoseStreams = dict(given)
    if ep.has("object_poses"):
        tab = ep.table("object_poses")
        names = np.asarray(tab.column("object").to_pylist())
        for name in sorted(set(names.tolist()) - set(given)):
            m = names == name
            ts = tab.column("t_ns").to_numpy()[m].astype(np.int64)
            p = np.stack([tab.column(c).to_numpy()[m] for c in ("x", "y", "z")], -1)
            q = np.stack([tab.column(c).to_numpy()[m] for c in ("qw", "qx", "qy", "qz")], -1)
            streams[name] = (ts, p, q)
    if not streams:
        return None
    parts = []
    for name in sorted(streams):
        ts, p, q = streams[name]
        pos, quat = interp_pose(t, np.asarray(ts, np.int64), p, q, outside="clamp")
        parts.append((name, pos, quat))
    n = len(t)
    cols: dict[str, Any] = {
        "t_ns": np.tile(t, len(parts)),
        "object": pa.array([nm for nm, _, _ in parts for _ in range(n)], pa.string()),
    }
    pos = np.concatenate([p for _, p, _ in parts])
    quat = np.concatenate([q for _, _, q in parts])
    for i, c in enumerate(("x", "y", "z")):
        cols[c] = pos[:, i]
    for i, c in enumerate(("qw", "qx", "qy", "qz")):
        cols[c] = quat[:, i]
    order = np.argsort(cols["t_ns"], kind="stable")
    return pa.table(cols).take(pa.array(order))


def render_dataset(
    src: Dataset,
    out: str | Path,
    traj: JointTrajectory,
    *,
    episode: str | None = None,
    cameras: Sequence[str] | None = None,
    camera_files: Sequence[str | Path] = (),
    orbit: float | None = None,
    frame_stamps: np.ndarray | None = None,
    fps: float = 30.0,
    new_episode: str = "render000",
    backend: str = "auto",
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    object_poses: PoseStreams | None = None,
    objects_source: str | None = None,
    keep_episodes: bool = False,
    normals: bool = False,
) -> RenderSummary:
    """Render ``traj`` into a new dataset at ``out`` (see the module docstring).

    Args:
        src: source dataset.
        out: new dataset folder (its parent must exist).
        traj: commanded joints (:func:`read_joint_trajectory` or :func:`episode_trajectory`).
        episode: source episode (objects, segments; default: the only one).
        cameras: recorded cameras to render (default: all of the source's, unless
            ``camera_files`` or ``orbit`` is given).
        camera_files: camera JSON files (``spec/schemas/camera.schema.json``: intrinsics and
            ``T_world_cam``) to render from.
        orbit: render a camera circling the robot this many turns over the trajectory
            (intrinsics, height and distance of the first recorded camera).
        frame_stamps: frame stamps (ns); default: every ``1/fps`` s over the trajectory.
        fps: frame rate when ``frame_stamps`` is None, Hz.
        new_episode: id of the rendered episode.
        backend: render backend (``auto``: see :func:`resolve_backend`; the one used is recorded).
        overwrite: replace ``out`` (only a robogs dataset that is not ``src``).
        progress: called with (frames done, frames in all).
        object_poses: poses for some objects instead of the source episode's (e.g. simulated
            from the commanded pusher motion by the CLI's ``--simulate``); the others are
            replayed.
        objects_source: how ``object_poses`` were made, for the stream and the provenance.
        keep_episodes: also keep the source's episodes (files shared) beside the rendered one,
            so that recorded and rendered episodes can be exported together.
        normals: also write the rendered surface normals (:class:`RenderedFrame`) as the
            generic stream ``normals/<cam>`` (``t_ns, frame_index, png``: RGB PNGs).

    Returns:
        What was written, with a warning per camera that saw nothing in some frames.
    """
    ep = src.episode(episode)
    out = Path(out)
    if frame_stamps is None:
        if not fps > 0:
            raise InputError(f"fps must be > 0, got {fps}", where="--fps")
        n = int((traj.t_ns[-1] - traj.t_ns[0]) * fps // 1_000_000_000) + 1
        frame_stamps = traj.t_ns[0] + np.round(np.arange(n) * 1e9 / fps).astype(np.int64)
    t_f = np.asarray(frame_stamps, np.int64)
    t_f = t_f[(t_f >= traj.t_ns[0]) & (t_f <= traj.t_ns[-1])]
    if len(t_f) == 0:
        raise InputError("no frame stamp falls inside the trajectory", hint="check t_ns")
    models: list[tuple[CameraModel, Callable[[int], np.ndarray] | None, np.ndarray | None]] = []
    for f in camera_files:
        from .cameras import CameraModel as _CM
        from .jsonio import read_json
        from .schemas import schema_problems

        doc = read_json(Path(f), what="camera file")
        problems = schema_problems("camera", doc)
        if problems:
            raise InputError(problems[0].message, path=f, where=problems[0].pointer)
        m = _CM.from_dict(doc)
        if m.T_world_cam is None:
            raise InputError("camera file has no T_world_cam", path=f)
        models.append((m, None, None))
    if orbit is not None:
        base = src.camera(src.camera_names[0])
        T = np.asarray(base.T_world_cam, np.float64)
        b = Binding(src, ep.id)
        robot = b.target_index >= 0
        target = b.rest.means[robot].double().mean(0).numpy() if robot.any() else np.zeros(3)
        pos, quat = orbit_poses(T[:3, 3], target, orbit, t_f)
        from .rerender import pose_stream

        m = CameraModel(
            "orbit",
            base.width,
            base.height,
            base.fx,
            base.fy,
            base.cx,
            base.cy,
            base.distortion_model,
            tuple(base.distortion),
            None,
            "time_varying",
        )
        models.append((m, pose_stream(t_f, pos, quat), np.concatenate([pos, quat], -1)))
    if cameras is None and not models:
        cameras = src.camera_names
    for c in cameras or []:
        models.append((src.camera(c), None, None))
    names = [m.name for m, _, _ in models]
    if len(set(names)) != len(names):
        raise InputError(f"camera names repeat: {names}", hint="give each camera file its own name")
    base_binding = _CommandedBinding(src, ep.id, traj)
    backend = resolve_backend(backend, base_binding.rest.means.device.type)
    for name, (ts, p, q) in (object_poses or {}).items():
        base_binding.set_object_poses(name, ts, p, q)
    replayed = f"replayed from episode {ep.id}"
    obj_source = (
        f"{objects_source or 'given'} ({', '.join(sorted(object_poses))}); others {replayed}"
        if object_poses
        else replayed
    )
    writer = Dataset.create(out, overwrite=overwrite, protect=[src.root])
    summary = RenderSummary(out, new_episode, {}, {})
    with writer:
        kept = [e for e in src.manifest.get("episodes", []) if e["id"] != new_episode]
        kept_dirs = tuple(f"episodes/{e['id']}/" for e in kept) if keep_episodes else ()
        for rel in src.files:
            if rel.startswith("cameras/") or (
                rel.startswith("episodes/") and not (kept_dirs and rel.startswith(kept_dirs))
            ):
                continue
            _link_or_copy(src.resolve(rel), writer.path(rel))
        if keep_episodes:
            writer.manifest["episodes"] = [dict(e) for e in kept]
            for c in src.camera_names:
                writer.set_camera(src.camera(c))
        for key in ("robot", "assets", "physics", "budgets"):
            if key in src.manifest:
                writer.manifest[key] = src.manifest[key]
        writer.manifest["conventions"] = dict(src.manifest.get("conventions", {}))
        e = f"episodes/{new_episode}"
        q_cols = {"t_ns": traj.t_ns}
        q_cols.update({f"position.{n}": traj.q[:, i] for i, n in enumerate(traj.joint_names)})
        writer.write_table(f"{e}/joint_states.parquet", pa.table(q_cols), kind="joint_states")
        derived = {"stamp_source": "derived", "offset_ns": 0}
        streams: dict[str, dict[str, Any]] = {
            "joint_states": {
                "kind": "joint_states",
                "path": f"{e}/joint_states.parquet",
                "nominal_rate_hz": _rate(traj.t_ns),
                "source": f"commanded: {traj.source}",
                **derived,
            },
        }
        ee_link = (src.manifest.get("robot") or {}).get("ee_link")
        if ee_link:
            chain = base_binding.chain
            T = chain.forward(torch.as_tensor(traj.q))[:, chain.link_index(ee_link)]
            qt = matrix_to_quat(T[:, :3, :3]).numpy()
            p = T[:, :3, 3].numpy()
            ee = {"t_ns": traj.t_ns, "link": pa.array([ee_link] * len(p), pa.string())}
            ee.update({c: p[:, i] for i, c in enumerate("xyz")})
            ee.update({c: qt[:, i] for i, c in enumerate(("qw", "qx", "qy", "qz"))})
            writer.write_table(f"{e}/ee_poses.parquet", pa.table(ee), kind="ee_poses")
            streams["ee_poses"] = {
                "kind": "ee_poses",
                "path": f"{e}/ee_poses.parquet",
                "nominal_rate_hz": _rate(traj.t_ns),
                "source": "forward kinematics of the commanded joints",
                **derived,
            }
        objects = _object_table(ep, traj.t_ns, object_poses)
        if objects is not None:
            writer.write_table(f"{e}/object_poses.parquet", objects, kind="object_poses")
            streams["object_poses"] = {
                "kind": "object_poses",
                "path": f"{e}/object_poses.parquet",
                "nominal_rate_hz": _rate(traj.t_ns),
                "source": obj_source,
                **derived,
            }
        writer.write_table(f"{e}/segments.parquet", ep.table("segments"), kind="segments")
        streams["segments"] = {
            "kind": "segments",
            "path": f"{e}/segments.parquet",
            "stamp_source": "none",
            "offset_ns": 0,
        }
        boxes: list[tuple[int, str, int, int, int, int, int, int]] = []
        total = len(t_f) * len(models)
        done = 0
        for model, pose_of, ext in models:
            if ext is None:
                writer.set_camera(model)
            else:
                writer.write_json(f"cameras/{model.name}.json", model.to_dict(), schema="camera")
                writer.manifest.setdefault("cameras", {})[model.name] = f"cameras/{model.name}.json"
            r = TrajectoryRenderer(
                src, ep, traj, model, pose_of=pose_of, backend=backend, binding=base_binding
            )
            cdir = f"{e}/cameras/{model.name}"
            pngs, dpngs, npngs, empty = [], [], [], 0
            with VideoWriter(writer.path(f"{cdir}/rgb.mp4"), model.width, model.height, fps) as vw:
                for k, t in enumerate(t_f):
                    fr = r.frame(int(t), normals=normals)
                    vw.write(fr.rgb)
                    pngs.append(encode_label_png(fr.labels))
                    mm = np.clip(np.round(fr.depth * 1000.0), 0, 65535).astype(np.uint16)
                    dpngs.append(encode_label_png(mm))
                    if normals:
                        assert fr.normals is not None
                        npngs.append(encode_normals_png(fr.normals))
                    found = label_boxes(fr.labels)
                    empty += not found
                    boxes += [(int(t), model.name, k, *b) for b in found]
                    done += 1
                    if progress is not None:
                        progress(done, total)
            idx = np.arange(len(t_f), dtype=np.int64)
            writer.write_table(
                f"{cdir}/frames.parquet",
                pa.table({"t_ns": t_f, "frame_index": idx}),
                kind="camera_frames",
            )
            writer.write_table(
                f"{cdir}/labels.parquet",
                pa.table({"frame_index": pa.array(idx), "png": pa.array(pngs, pa.binary())}),
                kind="camera_labels",
            )
            writer.write_table(
                f"{cdir}/depth.parquet",
                pa.table({"t_ns": t_f, "frame_index": idx, "png": pa.array(dpngs, pa.binary())}),
                kind="generic",
            )
            if normals:
                writer.write_table(
                    f"{cdir}/normals.parquet",
                    pa.table(
                        {"t_ns": t_f, "frame_index": idx, "png": pa.array(npngs, pa.binary())}
                    ),
                    kind="generic",
                )
                streams[f"normals/{model.name}"] = {
                    "kind": "generic",
                    "path": f"{cdir}/normals.parquet",
                    "nominal_rate_hz": _rate(t_f),
                    "source": "rendered splat normals, camera frame (OpenCV axes), "
                    "8-bit RGB PNG n*0.5+0.5 (0,0,0: none)",
                    **derived,
                }
            cam_stream: dict[str, Any] = {
                "kind": "camera",
                "camera": model.name,
                "frames": f"{cdir}/frames.parquet",
                "video": f"{cdir}/rgb.mp4",
                "labels": f"{cdir}/labels.parquet",
                "nominal_rate_hz": _rate(t_f),
                "source": "rendered from the bound splats",
                **derived,
            }
            if ext is not None:
                xt = {"t_ns": t_f}
                xt.update(
                    {c: ext[:, i] for i, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz"))}
                )
                writer.write_table(
                    f"{cdir}/extrinsics.parquet", pa.table(xt), kind="camera_extrinsics"
                )
                cam_stream["extrinsics"] = f"{cdir}/extrinsics.parquet"
            streams[f"camera/{model.name}"] = cam_stream
            streams[f"depth/{model.name}"] = {
                "kind": "generic",
                "path": f"{cdir}/depth.parquet",
                "nominal_rate_hz": _rate(t_f),
                "source": "rendered median depth, mm, 16-bit PNG (0: nothing)",
                **derived,
            }
            summary.frames[model.name] = len(t_f)
            summary.empty_frames[model.name] = empty
            if empty:
                summary.warnings.append(
                    f"camera {model.name!r} sees nothing in {empty} of {len(t_f)} frames "
                    "(it looks away from the scene or everything is behind it)"
                )
        if boxes:
            b = np.array([(x[0], x[2], *x[3:]) for x in boxes], np.int64)
            writer.write_table(
                f"{e}/boxes2d.parquet",
                pa.table(
                    {
                        "t_ns": b[:, 0],
                        "camera": pa.array([x[1] for x in boxes], pa.string()),
                        "frame_index": b[:, 1],
                        "label_id": b[:, 2].astype(np.int32),
                        **{
                            c: b[:, 3 + i].astype(np.float64)
                            for i, c in enumerate(("x_min", "y_min", "x_max", "y_max"))
                        },
                    }
                ),
                kind="boxes2d",
            )
            streams["boxes2d"] = {
                "kind": "boxes2d",
                "path": f"{e}/boxes2d.parquet",
                "nominal_rate_hz": None,
                "source": "rendered labels",
                **derived,
            }
        start = int(min(traj.t_ns[0], t_f[0]))
        end = int(max(traj.t_ns[-1], t_f[-1]))
        writer.add_episode(
            new_episode, start_ns=start, end_ns=end, streams=streams, segment=ep.segment
        )
        prov = dict(src.manifest.get("provenance") or {})
        before = (prov.get("rendered") or {}).get("episodes") or {} if keep_episodes else {}
        prov["rendered"] = {
            "source": src.name,
            "episodes": {
                **{k: v for k, v in before.items() if k in {e["id"] for e in kept}},
                new_episode: {
                    "joints": traj.source,
                    "objects": obj_source,
                    "cameras": names,
                    "backend": backend,
                },
            },
        }
        writer.manifest["provenance"] = prov
        writer.manifest["generator"] = {"command": "robogs render " + " ".join(sys.argv[2:])[:500]}
        writer.commit()
    if base_binding.chain_note:
        summary.notes.append(base_binding.chain_note)
    return summary
