"""``synthesize``: build a complete robogs dataset of a robot arm pushing a box.

Pipeline (all deterministic for a seed):

1. robot: the generated UR5 (with ``robot/mdh.json``) or an imported URDF, plus a
   spherical pusher link ``pusher_tip`` (the tool link);
2. plan pushes against the box simulation, solve IK at 100 Hz knots, spline the
   joints: this spline is the true joint trajectory;
3. simulate the box on a 1 ms grid with the tip path from forward kinematics;
4. sample sensor stamps with jitter (joint states 500 Hz, actions 125 Hz,
   mocap 120 Hz, camera 30 fps) and evaluate the true state at each stamp;
5. rasterise RGB and label frames at the camera stamps;
6. sample splats on the meshes at the rest state (the episode start), each with
   the colour its face shows in the frames at that state (sRGB-encoded and
   shaded, as 3DGS stores image colour; see ``splat_sampling``);
7. write everything through ``DatasetWriter``; the ground truth goes to
   ``<out>.ground_truth.json`` beside (never inside) the dataset.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import trimesh

from robogs.format.cameras import CameraModel
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.format.images import VideoWriter, encode_label_png
from robogs.format.splats import SplatSet

from . import scene
from .dynamics import BoxDynamics, simulate_push
from .plan import KNOT_DT, SIM_DT, PlanError, ik_knots, joint_spline, plan_pushes
from .primitives import float32_exact
from .raster import PinholeView
from .render_scene import MeshPart, SceneRenderer, label_boxes
from .rigid import invert_T, make_T, matrix_to_quat, quat_to_matrix, yaw_quat
from .robot_source import RobotAssets, generated_ur5, imported_robot
from .splat_sampling import (
    SurfaceSamples,
    check_spacing,
    concat_samples,
    sample_surface,
    splat_count,
)

__all__ = [
    "synthesize",
    "ground_truth_path",
    "NOISE",
    "JITTER_S",
    "RATES_HZ",
    "EPISODE_ID",
    "CAMERA_NAME",
]

EPISODE_ID = "ep000"
CAMERA_NAME = "cam0"
#: nominal sample rates (Hz)
RATES_HZ = {"joint_states": 500.0, "actions": 125.0, "object_poses": 120.0, "camera": 30.0}
#: half-width of the uniform stamp jitter (s)
JITTER_S = {"joint_states": 5e-5, "actions": 1e-4, "object_poses": 3e-4, "camera": 2e-3}
#: first nominal sample time after the episode start (s)
_FIRST_S = {"joint_states": 1e-3, "actions": 2e-3, "object_poses": 4e-3, "camera": 1e-2}
#: standard deviations of the measurement noise
NOISE = {
    "joint_position_rad": 1e-4,
    "joint_velocity_radps": 1e-3,
    "object_position_m": 2e-4,
    "object_rotation_rad": 5e-4,
}
#: the commanded position leads the measured one by this much (s)
ACTION_LEAD_S = 0.016
MU_STATIC, MU_DYNAMIC, MU_TOOL = 0.5, 0.4, 0.2
RESTITUTION = 0.1
OPACITY_LOGIT = 4.0


def ground_truth_path(out: str | Path) -> Path:
    """Where :func:`synthesize` writes the ground truth of the dataset at ``out`` (beside it)."""
    out = Path(out)
    return out.with_name(out.name + ".ground_truth.json")


@contextmanager
def _progress(enabled: bool, total: int) -> Iterator:
    if not enabled:
        yield lambda *a, **k: None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("[bold]synth[/] {task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        transient=True,
    ) as prog:
        task = prog.add_task("starting", total=total)

        def step(desc: str | None = None, advance: float = 1.0) -> None:
            prog.update(task, advance=advance, description=desc or prog.tasks[0].description)

        yield step


def _stamps(rng: np.random.Generator, stream: str, duration: float) -> np.ndarray:
    """Sensor stamps (s) of a stream: a nominal grid plus uniform jitter, inside [0, duration]."""
    period = 1.0 / RATES_HZ[stream]
    n = int(np.floor((duration - _FIRST_S[stream] - JITTER_S[stream]) / period)) + 1
    nominal = _FIRST_S[stream] + period * np.arange(n)
    return nominal + rng.uniform(-JITTER_S[stream], JITTER_S[stream], n)


def _to_ns(t: np.ndarray) -> np.ndarray:
    return scene.T0_NS + np.round(np.asarray(t) * 1e9).astype(np.int64)


def _box_pose_at(sim_t: np.ndarray, sim_states: np.ndarray, t: np.ndarray, hz: float) -> np.ndarray:
    """[N, 7] (x, y, z, qw, qx, qy, qz) of the box at times ``t`` by linear interpolation of the sim grid."""
    x = np.interp(t, sim_t, sim_states[:, 0])
    y = np.interp(t, sim_t, sim_states[:, 1])
    yaw = np.interp(t, sim_t, sim_states[:, 2])
    return np.concatenate([np.stack([x, y, np.full_like(x, hz)], 1), yaw_quat(yaw)], axis=1)


def _pose_T(pose7: np.ndarray) -> np.ndarray:
    return make_T(quat_to_matrix(pose7[3:]), pose7[:3])


def _noisy_poses(rng: np.random.Generator, poses: np.ndarray) -> np.ndarray:
    """Add position noise and a small random rotation (rotation-vector noise) to [N, 7] poses."""
    out = poses.copy()
    out[:, :3] += rng.normal(0.0, NOISE["object_position_m"], (len(poses), 3))
    rv = rng.normal(0.0, NOISE["object_rotation_rad"], (len(poses), 3))
    ang = np.linalg.norm(rv, axis=1)
    axis = rv / np.maximum(ang, 1e-300)[:, None]
    dq = np.concatenate([np.cos(ang / 2)[:, None], axis * np.sin(ang / 2)[:, None]], axis=1)
    w1, v1 = poses[:, 3], poses[:, 4:]
    w2, v2 = dq[:, 0], dq[:, 1:]
    w = w1 * w2 - (v1 * v2).sum(1)
    v = w1[:, None] * v2 + w2[:, None] * v1 + np.cross(v1, v2)
    q = np.concatenate([w[:, None], v], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    out[:, 3:] = q
    return out


def _camera(preset: scene.SizePreset) -> CameraModel:
    W, H = preset.width, preset.height
    f = 0.5 * W / np.tan(np.radians(scene.CAMERA_HFOV_DEG) / 2)
    return CameraModel(
        name=CAMERA_NAME,
        width=W,
        height=H,
        fx=float(f),
        fy=float(f),
        cx=W / 2,
        cy=H / 2,
        T_world_cam=scene.look_at(scene.CAMERA_EYE, scene.CAMERA_TARGET),
    )


def _splat_count(mesh: trimesh.Trimesh, spacing: float) -> int:
    return splat_count(float(mesh.area), spacing)


def _image_colors(part: MeshPart, T_world_part: np.ndarray) -> np.ndarray:
    """[F, 3] colour in [0, 1] of each face as the frames show it with the part at ``T_world_part``.

    The splats store this (sRGB-encoded, shaded) colour, not the linear base colour: in 3DGS
    the SH colour is the image colour (Kerbl et al. 2023).
    """
    return part.face_colors(np.asarray(T_world_part)[:3, :3]) / 255.0


def _splat_set(s: SurfaceSamples) -> SplatSet:
    n = len(s.means)
    return SplatSet(
        means=s.means.astype(np.float32),
        quats=s.quats.astype(np.float32),
        log_scales=s.log_scales.astype(np.float32),
        opacity_logits=np.full(n, OPACITY_LOGIT, np.float32),
        sh=s.sh_dc.astype(np.float32)[:, None, :],
        bind_id=s.bind_id.astype(np.int32),
        bind_face=s.bind_face.astype(np.int32),
        bind_uv=s.bind_uv.astype(np.float32),
        bind_offset=np.zeros(n, np.float32),
    )


@dataclass
class _Timeline:
    duration: float
    spline: Any
    sim_t: np.ndarray
    sim_states: np.ndarray
    pushes: list


def _plan_and_simulate(
    robot: RobotAssets, preset: scene.SizePreset, box: BoxDynamics, rng: np.random.Generator
) -> tuple[_Timeline, tuple[float, float, float]]:
    start = (
        scene.BOX_START[0] + rng.uniform(-0.02, 0.02),
        scene.BOX_START[1] + rng.uniform(-0.02, 0.02),
        scene.BOX_START[2] + rng.uniform(-0.3, 0.3),
    )
    plan = plan_pushes(preset.duration_s, box, start, (scene.BOX_START[0], 0.04), rng)
    t_knots = np.arange(0.0, plan.path.end_time + 1e-9, KNOT_DT)
    p_knots, _ = plan.path(t_knots)
    q_knots = ik_knots(robot.model, robot.tool_link, p_knots)
    spline = joint_spline(t_knots, q_knots)
    sim_t = np.arange(0.0, preset.duration_s + 1e-9, SIM_DT)
    T_tip = robot.model.fk(spline(sim_t))[robot.tool_link]
    tip = T_tip[:, :3, 3]
    tip_v = np.gradient(tip, SIM_DT, axis=0)
    states = simulate_push(box, start, tip, tip_v, SIM_DT)
    return _Timeline(preset.duration_s, spline, sim_t, states, plan.pushes), start


def synthesize(
    out: str | Path,
    *,
    seed: int = 0,
    size: str = "small",
    urdf: str | Path | None = None,
    overwrite: bool = False,
    progress: bool = True,
    package_roots: dict[str, str | Path] | None = None,
    splat_spacing_m: float | None = None,
) -> Path:
    """Generate the synthetic push scene as a robogs dataset at ``out``.

    Args:
        out: dataset folder to create (its parent must exist).
        seed: random seed; the same seed gives the same tables, images and splats.
        size: 'small' (4 s, 160x120), 'medium' (20 s, 320x240) or 'large' (60 s, 640x480).
        urdf: a real robot's URDF to use instead of the generated UR5.
        overwrite: replace an existing dataset at ``out``.
        progress: show a progress bar.
        package_roots: ``{package: folder}`` for ``package://`` URIs of ``urdf``.
        splat_spacing_m: mean surfel spacing, m (default: the size's, 10/6/4 mm); only the
            splats change (frames and tables are the same for a seed).

    Returns:
        ``out``. The ground truth is written to :func:`ground_truth_path` (``out`` + ``.ground_truth.json``).

    Raises:
        InputError: unknown size, spacing out of range, unreadable URDF or meshes.
        DatasetExistsError: ``out`` exists and ``overwrite`` is False.
    """
    if size not in scene.SIZES:
        raise InputError(f"unknown size {size!r}", hint=f"choose one of {', '.join(scene.SIZES)}")
    out = Path(out)
    preset = scene.SIZES[size]
    sp = preset.splat_spacing_m if splat_spacing_m is None else check_spacing(splat_spacing_m)
    rng = np.random.default_rng(seed)
    t_wall = time.perf_counter()
    robot = generated_ur5() if urdf is None else imported_robot(urdf, package_roots)
    model, tool = robot.model, robot.tool_link
    jn = model.joint_names
    box = BoxDynamics(
        scene.BOX_MASS,
        scene.BOX_SIZE,
        MU_STATIC,
        MU_DYNAMIC,
        robot.pusher_radius,
        table_top=scene.TABLE_TOP_Z,
        mu_tool=MU_TOOL,
    )
    hz = scene.TABLE_TOP_Z + 0.5 * scene.BOX_SIZE[2]
    cam = _camera(preset)
    cam_stamps = _stamps(rng, "camera", preset.duration_s)
    n_frames = len(cam_stamps)
    writer = Dataset.create(out, overwrite=overwrite, name=out.name)
    with writer, _progress(progress, n_frames + 5) as step:
        step("planning pushes", 0)
        try:
            tl, box_start = _plan_and_simulate(robot, preset, box, rng)
        except PlanError as exc:
            raise InputError(
                str(exc),
                path=urdf,
                hint="the arm must reach 0.3-0.7 m from its base on the "
                "table with the tool pointing down",
            ) from None
        step("sampling streams")
        D = preset.duration_s
        # -- joint states, ee poses, actions -------------------------------------------------
        tj = _stamps(rng, "joint_states", D)
        q_true = tl.spline(tj)
        qd_true = tl.spline(tj, 1)
        q_meas = q_true + rng.normal(0.0, NOISE["joint_position_rad"], q_true.shape)
        qd_meas = qd_true + rng.normal(0.0, NOISE["joint_velocity_radps"], q_true.shape)
        js = {"t_ns": _to_ns(tj)}
        js.update({f"position.{n}": q_meas[:, i] for i, n in enumerate(jn)})
        js.update({f"velocity.{n}": qd_meas[:, i] for i, n in enumerate(jn)})
        ep = f"episodes/{EPISODE_ID}"
        writer.write_table(f"{ep}/joint_states.parquet", pa.table(js), kind="joint_states")
        T_tool = model.fk(q_true)[tool]
        qt = matrix_to_quat(T_tool[:, :3, :3])
        ee = {
            "t_ns": _to_ns(tj),
            "link": pa.array([tool] * len(tj), pa.string()),
            "x": T_tool[:, 0, 3],
            "y": T_tool[:, 1, 3],
            "z": T_tool[:, 2, 3],
            "qw": qt[:, 0],
            "qx": qt[:, 1],
            "qy": qt[:, 2],
            "qz": qt[:, 3],
        }
        writer.write_table(f"{ep}/ee_poses.parquet", pa.table(ee), kind="ee_poses")
        ta = _stamps(rng, "actions", D)
        q_cmd = tl.spline(np.minimum(ta + ACTION_LEAD_S, tl.spline.x[-1]))
        act = {"t_ns": _to_ns(ta)}
        act.update({f"command.{n}": q_cmd[:, i] for i, n in enumerate(jn)})
        writer.write_table(f"{ep}/actions.parquet", pa.table(act), kind="actions")
        # -- object poses (mocap) -------------------------------------------------------------
        to = _stamps(rng, "object_poses", D)
        poses = _noisy_poses(rng, _box_pose_at(tl.sim_t, tl.sim_states, to, hz))
        op = {"t_ns": _to_ns(to), "object": pa.array(["box"] * len(to), pa.string())}
        op.update({c: poses[:, i] for i, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz"))})
        writer.write_table(f"{ep}/object_poses.parquet", pa.table(op), kind="object_poses")
        step("rendering")
        # -- meshes, labels, renderer ----------------------------------------------------------
        links = robot.visible_links
        link_label = {lk: i + 1 for i, lk in enumerate(links)}
        box_mesh = float32_exact(trimesh.creation.box(extents=np.asarray(scene.BOX_SIZE)))
        table_mesh = float32_exact(trimesh.creation.box(extents=np.asarray(scene.TABLE_SIZE)))
        T_table = make_T(None, np.asarray(scene.TABLE_CENTER))
        table_part = MeshPart("table", table_mesh, scene.LABEL_TABLE, scene.TABLE_COLOR)
        box_part = MeshPart("box", box_mesh, scene.LABEL_BOX, scene.BOX_COLOR)
        link_parts = {
            lk: MeshPart(lk, robot.meshes[lk], link_label[lk], robot.colors[lk]) for lk in links
        }
        view = PinholeView(
            cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, invert_T(cam.T_world_cam)
        )
        renderer = SceneRenderer(view, [(table_part, T_table)])
        q_frames = tl.spline(cam_stamps)
        link_T = model.fk(q_frames)
        box_frames = _box_pose_at(tl.sim_t, tl.sim_states, cam_stamps, hz)
        frame_ns = _to_ns(cam_stamps)
        cam_dir = f"{ep}/cameras/{CAMERA_NAME}"
        pngs, b2d_rows = [], []
        with VideoWriter(
            writer.path(f"{cam_dir}/rgb.mp4"), cam.width, cam.height, RATES_HZ["camera"]
        ) as vw:
            for f in range(n_frames):
                moving = [(link_parts[lk], link_T[lk][f]) for lk in links]
                moving.append((box_part, _pose_T(box_frames[f])))
                rgb, lab = renderer.frame(moving)
                vw.write(rgb)
                pngs.append(encode_label_png(lab))
                b2d_rows += [(frame_ns[f], f, *b) for b in label_boxes(lab)]
                step()
        step("writing tables")
        writer.write_table(
            f"{cam_dir}/frames.parquet",
            pa.table({"t_ns": frame_ns, "frame_index": np.arange(n_frames, dtype=np.int64)}),
            kind="camera_frames",
        )
        writer.write_table(
            f"{cam_dir}/labels.parquet",
            pa.table(
                {
                    "frame_index": pa.array(np.arange(n_frames, dtype=np.int64)),
                    "png": pa.array(pngs, pa.binary()),
                }
            ),
            kind="camera_labels",
        )
        b2d = np.array(b2d_rows, dtype=np.int64).reshape(-1, 7)
        writer.write_table(
            f"{ep}/boxes2d.parquet",
            pa.table(
                {
                    "t_ns": b2d[:, 0],
                    "camera": pa.array([CAMERA_NAME] * len(b2d), pa.string()),
                    "frame_index": b2d[:, 1],
                    "label_id": b2d[:, 2].astype(np.int32),
                    "x_min": b2d[:, 3].astype(np.float64),
                    "y_min": b2d[:, 4].astype(np.float64),
                    "x_max": b2d[:, 5].astype(np.float64),
                    "y_max": b2d[:, 6].astype(np.float64),
                }
            ),
            kind="boxes2d",
        )
        b3 = {"t_ns": frame_ns, "object": pa.array(["box"] * n_frames, pa.string())}
        b3.update(
            {c: box_frames[:, i] for i, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz"))}
        )
        b3.update(
            {f"size_{a}": np.full(n_frames, s) for a, s in zip("xyz", scene.BOX_SIZE, strict=True)}
        )
        writer.write_table(f"{ep}/boxes3d.parquet", pa.table(b3), kind="boxes3d")
        seg_names = [*links, "box", "table"]
        writer.write_table(
            f"{ep}/segments.parquet",
            pa.table(
                {
                    "label_id": pa.array(
                        [link_label[lk] for lk in links] + [scene.LABEL_BOX, scene.LABEL_TABLE],
                        pa.int32(),
                    ),
                    "category": pa.array(["robot"] * len(links) + ["box", "table"], pa.string()),
                    "instance": pa.array([link_label[lk] for lk in links] + [1, 1], pa.int32()),
                    "kind": pa.array(
                        ["robot_link"] * len(links) + ["object", "background"], pa.string()
                    ),
                    "target": pa.array(seg_names, pa.string()),
                }
            ),
            kind="segments",
        )
        # -- robot, assets, splats --------------------------------------------------------------
        step("splats and assets")
        writer.write_text("robot/robot.urdf", robot.urdf_text)
        for rel, data in robot.files.items():
            writer.write_bytes(rel, data)
        if robot.mdh is not None:
            writer.write_json("robot/mdh.json", robot.mdh, schema="mdh")
        writer.set_robot(
            "robot/robot.urdf",
            base_link=model.root,
            ee_link=tool,
            mdh_rel="robot/mdh.json" if robot.mdh is not None else None,
        )
        q_rest = tl.spline(np.array([0.0]))
        rest_T = model.fk(q_rest)
        box_rest = _box_pose_at(tl.sim_t, tl.sim_states, np.array([0.0]), hz)[0]
        table_rest = np.array([*scene.TABLE_CENTER, 1.0, 0.0, 0.0, 0.0])
        rest = {
            "t_ns": int(scene.T0_NS),
            "joint_positions": {n: float(q_rest[0, i]) for i, n in enumerate(jn)},
            "object_poses": {"box": box_rest.tolist(), "table": table_rest.tolist()},
        }
        rob_s = [
            sample_surface(
                np.asarray(robot.meshes[lk].vertices),
                np.asarray(robot.meshes[lk].faces),
                rest_T[lk][0],
                _splat_count(robot.meshes[lk], sp),
                _image_colors(link_parts[lk], rest_T[lk][0]),
                i,
                rng,
            )
            for i, lk in enumerate(links)
        ]
        writer.write_splats("robot/splats.ply", _splat_set(concat_samples(rob_s)))
        writer.manifest["robot"]["splats"] = {
            "path": "robot/splats.ply",
            "kind": "2dgs",
            "sh_degree": 0,
            "targets": list(links),
            "rest": rest,
        }
        for name, part, T_rest, kind in (
            ("box", box_part, _pose_T(box_rest), "object"),
            ("table", table_part, T_table, "table"),
        ):
            mesh = part.mesh
            writer.write_bytes(f"assets/{name}/mesh.ply", mesh.export(file_type="ply"))
            s = sample_surface(
                np.asarray(mesh.vertices),
                np.asarray(mesh.faces),
                T_rest,
                _splat_count(mesh, sp),
                _image_colors(part, T_rest),
                0,
                rng,
            )
            writer.write_splats(f"assets/{name}/splats.ply", _splat_set(s))
            static_pose = {} if kind == "object" else {"pose": _pose7(T_rest)}
            writer.set_asset(
                name,
                kind=kind,
                mesh=f"assets/{name}/mesh.ply",
                **static_pose,
                splats={
                    "path": f"assets/{name}/splats.ply",
                    "kind": "2dgs",
                    "sh_degree": 0,
                    "targets": [name],
                    "rest": rest,
                },
            )
        writer.set_camera(cam)
        writer.set_physics(_physics(robot, box))
        # -- manifest ------------------------------------------------------------------------
        start_ns = int(scene.T0_NS)
        end_ns = int(max(js["t_ns"][-1], act["t_ns"][-1], op["t_ns"][-1], frame_ns[-1]))
        streams = {
            "joint_states": {
                "kind": "joint_states",
                "path": f"{ep}/joint_states.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": RATES_HZ["joint_states"],
            },
            "actions": {
                "kind": "actions",
                "path": f"{ep}/actions.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": RATES_HZ["actions"],
                "command_kind": "position",
            },
            "ee_poses": {
                "kind": "ee_poses",
                "path": f"{ep}/ee_poses.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": RATES_HZ["joint_states"],
            },
            "object_poses": {
                "kind": "object_poses",
                "path": f"{ep}/object_poses.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": RATES_HZ["object_poses"],
                "source": "mocap",
            },
            "boxes2d": {
                "kind": "boxes2d",
                "path": f"{ep}/boxes2d.parquet",
                "stamp_source": "derived",
                "offset_ns": 0,
                "nominal_rate_hz": None,
                "source": f"{cam_dir}/labels.parquet",
            },
            "boxes3d": {
                "kind": "boxes3d",
                "path": f"{ep}/boxes3d.parquet",
                "stamp_source": "derived",
                "offset_ns": 0,
                "nominal_rate_hz": RATES_HZ["camera"],
                "source": "object_poses",
            },
            "segments": {
                "kind": "segments",
                "path": f"{ep}/segments.parquet",
                "stamp_source": "none",
                "offset_ns": 0,
            },
            f"camera/{CAMERA_NAME}": {
                "kind": "camera",
                "camera": CAMERA_NAME,
                "frames": f"{cam_dir}/frames.parquet",
                "video": f"{cam_dir}/rgb.mp4",
                "labels": f"{cam_dir}/labels.parquet",
                "stamp_source": "synthetic",
                "offset_ns": 0,
                "nominal_rate_hz": RATES_HZ["camera"],
            },
        }
        writer.add_episode(
            EPISODE_ID, start_ns=start_ns, end_ns=end_ns, streams=streams, segment="push"
        )
        writer.manifest["conventions"]["clock"] = "synthetic"
        cmd = (
            f"robogs synth {out.name} --seed {seed} --size {size}"
            + (f" --urdf {Path(urdf).name}" if urdf else "")
            + (f" --splat-spacing {sp:g}" if splat_spacing_m is not None else "")
        )
        writer.manifest["generator"] = {"command": cmd}
        writer.manifest["provenance"] = {
            "synthetic": True,
            "seed": int(seed),
            "size": size,
            "robot": "generated UR5 (published DH)" if urdf is None else Path(urdf).name,
            "splat_spacing_m": sp,
        }
        writer.commit()
        step("done")
    gt = _ground_truth(
        seed,
        size,
        robot,
        box,
        box_start,
        tl,
        cam,
        cam_stamps,
        q_frames,
        box_frames,
        rest,
        link_label,
        time.perf_counter() - t_wall,
    )
    ground_truth_path(out).write_text(json.dumps(gt, indent=1, sort_keys=True))
    return out


def _physics(robot: RobotAssets, box: BoxDynamics) -> dict[str, Any]:
    m = box.mass
    sx, sy, sz = box.size
    inertia = np.diag(
        [m * (sy**2 + sz**2) / 12, m * (sx**2 + sz**2) / 12, m * (sx**2 + sy**2) / 12]
    )
    return {
        "gravity_mps2": [0.0, 0.0, -9.81],
        "objects": {
            "box": {
                "equation": "rigid",
                "mass_kg": m,
                "com_m": [0.0, 0.0, 0.0],
                "inertia_kgm2": inertia.tolist(),
                "friction_static": box.mu_static,
                "friction_dynamic": box.mu_dynamic,
                "restitution": RESTITUTION,
                "damping_linear": 0.0,
                "damping_angular": 0.0,
                "size_m": list(box.size),
                "friction_model": "coulomb_ellipsoidal_limit_surface",
                "torsion_radius_m": box.torsion_radius,
            },
            "table": {
                "equation": "static",
                "friction_static": box.mu_static,
                "friction_dynamic": box.mu_dynamic,
                "restitution": RESTITUTION,
                "size_m": list(scene.TABLE_SIZE),
                "top_z_m": scene.TABLE_TOP_Z,
                "plane_z_m": scene.TABLE_TOP_Z,
            },
            # the keys the pushed-object model reads (spec 7.1); `contacts` below is the
            # simulator-facing record of the same tool
            "pusher": {
                "equation": "kinematic",
                "link": robot.tool_link,
                "shape": "sphere",
                "radius_m": robot.pusher_radius,
            },
        },
        "joints": {
            j.name: {"damping": j.damping, "friction": j.friction, "armature": 0.0}
            for j in robot.model.actuated_joints
        },
        "contacts": {
            "tool": {
                "link": robot.tool_link,
                "shape": "sphere",
                "radius_m": robot.pusher_radius,
                "object": "box",
                "friction": box.mu_tool,
                "stiffness_npm": box.stiffness,
                "damping_nspm": box.damping,
            }
        },
        "effects": [],
        "sensors": {CAMERA_NAME: {"time_offset_ns": 0}},
    }


def _ground_truth(
    seed: int,
    size: str,
    robot: RobotAssets,
    box: BoxDynamics,
    box_start: tuple[float, float, float],
    tl: _Timeline,
    cam: CameraModel,
    cam_stamps: np.ndarray,
    q_frames: np.ndarray,
    box_frames: np.ndarray,
    rest: dict[str, Any],
    link_label: dict[str, int],
    wall_s: float,
) -> dict[str, Any]:
    """The ``ground_truth.json`` record of a generated scene (the oracle the tests read).

    ``box_start`` is (x [m], y [m], yaw [rad]) in the world frame; ``cam_stamps`` are the camera
    stamps [s] after the scene's t0, ``q_frames`` [N, joints] (rad) and ``box_frames`` [N, 7]
    (x, y, z, qw, qx, qy, qz; world frame) the true joints and box pose at those stamps;
    ``wall_s`` the generation time [s].
    """
    end = tl.sim_states[-1]
    return {
        "seed": int(seed),
        "size": size,
        "duration_s": tl.duration,
        "t0_ns": int(scene.T0_NS),
        "generation_wall_s": round(float(wall_s), 3),
        "robot": {
            "source": robot.source,
            "joint_names": robot.model.joint_names,
            "tool_link": robot.tool_link,
            "pusher_radius_m": robot.pusher_radius,
            "base_link": robot.model.root,
            "flange_link": robot.extra.get("flange_link", "tool0"),
        },
        "table": {
            "top_z_m": scene.TABLE_TOP_Z,
            "size_m": list(scene.TABLE_SIZE),
            "center_m": list(scene.TABLE_CENTER),
        },
        "box": {
            "size_m": list(box.size),
            "mass_kg": box.mass,
            "mu_static": box.mu_static,
            "mu_dynamic": box.mu_dynamic,
            "torsion_radius_m": box.torsion_radius,
            "mu_tool": box.mu_tool,
            "tool_stiffness_npm": box.stiffness,
            "tool_damping_nspm": box.damping,
            "start_xy_yaw": list(box_start),
            "end_xy_yaw": [float(end[0]), float(end[1]), float(end[2])],
        },
        "labels": {
            **{lk: lab for lk, lab in link_label.items()},
            "box": scene.LABEL_BOX,
            "table": scene.LABEL_TABLE,
        },
        "camera": cam.to_dict(),
        "rest": rest,
        "noise": NOISE,
        "stamp_jitter_s": JITTER_S,
        "rates_hz": RATES_HZ,
        "action_lead_s": ACTION_LEAD_S,
        "pushes": [p.__dict__ for p in tl.pushes],
        "frames": {
            "t_ns": _to_ns(cam_stamps).tolist(),
            "q_true": q_frames.round(12).tolist(),
            "box_pose_true": box_frames.round(12).tolist(),
        },
    }


def _pose7(T: np.ndarray) -> list[float]:
    """[x, y, z, qw, qx, qy, qz] of a 4x4 rigid transform (for a static asset pose)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(T)[:3, :3]).as_quat()
    return [float(v) for v in (*np.asarray(T)[:3, 3], w, x, y, z)]
