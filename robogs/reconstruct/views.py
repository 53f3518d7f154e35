"""The input of a reconstruction: the static views of a dataset, their cameras and labels.

A *static capture* is any set of camera frames that see the scene in one state:

* a camera stream with time-varying extrinsics (a ``camera_extrinsics`` table), as the
  nerfstudio/COLMAP importers write (view i stamped ``t_ns = i``); or
* several cameras with static ``T_world_cam``.

When the episode records ``joint_states`` (and ``object_poses``), a frame counts as static only
if the joints are within ``static_tol_rad`` of the state at the first usable frame (and the
objects within ``static_tol_m``); the others are left out and counted. That first state is the
rest state of the reconstruction (the ``rest`` of the written splats).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import torch

from robogs.format.cameras import CameraModel
from robogs.format.dataset import Dataset, Episode
from robogs.format.errors import FormatError, InputError
from robogs.format.frames import quat_to_matrix
from robogs.format.interp import interp_linear, interp_pose
from robogs.format.render import Camera
from robogs.format.render.camera import DISTORTION_MODELS, camera_from_model
from robogs.format.rerender import read_label_frames, read_video_frames

__all__ = ["View", "Capture", "Segment", "load_capture", "split_heldout"]


@dataclass
class View:
    """One static frame.

    Attributes:
        key: ``"<camera>/<frame_index>"``, unique in the capture.
        camera_name: the stored camera.
        frame_index: frame of the camera stream.
        t_ns: its stamp on the dataset clock.
        camera: render camera (OpenCV axes, ``T_world_cam`` float64), at the capture scale.
        rgb: [H, W, 3] float32 in [0, 1].
        labels: [H, W] int64 panoptic ids (0 = unlabelled), or None.
    """

    key: str
    camera_name: str
    frame_index: int
    t_ns: int
    camera: Camera
    rgb: torch.Tensor
    labels: np.ndarray | None


@dataclass(frozen=True)
class Segment:
    """What a label id means: ``kind`` (robot_link/object/background) and ``target`` name."""

    label_id: int
    kind: str
    target: str


@dataclass
class Capture:
    """The static views of one episode and the state they show.

    Attributes:
        episode: the episode.
        views: views in a fixed order (camera name, then frame index).
        rest_t_ns: stamp of the state (the first usable view).
        joint_positions: joint -> rad or m at the rest state (empty without a robot).
        object_poses: object -> [x, y, z, qw, qx, qy, qz] at the rest state.
        segments: label id -> :class:`Segment`.
        skipped: reason -> number of frames left out.
    """

    episode: Episode
    views: list[View]
    rest_t_ns: int
    joint_positions: dict[str, float]
    object_poses: dict[str, list[float]]
    segments: dict[int, Segment]
    skipped: dict[str, int] = field(default_factory=dict)


def split_heldout(views: list[View], every: int) -> tuple[list[View], list[View]]:
    """(training, held-out): every ``every``-th view (0, every, 2 every, ...) is held out; 0 = none."""
    if every <= 0:
        return list(views), []
    held = [v for i, v in enumerate(views) if i % every == 0]
    train = [v for i, v in enumerate(views) if i % every != 0]
    return train, held


def _pose_T(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(np.asarray(q, np.float64) / max(float(np.linalg.norm(q)), 1e-12))
    T[:3, 3] = p
    return T


def _check_intrinsics(model: CameraModel, where: str, path: Any) -> None:
    vals = (model.fx, model.fy, model.cx, model.cy)
    if not all(math.isfinite(v) for v in vals) or model.fx <= 0 or model.fy <= 0:
        raise InputError(
            f"camera {model.name!r} has degenerate intrinsics fx={model.fx} fy={model.fy}",
            path=path,
            where=where,
            hint="focal lengths must be finite and > 0 px",
        )
    if model.width <= 0 or model.height <= 0:
        raise InputError(
            f"camera {model.name!r} has image size {model.width}x{model.height}",
            path=path,
            where=where,
        )
    if not (0.0 < model.cx < model.width and 0.0 < model.cy < model.height):
        raise InputError(
            f"camera {model.name!r} principal point ({model.cx:g}, {model.cy:g}) px lies outside its "
            f"{model.width}x{model.height} image",
            path=path,
            where=where,
            hint="intrinsics and image size disagree (were the images resized?)",
        )
    if model.distortion_model not in DISTORTION_MODELS:
        raise InputError(
            f"camera {model.name!r} uses the {model.distortion_model!r} lens model, which "
            "the renderer cannot train with",
            path=path,
            where=where,
            hint=f"undistort the images first; supported: {', '.join(sorted(DISTORTION_MODELS))}",
        )


def _camera_poses(
    ds: Dataset, ep: Episode, entry: dict[str, Any], model: CameraModel, t_ns: np.ndarray
) -> np.ndarray:
    """[F, 4, 4] ``T_world_cam`` of every frame; raises for frames without a pose."""
    where = f"episodes/{ep.id}/camera/{model.name}"
    if model.extrinsics == "unknown":
        raise InputError(
            f"camera {model.name!r} declares its extrinsics unknown (images only): the views "
            "have no poses",
            path=ds.manifest_path,
            where=where,
            hint="recover them by structure from motion (robogs convert IMAGES OUT --sfm), or "
            "import a COLMAP/nerfstudio capture",
        )
    if model.extrinsics == "time_varying":
        rel = entry.get("extrinsics")
        if not isinstance(rel, str):
            raise InputError(
                f"camera {model.name!r} has time-varying extrinsics but its stream has no "
                "extrinsics table: the views have no poses",
                path=ds.manifest_path,
                where=where,
                hint="add a camera_extrinsics table (t_ns, x, y, z, qw, qx, qy, qz)",
            )
        from robogs.format.dataset import read_parquet

        path = ds.resolve(rel, where=where)
        tab = read_parquet(path)
        et = tab.column("t_ns").to_numpy().astype(np.int64)
        if len(et) == 0:
            raise InputError("the extrinsics table is empty: the views have no poses", path=path)
        xyz = np.stack([tab.column(c).to_numpy() for c in "xyz"], -1).astype(np.float64)
        q = np.stack([tab.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1).astype(
            np.float64
        )
        bad = (t_ns < et[0]) | (t_ns > et[-1])
        if (
            not np.isfinite(xyz).all()
            or not np.isfinite(q).all()
            or (np.linalg.norm(q, axis=1) < 1e-9).any()
        ):
            raise InputError(
                "the extrinsics table has non-finite or zero-quaternion poses", path=path
            )
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{int(bad.sum())} of {len(t_ns)} frames of camera {model.name!r} have no pose "
                f"(first at t_ns={int(t_ns[k])}, extrinsics cover {int(et[0])}..{int(et[-1])})",
                path=path,
                hint="every view needs T_world_cam: extend the extrinsics table",
            )
        p, qq = interp_pose(t_ns, et, xyz, q, outside="clamp")
        return np.stack([_pose_T(p[i], qq[i]) for i in range(len(t_ns))])
    if model.T_world_cam is None:
        raise InputError(
            f"camera {model.name!r} has no T_world_cam: the views have no poses",
            path=ds.manifest_path,
            where=where,
            hint="calibrate the camera's extrinsics",
        )
    T = np.asarray(model.T_world_cam, np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InputError(
            f"camera {model.name!r} T_world_cam is not a finite 4x4 matrix", where=where
        )
    return np.repeat(T[None], len(t_ns), 0)


def _segments(ep: Episode) -> dict[int, Segment]:
    name = next((n for n, s in ep.streams.items() if s.get("kind") == "segments"), None)
    if name is None:
        return {}
    tab = ep.table(name)
    out = {}
    for lab, kind, target in zip(
        tab.column("label_id").to_pylist(),
        tab.column("kind").to_pylist(),
        tab.column("target").to_pylist(),
        strict=True,
    ):
        out.setdefault(int(lab), Segment(int(lab), str(kind), str(target or "")))
    return out


def _state(
    ep: Episode, joint_names: list[str], t: np.ndarray
) -> tuple[np.ndarray | None, dict[str, np.ndarray]]:
    """Joint positions [F, J] and object poses {name: [F, 7]} at stamps ``t`` (None/{} if not recorded)."""
    q = None
    if joint_names and any(s.get("kind") == "joint_states" for s in ep.streams.values()):
        name = next(n for n, s in ep.streams.items() if s.get("kind") == "joint_states")
        tab = ep.table(name)
        cols = [f"position.{j}" for j in joint_names]
        missing = [c for c in cols if c not in tab.column_names]
        if missing:
            raise FormatError(f"joint_states lacks {', '.join(missing)}", path=ep.table_path(name))
        ts = tab.column("t_ns").to_numpy().astype(np.int64)
        vals = np.stack([tab.column(c).to_numpy() for c in cols], -1).astype(np.float64)
        q = interp_linear(t, ts, vals, outside="clamp")
    objs: dict[str, np.ndarray] = {}
    name = next((n for n, s in ep.streams.items() if s.get("kind") == "object_poses"), None)
    if name is not None:
        tab = ep.table(name)
        who = np.asarray(tab.column("object").to_pylist())
        for obj in sorted(set(who.tolist())):
            m = who == obj
            ts = tab.column("t_ns").to_numpy()[m].astype(np.int64)
            xyz = np.stack([tab.column(c).to_numpy()[m] for c in "xyz"], -1)
            qq = np.stack([tab.column(c).to_numpy()[m] for c in ("qw", "qx", "qy", "qz")], -1)
            p, r = interp_pose(t, ts, xyz, qq, outside="clamp")
            objs[obj] = np.concatenate([p, r], -1)
    return q, objs


def load_capture(
    ds: Dataset,
    *,
    episode: str | None = None,
    cameras: list[str] | None = None,
    scale: float = 1.0,
    max_views: int | None = None,
    static_tol_rad: float = 1e-3,
    static_tol_m: float = 1e-3,
    require_labels: bool = True,
) -> Capture:
    """Read the static views of an episode (images decoded, cameras scaled by ``scale``).

    Raises:
        InputError: no camera streams or no video, views without poses, intrinsics that
            disagree with the images, label images of the wrong size, an empty label
            image (all pixels 0), fewer than two static views.
    """
    ep = ds.episode(episode)
    streams = {
        s["camera"]: s for s in ep.streams.values() if s.get("kind") == "camera" and "camera" in s
    }
    if cameras:
        unknown = sorted(set(cameras) - set(streams))
        if unknown:
            raise InputError(
                f"episode {ep.id!r} has no stream for camera(s) {', '.join(unknown)}",
                hint=f"available: {', '.join(sorted(streams)) or 'none'}",
            )
        streams = {c: streams[c] for c in cameras}
    if not streams:
        raise InputError(
            f"episode {ep.id!r} has no camera streams to reconstruct from",
            path=ds.manifest_path,
            hint="import a multi-view capture (robogs convert) first",
        )
    chain_joints: list[str] = []
    if ds.manifest.get("robot"):
        from robogs.format.kinematics import Chain

        chain_joints = list(Chain.from_urdf(ds.urdf(load_meshes=False)).joint_names)
    raw: list[tuple[str, int, int, np.ndarray, CameraModel, dict[str, Any]]] = []
    for cam_name, entry in sorted(streams.items()):
        model = ds.camera(cam_name)
        where = f"cameras/{cam_name}"
        _check_intrinsics(model, where, ds.manifest_path)
        if not isinstance(entry.get("video"), str):
            raise InputError(
                f"camera {cam_name!r} has no video in episode {ep.id!r}",
                path=ds.manifest_path,
                where=f"episodes/{ep.id}",
            )
        fr = ep.frames(cam_name)
        t = fr.column("t_ns").to_numpy().astype(np.int64)
        fi = fr.column("frame_index").to_numpy().astype(np.int64)
        poses = _camera_poses(ds, ep, entry, model, t)
        for k in range(len(t)):
            raw.append((cam_name, int(fi[k]), int(t[k]), poses[k], model, entry))
    if not raw:
        raise InputError(f"episode {ep.id!r} has no camera frames", path=ds.manifest_path)
    stamps = np.array([r[2] for r in raw], np.int64)
    q, objs = _state(ep, chain_joints, stamps)
    keep = np.ones(len(raw), bool)
    skipped: dict[str, int] = {}
    if q is not None:
        moved = np.abs(q - q[0]).max(axis=1) > static_tol_rad
        keep &= ~moved
        if moved.any():
            skipped["robot moved"] = int(moved.sum())
    for obj, P in objs.items():
        moved = np.linalg.norm(P[:, :3] - P[0, :3], axis=1) > static_tol_m
        if moved.any():
            skipped[f"{obj} moved"] = int((moved & keep).sum())
        keep &= ~moved
    idx = np.flatnonzero(keep)
    if max_views is not None and len(idx) > max_views:
        idx = idx[np.linspace(0, len(idx) - 1, max_views).round().astype(int)]
    if len(idx) < 2:
        raise InputError(
            f"only {len(idx)} static view(s) in episode {ep.id!r}; a reconstruction needs several",
            hint="capture the scene standing still from many viewpoints",
        )
    segments = _segments(ep)
    views: list[View] = []
    by_cam: dict[str, list[int]] = {}
    for k in idx:
        by_cam.setdefault(raw[k][0], []).append(int(k))
    for cam_name, ks in sorted(by_cam.items()):
        entry, model = raw[ks[0]][5], raw[ks[0]][4]
        wanted = {raw[k][1]: k for k in ks}
        rgbs = dict(read_video_frames(ep.video_path(cam_name), sorted(wanted)))
        missing = sorted(set(wanted) - set(rgbs))
        if missing:
            raise InputError(
                f"the video of camera {cam_name!r} lacks frames {missing[:5]}",
                path=ep.video_path(cam_name),
                hint="the frame table lists more frames than the video holds",
            )
        labs: dict[int, np.ndarray] = {}
        if isinstance(entry.get("labels"), str):
            labs = dict(read_label_frames(ep.labels_path(cam_name), sorted(wanted)))
        for fi_, k in sorted(wanted.items()):
            img = rgbs[fi_]
            if img.shape[:2] != (model.height, model.width):
                raise InputError(
                    f"frame {fi_} of camera {cam_name!r} is {img.shape[1]}x{img.shape[0]} px but "
                    f"its intrinsics are for {model.width}x{model.height}",
                    path=ep.video_path(cam_name),
                    hint="inconsistent intrinsics: fix the camera file or the video",
                )
            cam = camera_from_model(model, raw[k][3], scale)
            if (cam.width, cam.height) != (model.width, model.height):
                img = cv2.resize(img, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
            lab = labs.get(fi_)
            if lab is not None:
                if lab.shape != (model.height, model.width):
                    raise InputError(
                        f"label image of frame {fi_} is {lab.shape[1]}x{lab.shape[0]} px, camera "
                        f"{cam_name!r} is {model.width}x{model.height}",
                        path=ep.labels_path(cam_name),
                    )
                if lab.shape != (cam.height, cam.width):
                    lab = cv2.resize(lab, (cam.width, cam.height), interpolation=cv2.INTER_NEAREST)
                lab = lab.astype(np.int64)
            rgb = torch.from_numpy(np.ascontiguousarray(img)).to(torch.float32) / 255.0
            views.append(View(f"{cam_name}/{fi_}", cam_name, fi_, raw[k][2], cam, rgb, lab))
    if require_labels:
        with_labels = [v for v in views if v.labels is not None]
        if not with_labels:
            raise InputError(
                f"no camera of episode {ep.id!r} has panoptic labels; segmentation into links "
                "and objects needs them",
                hint="add labels.parquet to the camera streams",
            )
        empty = [v for v in with_labels if not (v.labels > 0).any()]
        if len(empty) == len(with_labels):
            raise InputError(
                "every label image is empty (all pixels 0): nothing to segment or bind",
                path=ep.labels_path(with_labels[0].camera_name),
                hint="label the robot links and objects, or check the label export",
            )
        if empty:
            # an empty mask would carve the whole visual hull in its view and vote every point
            # it sees "unlabelled"
            keys = ", ".join(v.key for v in empty[:5]) + (", ..." if len(empty) > 5 else "")
            raise InputError(
                f"{len(empty)} of {len(with_labels)} label images are empty (all pixels 0): {keys}",
                path=ep.labels_path(empty[0].camera_name),
                where=f"frame_index {empty[0].frame_index}",
                hint="label those frames, or leave their cameras out with --cameras",
            )
        if not segments:
            raise InputError(
                f"episode {ep.id!r} has no segments table mapping label ids to links and objects",
                hint="add segments.parquet (label_id, category, instance, kind, target)",
            )
    first = int(idx[0])
    joints = {} if q is None else {j: float(q[first, i]) for i, j in enumerate(chain_joints)}
    poses = {o: [float(x) for x in P[first]] for o, P in objs.items()}
    return Capture(ep, views, int(stamps[first]), joints, poses, segments, skipped)
