"""Novel-pose evaluation: the binding rendered at joint configurations never recorded, against
the synthetic scene's independent triangle rasteriser.

A test harness (used by ``test_novel_pose.py`` and ``bench/render.py``), not part of the
package: it is the one place that joins the renderer and the generator, which the packages keep
apart (``tests/core/test_import_rules.py``).

For a dataset written by :func:`robogs.synth.scene.synthesize` (generated UR5), each joint
configuration is rendered twice into the dataset's camera (optionally at ``scale`` times its
resolution):

* **ground truth**: the meshes of the generator's own robot (:func:`generated_ur5`, its own
  forward kinematics) and of the box and table, drawn by :mod:`robogs.synth.scene.raster`
  (z-buffered triangles, label per mesh);
* **binding**: the dataset's bound Gaussians posed by ``robogs.format``'s forward kinematics of
  the same joints (:class:`robogs.format.render_trajectory.TrajectoryRenderer`), the box at its
  rest pose in both.

They share nothing but the joint values, the camera and the rest state. The comparison is the
validator's (:func:`robogs.format.rerender.compare_frame`): per label, IoU outside a 2 px void
band around the true label edges and the symmetric mean boundary distance (px); plus the PSNR
of the rendered colour over the rendered foreground (:func:`foreground_psnr`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from robogs.format import Dataset
from robogs.format.cameras import CameraModel
from robogs.format.frames import quat_to_matrix
from robogs.synth.scene import scene as layout
from robogs.synth.scene.raster import PinholeView
from robogs.synth.scene.render_scene import MeshPart, SceneRenderer
from robogs.synth.scene.robot_source import generated_ur5

__all__ = ["SPACING_M", "PoseMetrics", "novel_configurations", "novel_pose_metrics"]

#: surfel spacing of the scene the test and bench build (``robogs synth --splat-spacing``), m.
#: At 2x the small camera (320x240, f = 266 px) 7 mm is 1.6 px at the 1.18 m working distance
#: (10 mm, the small preset's, is 2.3 px: above the 1.5 px boundary budget); bench/RESULTS.md
#: has the sweep (10/8/7/6/5 mm, worst link of 8 configurations per scene).
SPACING_M = 0.007


@dataclass(frozen=True)
class PoseMetrics:
    """Figures of one joint configuration.

    Attributes:
        q: [J] joint positions, rad.
        names: labelled targets compared (links with at least ``min_px`` true pixels).
        iou: [C] IoU per target (void band excluded); NaN where the union holds fewer than the
            validator's ``IOU_MIN_PIXELS`` (a sliver's IoU is not a measurement).
        boundary_px: [C] symmetric mean boundary distance per target, px.
        psnr_db: PSNR of the rendered colour over its foreground against the rasteriser's.
        min_distance_rad: distance (max-norm) to the nearest recorded joint state.
    """

    q: np.ndarray
    names: list[str]
    iou: np.ndarray
    boundary_px: np.ndarray
    psnr_db: float
    min_distance_rad: float


def novel_configurations(
    ds: Dataset, count: int, *, seed: int = 0, margin: float = 0.25
) -> np.ndarray:
    """``count`` joint vectors [count, J] at least ``margin`` rad (max-norm) from every recorded
    joint state: the rest pose plus uniform offsets of up to ±0.6 rad on the first four joints,
    rejection-sampled (deterministic for a seed)."""
    rest = ds.splat_entry("robot")["rest"]["joint_positions"]
    robot = generated_ur5()
    names = robot.model.joint_names
    q0 = np.array([rest[n] for n in names])
    js = ds.episode().table("joint_states")
    rec = np.stack([js.column(f"position.{n}").to_numpy() for n in names], -1)
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []
    while len(out) < count:
        q = q0.copy()
        q[:4] += rng.uniform(-0.6, 0.6, 4)
        if np.abs(rec - q).max(1).min() >= margin:
            out.append(q)
    return np.stack(out)


def _scaled(cam: CameraModel, scale: float) -> CameraModel:
    w, h = int(round(cam.width * scale)), int(round(cam.height * scale))
    sx, sy = w / cam.width, h / cam.height
    return CameraModel(
        cam.name, w, h, cam.fx * sx, cam.fy * sy, cam.cx * sx, cam.cy * sy,
        cam.distortion_model, tuple(cam.distortion), cam.T_world_cam, cam.extrinsics,
    )  # fmt: skip


def _pose_T(pose7: list[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = quat_to_matrix(np.asarray(pose7[3:], np.float64))
    T[:3, 3] = pose7[:3]
    return T


def novel_pose_metrics(
    dataset: str | Path,
    qs: np.ndarray,
    *,
    scale: float = 2.0,
    min_px: int = 40,
    binding_offset: np.ndarray | None = None,
) -> list[PoseMetrics]:
    """Compare the binding's render with the rasteriser's at each joint vector of ``qs``.

    Args:
        dataset: a dataset made by ``robogs synth`` with the generated UR5 (no ``--urdf``).
        qs: [K, J] joint vectors (rad), the generator's joint order (= the URDF's).
        scale: render both at this multiple of the camera resolution.
        min_px: targets with fewer true pixels (outside the void band) are not compared.
        binding_offset: [J] rad added to the joints of the binding's render only (a mutation
            the comparison must catch).
    """
    from robogs.format.checks.binding import IOU_MIN_PIXELS
    from robogs.format.render_trajectory import JointTrajectory, TrajectoryRenderer
    from robogs.format.rerender import compare_frame, foreground_psnr

    ds = Dataset.open(dataset)
    ep = ds.episode()
    robot = generated_ur5()
    names = robot.model.joint_names
    cam = _scaled(ds.camera(ds.camera_names[0]), scale)
    rest = ds.splat_entry("robot")["rest"]
    t0 = int(rest["t_ns"])
    links = robot.visible_links
    parts = {
        lk: MeshPart(lk, robot.meshes[lk], i + 1, robot.colors[lk]) for i, lk in enumerate(links)
    }
    box = MeshPart("box", ds.mesh("box"), layout.LABEL_BOX, layout.BOX_COLOR)
    table = MeshPart("table", ds.mesh("table"), layout.LABEL_TABLE, layout.TABLE_COLOR)
    T_box = _pose_T(rest["object_poses"]["box"])
    view = PinholeView(
        cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy,
        np.linalg.inv(np.asarray(cam.T_world_cam, np.float64)),
    )  # fmt: skip
    truth = SceneRenderer(view, [(table, _pose_T(rest["object_poses"]["table"]))])
    js = ep.table("joint_states")
    rec = np.stack([js.column(f"position.{n}").to_numpy() for n in names], -1)
    out: list[PoseMetrics] = []
    renderer = None
    for q in np.asarray(qs, np.float64):
        qb = q if binding_offset is None else q + np.asarray(binding_offset, np.float64)
        traj = JointTrajectory(
            np.array([t0, t0 + 1], np.int64), np.stack([qb, qb]), list(names), "novel"
        )
        if renderer is None:
            renderer = TrajectoryRenderer(ds, ep, traj, cam)
            pose = np.asarray(rest["object_poses"]["box"], np.float64)
            renderer.binding.set_object_poses(
                "box", np.array([t0, t0 + 1]), np.stack([pose[:3]] * 2), np.stack([pose[3:]] * 2)
            )
        else:
            renderer.binding._joint_stream = (  # same binding, next configuration
                torch.as_tensor(traj.t_ns),
                torch.as_tensor(traj.q, dtype=torch.float64),
            )
        T = robot.model.fk(q[None])
        rgb_true, lab_true = truth.frame([*((parts[lk], T[lk][0]) for lk in links), (box, T_box)])
        rr = renderer.rr
        with torch.no_grad():
            o = rr.render(t0)
        prob = rr.probabilities(o)
        ch = rr.channels
        lut = ch.lookup(int(lab_true.max()) + 1)
        m = compare_frame(prob, o.depth_median.cpu().numpy(), lut[lab_true], ch.count)
        keep = m.recorded >= min_px
        iou = np.where(m.union >= IOU_MIN_PIXELS, m.inter / np.maximum(m.union, 1), np.nan)
        bnd = np.where(
            m.boundary_count > 0, m.boundary_sum / np.maximum(m.boundary_count, 1), np.nan
        )
        out.append(
            PoseMetrics(
                q,
                [n for n, k in zip(ch.names, keep, strict=True) if k],
                iou[keep],
                bnd[keep],
                foreground_psnr(o.rgb.cpu().numpy(), o.alpha.cpu().numpy(), rgb_true),
                float(np.abs(rec - q).max(1).min()),
            )
        )
    return out
