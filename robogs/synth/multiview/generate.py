"""``synthesize_multiview``: a static multi-view capture of an arm and a box, with ground truth.

The scene stands still; a camera moves around it (a ``camera_extrinsics`` table, as the
nerfstudio/COLMAP importers write). View ``i`` is stamped ``t_ns = i`` (``stamp_source: none``);
``joint_states`` and ``object_poses`` hold the constant state at every stamp, so the binding
can pose the splats at any view. Colour is rasterised with ``robogs.synth.scene.raster`` (flat
two-sided Lambert shading) at ``supersample`` x the resolution and box-filtered down, so edges
are anti-aliased like a real camera's; label images sample pixel centres. Video is lossless
(FFV1 in Matroska) so held-out image metrics measure the reconstruction, not a codec.

Nothing here uses the toolkit's kinematics, renderer or checks: forward kinematics comes from
``robogs.synth.scene.chain`` and pixels from the generator's own triangle rasteriser.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pyarrow as pa
import trimesh

from robogs.format.cameras import CameraModel
from robogs.format.dataset import Dataset
from robogs.format.errors import InputError
from robogs.format.images import encode_label_png
from robogs.synth.scene.raster import FrameBuffers, PinholeView, rasterize, shade_faces
from robogs.synth.scene.rigid import invert_T, matrix_to_quat
from robogs.synth.scene.robot_source import RobotAssets, generated_ur5
from robogs.synth.scene.scene import look_at

from .two_link import two_link_robot

__all__ = [
    "synthesize_multiview",
    "MultiviewTruth",
    "truth_path",
    "write_truth",
    "read_truth_poses",
    "EPISODE_ID",
    "CAMERA_NAME",
    "LABEL_BOX",
    "LABEL_TABLE",
    "BACKGROUND_RGB",
]

EPISODE_ID = "static"
CAMERA_NAME = "orbit"
LABEL_BOX = 100
LABEL_TABLE = 200
#: uniform background, uint8 sRGB
BACKGROUND_RGB = (0, 0, 0)
_LIGHT = np.array([0.3, -0.5, 1.0]) / np.linalg.norm([0.3, -0.5, 1.0])
_BOX_COLOR = (0.15, 0.65, 0.25)
_TABLE_COLOR = (0.62, 0.45, 0.28)
#: table-top texture: tile edge (m) and its fixed seed (the scene is the same for every --seed)
_TABLE_TILE_M = 0.025
_TEXTURE_SEED = 20261126


@dataclass
class _Part:
    name: str
    label: int
    mesh: trimesh.Trimesh  # world frame at the static state
    rgb: tuple[float, float, float]
    T_world_part: np.ndarray
    face_rgb: np.ndarray | None = None  # [F, 3] linear RGB per face (default: ``rgb``)
    colors: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        n = np.asarray(self.mesh.face_normals)  # world frame
        if self.face_rgb is None:
            self.colors = shade_faces(n, np.asarray(self.rgb), _LIGHT)
            return
        lam = np.abs(n @ _LIGHT)  # flat two-sided Lambert, as ``shade_faces``, per face colour
        lin = np.clip((0.35 + 0.65 * lam)[:, None] * self.face_rgb, 0.0, 1.0)
        self.colors = np.round(255.0 * lin ** (1 / 2.2)).astype(np.uint8)


def _textured_table(
    size: tuple[float, float, float], tile: float, seed: int
) -> tuple[trimesh.Trimesh, np.ndarray]:
    """A box whose top is a grid of ``tile``-m squares of random tones (asset frame at its centre).

    A uniform table top is photo-consistent at any height inside its visual hull, and a
    repeating checker gives feature matching (structure from motion) ambiguous matches; real
    tables have irregular texture, and so does this one: every tile's tone is drawn
    independently (seeded), a wood-like brown scaled by a factor in [0.45, 1.35] with a little
    hue jitter, so no neighbourhood repeats.
    """
    sx, sy, sz = size
    box = trimesh.creation.box(extents=size)
    keep = np.asarray(box.face_normals)[:, 2] < 0.5  # all but the top face
    sides = box.submesh([np.flatnonzero(keep)], append=True, repair=False)
    nx, ny = int(round(sx / tile)), int(round(sy / tile))
    xs, ys = np.linspace(-sx / 2, sx / 2, nx + 1), np.linspace(-sy / 2, sy / 2, ny + 1)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    verts = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, sz / 2)], 1)
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b, c, d = a + (ny + 1), a + (ny + 2), a + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    top = trimesh.Trimesh(verts, faces, process=False)
    rng = np.random.default_rng(seed)
    tone = rng.uniform(0.45, 1.35, (nx * ny, 1)) * rng.uniform(0.85, 1.15, (nx * ny, 3))
    tiles = np.clip(np.asarray(_TABLE_COLOR) * tone, 0.0, 1.0)
    mesh = trimesh.util.concatenate([sides, top])
    rgb = np.concatenate([np.tile(_TABLE_COLOR, (len(sides.faces), 1)), np.tile(tiles, (2, 1))])
    return mesh, rgb


@dataclass
class MultiviewTruth:
    """Ground truth of a multi-view scene (kept outside the dataset).

    Attributes:
        meshes: target (link or object) -> mesh in the world frame at the static state, m.
        images: [V, H, W, 3] uint8 anti-aliased colour of every view (what the video holds).
        labels: [V, H, W] uint16 label ids.
        T_world_cam: [V, 4, 4] camera poses (OpenCV axes).
        K: [3, 3] intrinsics, px (pixel centres at +0.5).
        joint_positions: joint -> rad.
        object_poses: object -> [x, y, z, qw, qx, qy, qz].
        label_of: target -> label id.
        heldout: indices of the views a test should hold out (every 8th).
    """

    meshes: dict[str, trimesh.Trimesh]
    images: np.ndarray
    labels: np.ndarray
    T_world_cam: np.ndarray
    K: np.ndarray
    joint_positions: dict[str, float]
    object_poses: dict[str, list[float]]
    label_of: dict[str, int]
    heldout: list[int]
    _depth: list[np.ndarray] = field(default_factory=list, repr=False)

    @property
    def scene_mesh(self) -> trimesh.Trimesh:
        """All target meshes concatenated (world frame)."""
        return trimesh.util.concatenate(list(self.meshes.values()))

    def visible_surface_points(
        self, n: int, *, seed: int = 0, tol_m: float = 2e-3
    ) -> tuple[np.ndarray, np.ndarray]:
        """Area-uniform samples of the true surface that at least one view sees.

        Surfaces hidden in every view (faces inside another part, contact patches) are
        dropped, as in the DTU observation mask. A sample is seen by a view when it projects
        inside the image in front of the camera and its depth is within ``tol_m`` of the depth
        buffer there.

        Returns:
            points [M, 3] (m, world) and unit face normals [M, 3].
        """
        mesh = self.scene_mesh
        pts, fid = trimesh.sample.sample_surface(mesh, n, seed=seed)
        normals = np.asarray(mesh.face_normals)[fid]
        seen = np.zeros(len(pts), bool)
        for T, depth in zip(self.T_world_cam, self._depth, strict=True):
            Tcw = invert_T(T)
            pc = pts @ Tcw[:3, :3].T + Tcw[:3, 3]
            z = pc[:, 2]
            zs = np.where(z > 1e-6, z, 1.0)
            u = self.K[0, 0] * pc[:, 0] / zs + self.K[0, 2]
            v = self.K[1, 1] * pc[:, 1] / zs + self.K[1, 2]
            H, W = depth.shape
            ok = (z > 1e-6) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
            iu = np.clip(u.astype(np.int64), 0, W - 1)
            iv = np.clip(v.astype(np.int64), 0, H - 1)
            d = depth[iv, iu]
            seen |= ok & (d > 0) & (np.abs(d - z) < tol_m)
        return pts[seen], normals[seen]


def truth_path(out: str | Path) -> Path:
    """Where the ground truth of the capture at ``out`` goes: ``OUT.ground_truth.json`` beside it."""
    out = Path(out)
    return out.with_name(out.name + ".ground_truth.json")


def write_truth(truth: MultiviewTruth, out: str | Path) -> Path:
    """Write the truth beside the dataset ``out`` (never inside it); returns the JSON path.

    ``OUT.ground_truth.json`` holds the camera poses (``T_world_cam`` per view, OpenCV axes,
    world at the robot base, m), ``K`` (px), the joint and object rest state and the label ids;
    ``OUT.ground_truth.ply`` the true scene mesh (m, world), for mesh metrics.
    """
    import json
    import os

    path = truth_path(out)
    ply = path.with_suffix(".ply")
    doc = {
        "T_world_cam": np.asarray(truth.T_world_cam).tolist(),
        "K": np.asarray(truth.K).tolist(),
        "joint_positions": truth.joint_positions,
        "object_poses": truth.object_poses,
        "label_of": truth.label_of,
        "heldout": truth.heldout,
        "scene_mesh": ply.name,
        "scene_size_m": float(np.linalg.norm(np.ptp(truth.scene_mesh.vertices, axis=0))),
    }
    for target, data in ((ply, truth.scene_mesh.export(file_type="ply")), (path, None)):
        tmp = target.with_name(target.name + ".tmp")
        if data is None:
            tmp.write_text(json.dumps(doc, indent=1), encoding="utf-8")
        else:
            tmp.write_bytes(data)
        os.replace(tmp, target)
    return path


def read_truth_poses(path: str | Path) -> np.ndarray:
    """[V, 4, 4] true ``T_world_cam`` from a :func:`write_truth` JSON."""
    import json

    return np.asarray(json.loads(Path(path).read_text(encoding="utf-8"))["T_world_cam"])


def _fibonacci_directions(n: int, z_min: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` near-uniform unit vectors with z >= ``z_min`` (a Fibonacci lattice, random twist)."""
    i = np.arange(n) + 0.5
    z = 1.0 - (1.0 - z_min) * i / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = i * math.pi * (3.0 - math.sqrt(5.0)) + rng.uniform(0, 2 * math.pi)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def _orbit_poses(n: int, centre: np.ndarray, radius: float, z_min: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    dirs = _fibonacci_directions(n, z_min, rng)
    dirs[:, 2] = np.clip(dirs[:, 2], -0.97, 0.97)  # keep look_at away from the vertical
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    order = rng.permutation(n)
    return np.stack([look_at(tuple(centre + radius * d), tuple(centre)) for d in dirs[order]])


def _render(
    parts: list[_Part], T_world_cam: np.ndarray, K: np.ndarray, W: int, H: int, ss: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Anti-aliased RGB [H, W, 3] uint8, labels [H, W] uint16 and depth [H, W] (m, 0 = empty)."""
    verts, faces, labels, colors, off = [], [], [], [], 0
    for p in parts:
        verts.append(np.asarray(p.mesh.vertices, np.float64))
        faces.append(np.asarray(p.mesh.faces, np.int64) + off)
        labels.append(np.full(len(p.mesh.faces), p.label, np.uint16))
        colors.append(p.colors)
        off += len(p.mesh.vertices)
    V, F = np.concatenate(verts), np.concatenate(faces)
    L, C = np.concatenate(labels), np.concatenate(colors)
    Tcw = invert_T(T_world_cam)
    bg = np.broadcast_to(np.asarray(BACKGROUND_RGB, np.uint8), (H * ss, W * ss, 3))
    view_ss = PinholeView(
        W * ss, H * ss, K[0, 0] * ss, K[1, 1] * ss, K[0, 2] * ss, K[1, 2] * ss, Tcw
    )
    buf = FrameBuffers.empty(W * ss, H * ss, bg)
    rasterize(view_ss, V, F, L, C, buf)
    rgb = buf.rgb_image(W * ss, H * ss).astype(np.float64)
    rgb = rgb.reshape(H, ss, W, ss, 3).mean(axis=(1, 3))
    view = PinholeView(W, H, K[0, 0], K[1, 1], K[0, 2], K[1, 2], Tcw)
    buf1 = FrameBuffers.empty(W, H, np.broadcast_to(np.zeros(3, np.uint8), (H, W, 3)))
    rasterize(view, V, F, L, C, buf1)
    inv = buf1.inv_depth.reshape(H, W)
    depth = np.where(inv > 0, 1.0 / np.where(inv > 0, inv, 1.0), 0.0)
    return np.round(rgb).astype(np.uint8), buf1.label_image(W, H).copy(), depth


def _table(cols: dict) -> pa.Table:
    return pa.Table.from_pydict(cols)


def _pose7(T: np.ndarray) -> list[float]:
    return [*map(float, T[:3, 3]), *map(float, matrix_to_quat(T[:3, :3]))]


def _write_video(path: Path, frames: np.ndarray) -> None:
    """Lossless FFV1/Matroska colour video (frames RGB uint8)."""
    H, W = frames.shape[1:3]
    vw = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 1.0, (W, H))
    if not vw.isOpened():
        raise InputError(
            "OpenCV cannot write FFV1 video", path=path, hint="install opencv with FFmpeg"
        )
    for f in frames:
        vw.write(cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2BGR))
    vw.release()


def synthesize_multiview(
    out: str | Path,
    *,
    robot: str = "two_link",
    n_views: int = 32,
    width: int = 96,
    height: int = 72,
    hfov_deg: float = 50.0,
    supersample: int = 3,
    seed: int = 0,
    object_meshes: bool = False,
    overwrite: bool = False,
    poses: bool = True,
) -> MultiviewTruth:
    """Write a static multi-view robogs dataset and return its ground truth.

    Args:
        out: dataset folder to create.
        robot: ``"two_link"`` (procedural arm on a base, a box beside it, cameras on the whole
            sphere, nothing else) or ``"ur5"`` (the generated UR5 of ``robogs.synth.scene`` over a
            table with a randomly toned 2.5 cm tiled top and a box, cameras on the upper hemisphere).
        n_views: number of views (every 8th is listed in ``heldout``).
        width, height: image size, px.
        hfov_deg: horizontal field of view.
        supersample: colour is rendered at this factor and box-filtered.
        seed: camera lattice twist and order.
        object_meshes: also store the box (and table) meshes as asset meshes; by default the
            assets have none, as in a capture whose objects are to be reconstructed.
        overwrite: replace an existing folder.
        poses: write the camera poses (a ``camera_extrinsics`` table); False declares the
            camera's extrinsics ``unknown`` (images, intrinsics and labels only, as a handheld
            capture before structure from motion); the poses stay in the returned truth.
    """
    out = Path(out)
    if robot == "two_link":
        assets: RobotAssets = two_link_robot()
        q = np.array([[0.6, 0.9]])
        box_size, box_pose = (0.10, 0.08, 0.08), (0.22, 0.14, 0.04, 0.3)
        centre, radius, z_min = np.array([0.10, 0.06, 0.18]), 0.62, -0.9
        table = None
    elif robot == "ur5":
        assets = generated_ur5()
        q = np.array([[0.6, -1.6, 1.7, -1.6, -1.57, 0.0]])
        box_size, box_pose = (0.10, 0.08, 0.06), (0.46, 0.12, 0.03, 0.2)
        centre, radius, z_min = np.array([0.25, 0.05, 0.25]), 1.35, 0.15
        table = ((1.2, 1.0, 0.04), np.array([0.30, 0.0, -0.02]))
    else:
        raise InputError(f"unknown robot {robot!r}", hint='use "two_link" or "ur5"')
    model = assets.model
    links = assets.visible_links
    link_T = model.fk(q)
    label_of = {lk: i + 1 for i, lk in enumerate(links)}
    parts = [
        _Part(
            lk,
            label_of[lk],
            assets.meshes[lk].copy().apply_transform(link_T[lk][0]),
            assets.colors[lk],
            link_T[lk][0],
        )
        for lk in links
    ]
    T_box = np.eye(4)
    bx, by, bz, yaw = box_pose
    T_box[:3, :3] = trimesh.transformations.rotation_matrix(yaw, (0, 0, 1))[:3, :3]
    T_box[:3, 3] = (bx, by, bz)
    box_mesh = trimesh.creation.box(extents=box_size)
    parts.append(_Part("box", LABEL_BOX, box_mesh.copy().apply_transform(T_box), _BOX_COLOR, T_box))
    label_of["box"] = LABEL_BOX
    object_poses = {"box": _pose7(T_box)}
    if table is not None:
        T_table = np.eye(4)
        T_table[:3, 3] = table[1]
        table_mesh, table_rgb = _textured_table(table[0], _TABLE_TILE_M, _TEXTURE_SEED)
        parts.append(
            _Part(
                "table",
                LABEL_TABLE,
                table_mesh.copy().apply_transform(T_table),
                _TABLE_COLOR,
                T_table,
                face_rgb=table_rgb,
            )
        )
        label_of["table"] = LABEL_TABLE
        object_poses["table"] = _pose7(T_table)
    fx = 0.5 * width / math.tan(math.radians(hfov_deg) / 2)
    K = np.array([[fx, 0.0, 0.5 * width], [0.0, fx, 0.5 * height], [0.0, 0.0, 1.0]])
    cam_poses = _orbit_poses(n_views, centre, radius, z_min, seed)
    imgs, labs, depths = [], [], []
    for T in cam_poses:
        rgb, lab, depth = _render(parts, T, K, width, height, supersample)
        imgs.append(rgb)
        labs.append(lab)
        depths.append(depth)
    images, labels = np.stack(imgs), np.stack(labs)
    jn = model.joint_names
    stamps = np.arange(n_views, dtype=np.int64)
    ep = f"episodes/{EPISODE_ID}"
    cam_dir = f"{ep}/cameras/{CAMERA_NAME}"
    with Dataset.create(out, overwrite=overwrite, name=out.name) as w:
        w.write_text("robot/robot.urdf", assets.urdf_text)
        for rel, data in assets.files.items():
            w.write_bytes(rel, data)
        w.set_robot("robot/robot.urdf", base_link=model.root, ee_link=assets.tool_link)
        js = {"t_ns": stamps}
        js.update({f"position.{n}": np.full(n_views, q[0, i]) for i, n in enumerate(jn)})
        w.write_table(f"{ep}/joint_states.parquet", _table(js), kind="joint_states")
        names = sorted(object_poses)
        op = {
            "t_ns": np.repeat(stamps, len(names)),
            "object": pa.array(names * n_views, pa.string()),
        }
        vals = np.array([object_poses[n] for n in names] * n_views)
        op.update({c: vals[:, i] for i, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz"))})
        w.write_table(f"{ep}/object_poses.parquet", _table(op), kind="object_poses")
        seg_targets = [*links, "box"] + (["table"] if table is not None else [])
        w.write_table(
            f"{ep}/segments.parquet",
            _table(
                {
                    "label_id": pa.array([label_of[t] for t in seg_targets], pa.int32()),
                    "category": pa.array(
                        ["robot"] * len(links) + seg_targets[len(links) :], pa.string()
                    ),
                    "instance": pa.array(
                        [label_of[t] for t in links] + [1] * (len(seg_targets) - len(links)),
                        pa.int32(),
                    ),
                    "kind": pa.array(
                        ["robot_link"] * len(links)
                        + ["object"]
                        + (["background"] if table is not None else []),
                        pa.string(),
                    ),
                    "target": pa.array(seg_targets, pa.string()),
                }
            ),
            kind="segments",
        )
        w.write_table(
            f"{cam_dir}/frames.parquet",
            _table({"t_ns": stamps, "frame_index": np.arange(n_views, dtype=np.int64)}),
            kind="camera_frames",
        )
        w.write_table(
            f"{cam_dir}/labels.parquet",
            _table(
                {
                    "frame_index": pa.array(np.arange(n_views, dtype=np.int64)),
                    "png": pa.array([encode_label_png(x) for x in labels], pa.binary()),
                }
            ),
            kind="camera_labels",
        )
        if poses:
            ext = np.array([_pose7(T) for T in cam_poses])
            ex = {"t_ns": stamps}
            ex.update({c: ext[:, i] for i, c in enumerate(("x", "y", "z", "qw", "qx", "qy", "qz"))})
            w.write_table(f"{cam_dir}/extrinsics.parquet", _table(ex), kind="camera_extrinsics")
        _write_video(w.path(f"{cam_dir}/rgb.mkv"), images)
        w.set_camera(
            CameraModel(
                CAMERA_NAME,
                width,
                height,
                float(K[0, 0]),
                float(K[1, 1]),
                float(K[0, 2]),
                float(K[1, 2]),
                extrinsics="time_varying" if poses else "unknown",
            )
        )
        if object_meshes:
            w.write_bytes("assets/box/mesh.ply", box_mesh.export(file_type="ply"))
            w.set_asset("box", kind="object", mesh="assets/box/mesh.ply")
        else:
            w.set_asset("box", kind="object")
        m, (sx, sy, sz) = 0.4, box_size
        inertia = np.diag([sy**2 + sz**2, sx**2 + sz**2, sx**2 + sy**2]) * m / 12.0
        objects = {
            "box": {
                "equation": "rigid",
                "mass_kg": m,
                "com_m": [0.0, 0.0, 0.0],
                "inertia_kgm2": inertia.tolist(),
                "size_m": list(box_size),
            }
        }
        if table is not None:
            if object_meshes:
                w.write_bytes("assets/table/mesh.ply", table_mesh.export(file_type="ply"))
                w.set_asset("table", kind="table", mesh="assets/table/mesh.ply")
            else:
                w.set_asset("table", kind="table")
            objects["table"] = {"equation": "static"}
        w.set_physics({"gravity_mps2": [0.0, 0.0, -9.81], "objects": objects, "joints": {}})
        none = {"stamp_source": "none", "offset_ns": 0}
        streams = {
            "joint_states": {"kind": "joint_states", "path": f"{ep}/joint_states.parquet", **none},
            "object_poses": {"kind": "object_poses", "path": f"{ep}/object_poses.parquet", **none},
            "segments": {"kind": "segments", "path": f"{ep}/segments.parquet", **none},
            f"camera/{CAMERA_NAME}": {
                "kind": "camera",
                "camera": CAMERA_NAME,
                "frames": f"{cam_dir}/frames.parquet",
                "video": f"{cam_dir}/rgb.mkv",
                "labels": f"{cam_dir}/labels.parquet",
                **({"extrinsics": f"{cam_dir}/extrinsics.parquet"} if poses else {}),
                "nominal_rate_hz": None,
                "source": "robogs.synth.multiview",
                **none,
            },
        }
        w.add_episode(
            EPISODE_ID, start_ns=0, end_ns=int(n_views - 1), streams=streams, segment="static"
        )
        w.manifest["conventions"]["clock"] = "none (static capture: t_ns is the view ordinal)"
        w.manifest["generator"] = {
            "command": f"robogs.synth.multiview robot={robot} views={n_views} "
            f"size={width}x{height} seed={seed}" + ("" if poses else " poses=unknown")
        }
        w.manifest["provenance"] = {"synthetic": True, "multiview": robot, "seed": int(seed)}
        w.commit()
    return MultiviewTruth(
        meshes={p.name: p.mesh for p in parts},
        images=images,
        labels=labels,
        T_world_cam=cam_poses,
        K=K,
        joint_positions={n: float(q[0, i]) for i, n in enumerate(jn)},
        object_poses=object_poses,
        label_of=label_of,
        heldout=list(range(0, n_views, 8)),
        _depth=depths,
    )
