"""Initial Gaussians: samples on the URDF meshes, on the visual hull of the labels, or random.

* ``urdf``: area-uniform samples on every link's visual mesh at the recorded joint state (and,
  with ``use_assets``, on the asset meshes at their recorded poses); surfels lie in the faces.
* ``hull``: the visual hull of the labelled foreground (Laurentini 1994): voxels whose
  projection is foreground (label > 0) in every view that sees them, carved to its photo hull
  (``carve.py``, Kutulakos & Seitz 2000; ``carve_tau=None`` skips it); samples on the boundary
  that several views confirm, with normals from the smoothed occupancy gradient. Hull samples
  closer than two voxels to a mesh sample are dropped, so known geometry is not doubled.
* ``random``: uniform points in the workspace box (Kerbl et al. 2023 for scenes without SfM).

Colours are the mean of the pixels the points project to in the views where they face the
camera and are not hidden behind other points (a point z-buffer at the image resolution).
Scales are the mean distance to the 3 nearest samples (Kerbl et al. 2023).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import trimesh
from scipy.spatial import cKDTree

from robogs.format.dataset import Dataset
from robogs.format.frames import matrix_to_quat, quat_to_matrix
from robogs.format.render import rgb_to_sh_dc

from .carve import carve_photo_hull, refine_along_normals
from .robot_geometry import link_meshes
from .views import Capture, View

__all__ = ["InitConfig", "InitPoints", "workspace_bounds", "initial_points", "initial_tensors"]


@dataclass(frozen=True)
class InitConfig:
    """How to seed the Gaussians.

    Attributes:
        mode: ``auto`` (URDF meshes plus visual hull), ``urdf``, ``hull`` or ``random``.
        spacing_m: target distance between samples, m (None: 1/110 of the workspace diagonal).
        hull_resolution: voxels along the longest workspace axis for the visual hull (None: the
            workspace over half the spacing, 32..192).
        random_count: number of random points (``random`` mode).
        use_assets: also sample the asset meshes already in the dataset.
        carve_tau: colour tolerance (RGB in [0, 1]) of the space carving that shrinks the visual
            hull to its photo hull (``carve.py``); None: seed on the visual hull itself.
        seed: sampling seed.
    """

    mode: str = "auto"
    spacing_m: float | None = None
    hull_resolution: int | None = None
    random_count: int = 20_000
    use_assets: bool = False
    carve_tau: float | None = 0.03
    seed: int = 0


@dataclass
class InitPoints:
    """Seed points: positions [N, 3] (m, world), unit normals [N, 3] (or NaN), RGB [N, 3], and the
    workspace box (lo, hi) [3] they were drawn in."""

    points: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def _ray_centre(views: list[View]) -> tuple[np.ndarray, float]:
    """Least-squares point nearest to every optical axis, and the median camera distance to it."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    centres = []
    for v in views:
        T = v.camera.T_world_cam.numpy()
        c, d = T[:3, 3], T[:3, 2]
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ c
        centres.append(c)
    p = np.linalg.lstsq(A, b, rcond=None)[0]
    return p, float(np.median(np.linalg.norm(np.asarray(centres) - p, axis=1)))


def workspace_bounds(
    capture: Capture, extra_points: np.ndarray | None = None, views: list[View] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned box (lo, hi) [3] m holding the labelled scene, grown to hold ``extra_points``.

    The cameras look at the point nearest to all optical axes; the scene they all see lies within
    the median camera distance of it. With labels, the box shrinks to the part of a coarse (48^3)
    visual hull of the labelled foreground that at least 20 % of the views see and that is the
    first occupied voxel along the rays of at least 5 % of them (2 or more): the hull also holds
    the "shadow" behind objects (a deep cone under a table seen only from above, which single
    views glimpse through gaps of the coarse z-buffer) and the space just in front of a camera
    that only its neighbours see. Plus one coarse voxel;
    without labels, it is the box that the vertical field of view spans at the median distance.
    """
    views = capture.views if views is None else views
    p, dist = _ray_centre(views)
    lo, hi = p - dist, p + dist
    n_lab = sum(v.labels is not None for v in views)
    occ, vox = _hull_grid(views, lo, hi, 48, None, min_seen=max(2, math.ceil(0.2 * n_lab)))
    idx = np.argwhere(occ) if occ is not None else np.zeros((0, 3), int)
    if len(idx):  # frontmost for a few cameras: one may see a sliver of the hull's "shadow"
        idx = idx[_frontmost(lo + (idx + 0.5) * vox, views, vox, max(2, math.ceil(0.05 * n_lab)))]
    if len(idx):
        lo, hi = lo + (idx.min(0) - 1.0) * vox, lo + (idx.max(0) + 2.0) * vox
    else:
        half = min(math.atan(0.5 * v.camera.height / v.camera.fy) for v in views)
        r = dist * math.tan(half)
        lo, hi = p - r, p + r
    if extra_points is not None and len(extra_points):
        pad = 0.05 * np.linalg.norm(extra_points.max(0) - extra_points.min(0))
        lo = np.minimum(lo, extra_points.min(0) - pad)
        hi = np.maximum(hi, extra_points.max(0) + pad)
    return lo, hi


def _mesh_samples(
    meshes: list[trimesh.Trimesh], spacing: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    pts, nrm = [], []
    for k, m in enumerate(meshes):
        n = max(8, int(math.ceil(m.area / spacing**2)))
        p, f = trimesh.sample.sample_surface_even(m, n, radius=0.5 * spacing, seed=seed + k)
        pts.append(np.asarray(p))
        nrm.append(np.asarray(m.face_normals)[f])
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.concatenate(pts), np.concatenate(nrm)


def _project(pts: torch.Tensor, v: View) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pixel (col, row) float coordinates and camera depth of world points [N, 3] (float64)."""
    T = v.camera.T_world_cam
    pc = (pts - T[:3, 3]) @ T[:3, :3]
    z = pc[:, 2]
    zs = torch.where(z > 1e-9, z, torch.ones_like(z))
    u = v.camera.fx * pc[:, 0] / zs + v.camera.cx
    w = v.camera.fy * pc[:, 1] / zs + v.camera.cy
    return u, w, z


def _hull_grid(
    views: list[View],
    lo: np.ndarray,
    hi: np.ndarray,
    res: int,
    known: set[int] | None,
    min_seen: int = 2,
) -> tuple[np.ndarray | None, float]:
    """Occupancy [X, Y, Z] of the labelled foreground's visual hull (None without labels), voxel m.

    A voxel is kept when every view that sees it (inside the image, in front) labels it as
    foreground, and at least ``min_seen`` views see it. With ``known`` label ids (parts already seeded from
    meshes), it is also dropped unless more views see it as another label than as a known one:
    the hull's excess around the known parts (concavities, too few views) would be floaters.
    """
    if not any(v.labels is not None for v in views):
        return None, 0.0
    size = hi - lo
    vox = float(size.max()) / res
    dims = np.maximum(np.ceil(size / vox).astype(int), 2)
    axes = [
        torch.arange(d, dtype=torch.float64) * vox + lo[i] + 0.5 * vox for i, d in enumerate(dims)
    ]
    grid = torch.stack(torch.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    occ = torch.ones(len(grid), dtype=torch.bool)
    seen = torch.zeros(len(grid), dtype=torch.int32)
    votes = torch.zeros(len(grid), dtype=torch.int32)
    known_lut = torch.zeros(1 << 16, dtype=torch.bool)
    if known:
        known_lut[torch.tensor(sorted(known), dtype=torch.long)] = True
    alive = torch.arange(len(grid))  # voxels still in the hull: only they are projected
    for v in views:
        if v.labels is None:
            continue
        u, w, z = _project(grid[alive], v)
        H, W = v.labels.shape
        inside = (z > 0) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
        iu = u.clamp(0, W - 1).long()
        iw = w.clamp(0, H - 1).long()
        lab = torch.from_numpy(v.labels)[iw, iu]
        fg = lab > 0
        seen[alive] += inside.to(torch.int32)
        if known:
            is_known = known_lut[lab.clamp(0, (1 << 16) - 1)]
            votes[alive] += (inside & fg & ~is_known).to(torch.int32) - (inside & is_known).to(
                torch.int32
            )
        keep = ~inside | fg
        occ[alive[~keep]] = False
        alive = alive[keep]
    occ &= seen >= min_seen
    if known:
        occ &= votes > 0
    return occ.reshape(*dims).numpy(), vox


def _frontmost(points: np.ndarray, views: list[View], vox: float, min_views: int = 1) -> np.ndarray:
    """[N] bool: voxel centres that are the nearest occupied voxel along the rays of at least
    ``min_views`` cameras.

    Per view, a z-buffer of the centres at a resolution where a buffer pixel spans 1.5 voxels at
    the median depth (so the sampled centres leave no holes); a centre is frontmost where it lies
    within 1.5 voxels of the buffer.
    """
    P = torch.as_tensor(points, dtype=torch.float64)
    count = torch.zeros(len(P), dtype=torch.int32)
    for v in views:
        u, w, z = _project(P, v)
        H, W = v.rgb.shape[:2]
        inside = (z > 0) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
        if not inside.any():
            continue
        px_per_voxel = vox * v.camera.fx / float(z[inside].median())
        s = float(np.clip(1.0 / (1.5 * px_per_voxel), 0.01, 1.0))  # buffer pixel > 1 voxel
        Ws, Hs = max(1, int(W * s)), max(1, int(H * s))
        pix = (w * s).clamp(0, Hs - 1).long() * Ws + (u * s).clamp(0, Ws - 1).long()
        zbuf = torch.full((Hs * Ws,), float("inf"), dtype=torch.float64)
        zbuf.scatter_reduce_(0, pix[inside], z[inside], reduce="amin")
        count += (inside & (z <= zbuf[pix] + 1.5 * vox)).to(torch.int32)
    return (count >= min_views).numpy()


def _visual_hull(
    views: list[View],
    lo: np.ndarray,
    hi: np.ndarray,
    res: int,
    known: set[int] | None = None,
    carve_tau: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Boundary samples [M, 3] and outward normals of the visual hull (see :func:`_hull_grid`) that
    some camera sees; with ``carve_tau``, of its photo hull (``carve.carve_photo_hull``), where
    the photos confirm it."""
    occ, vox = _hull_grid(views, lo, hi, res, known)
    if occ is None or not occ.any():
        return np.zeros((0, 3)), np.zeros((0, 3))
    confirmed = None
    if carve_tau is not None:
        cr = carve_photo_hull(occ, lo, vox, views, known or set(), tau=carve_tau)
        occ, confirmed = cr.occupancy, cr.confirmed
        if not occ.any():
            return np.zeros((0, 3)), np.zeros((0, 3))
    vol = torch.from_numpy(occ).to(torch.float64)
    pad = torch.nn.functional.pad(vol[None, None], (1, 1, 1, 1, 1, 1))[0, 0]
    neigh_empty = torch.zeros_like(vol, dtype=torch.bool)
    for ax in range(3):
        for s in (0, 2):
            sl = [slice(1, -1)] * 3
            sl[ax] = slice(s, s + vol.shape[ax])
            neigh_empty |= pad[tuple(sl)] == 0
    surf = (vol > 0) & neigh_empty
    if confirmed is not None:
        surf &= torch.from_numpy(confirmed)
    smooth = torch.nn.functional.avg_pool3d(pad[None, None], 3, stride=1)[0, 0]
    g = torch.stack(torch.gradient(smooth, spacing=vox), -1)
    idx = torch.nonzero(surf)
    n = -g[idx[:, 0], idx[:, 1], idx[:, 2]]
    norm = n.norm(dim=1, keepdim=True)
    n = torch.where(norm > 1e-9, n / norm.clamp(min=1e-12), torch.full_like(n, float("nan")))
    p = (torch.as_tensor(lo) + (idx.to(torch.float64) + 0.5) * vox).numpy()
    if confirmed is not None:  # seen by several views already
        return p, n.numpy()
    seen = _frontmost(p, views, vox)  # hull boundary no camera sees would never be trained
    return p[seen], n.numpy()[seen]


def _point_colors(views: list[View], pts: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Mean pixel colour [N, 3] over the views where each point faces the camera and is frontmost."""
    P = torch.as_tensor(pts, dtype=torch.float64)
    N = torch.as_tensor(np.nan_to_num(normals), dtype=torch.float64)
    acc = torch.zeros(len(P), 3, dtype=torch.float64)
    cnt = torch.zeros(len(P), dtype=torch.float64)
    for v in views:
        u, w, z = _project(P, v)
        H, W = v.rgb.shape[:2]
        inside = (z > 0) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
        centre = v.camera.T_world_cam[:3, 3]
        facing = ((centre - P) * N).sum(1) > 0
        facing |= N.abs().sum(1) == 0
        pix = w.clamp(0, H - 1).long() * W + u.clamp(0, W - 1).long()
        zbuf = torch.full((H * W,), float("inf"), dtype=torch.float64)
        zbuf.scatter_reduce_(0, pix[inside], z[inside], reduce="amin")
        front = inside & (z <= zbuf[pix] * 1.02 + 1e-3)
        ok = front & facing
        acc[ok] += v.rgb.reshape(-1, 3).to(torch.float64)[pix[ok]]
        cnt[ok] += 1
    col = acc / cnt.clamp(min=1)[:, None]
    col[cnt == 0] = 0.5
    return col.numpy()


def initial_points(
    ds: Dataset, capture: Capture, train_views: list[View], cfg: InitConfig
) -> InitPoints:
    """Seed points for ``cfg.mode`` (see the module docstring)."""
    meshes: list[trimesh.Trimesh] = []
    known: set[int] = set()
    if cfg.mode in ("auto", "urdf") and ds.manifest.get("robot") and capture.joint_positions:
        lms = link_meshes(ds, capture.joint_positions)
        meshes += [lm.world_mesh() for lm in lms.values()]
        known |= {s.label_id for s in capture.segments.values() if s.target in lms}
    if cfg.use_assets:
        for name, entry in sorted(ds.assets.items()):
            if "mesh" not in entry:
                continue
            m = ds.mesh(name).copy()
            pose = capture.object_poses.get(name)
            if pose is not None:
                T = np.eye(4)
                T[:3, :3] = quat_to_matrix(np.asarray(pose[3:], np.float64))
                T[:3, 3] = pose[:3]
                m.apply_transform(T)
            meshes.append(m)
            known |= {s.label_id for s in capture.segments.values() if s.target == name}
    mesh_pts = np.concatenate([m.vertices for m in meshes]) if meshes else None
    lo, hi = workspace_bounds(capture, mesh_pts, train_views)
    spacing = cfg.spacing_m or float(np.linalg.norm(hi - lo)) / 110.0
    pts, nrm = _mesh_samples(meshes, spacing, cfg.seed)
    if cfg.mode in ("auto", "hull"):
        res = cfg.hull_resolution or int(np.clip(np.ceil(2.0 * (hi - lo).max() / spacing), 32, 192))
        hp, hn = _visual_hull(train_views, lo, hi, res, known, cfg.carve_tau)
        vox = float((hi - lo).max()) / res
        if len(pts) and len(hp):
            d, _ = cKDTree(pts).query(hp, k=1)
            far = d > 2.0 * vox
            hp, hn = hp[far], hn[far]
        if len(hp) and vox < spacing:  # thin hull samples to the target spacing
            keep = np.random.default_rng(cfg.seed).random(len(hp)) < (vox / spacing) ** 2
            hp, hn = hp[keep], hn[keep]
        if len(hp) and cfg.carve_tau is not None:  # photo-hull voxels: onto the surface
            hp, _ = refine_along_normals(hp, hn, train_views, vox, occluders=pts)
        pts, nrm = np.concatenate([pts, hp]), np.concatenate([nrm, hn])
    if cfg.mode == "random" or len(pts) == 0:
        rng = np.random.default_rng(cfg.seed)
        pts = lo + rng.random((cfg.random_count, 3)) * (hi - lo)
        nrm = np.full_like(pts, np.nan)
    colors = _point_colors(train_views, pts, nrm)
    return InitPoints(pts, nrm, colors, lo, hi)


def _quats_from_normals(normals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Quaternions (w, x, y, z) whose rotation maps +z to each normal (random where NaN)."""
    n = normals.copy()
    bad = ~np.isfinite(n).all(1)
    bad[~bad] = np.linalg.norm(n[~bad], axis=1) < 1e-9  # no gradient: no orientation either
    n[bad] = rng.normal(size=(int(bad.sum()), 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = np.cross(a, n)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    R = np.stack([t1, t2, n], axis=2)
    return matrix_to_quat(torch.as_tensor(R)).numpy()


def initial_tensors(
    init: InitPoints,
    *,
    kind: str,
    sh_degree: int,
    seed: int = 0,
    scale_factor: float = 0.5,
    device: torch.device | str = "cpu",
) -> dict[str, torch.Tensor]:
    """Parameter tensors (pre-activation) of the seed points, float32 on ``device``.

    Standard deviations are ``scale_factor`` times the mean distance to the 3 nearest seeds
    (Kerbl et al. use 1; half keeps surfels seeded on a surface from bleeding past its edges).
    """
    pts = init.points
    k = min(4, len(pts))
    d, _ = cKDTree(pts).query(pts, k=k)
    dist = scale_factor * np.maximum(d[:, 1:].mean(1) if k > 1 else np.full(len(pts), 1e-2), 1e-5)
    has_normal = np.isfinite(init.normals).all(1)
    rng = np.random.default_rng(seed)
    quats = _quats_from_normals(init.normals, rng)
    ns = 2 if kind == "2dgs" else 3
    log_scales = np.repeat(np.log(dist)[:, None], ns, 1)
    if ns == 3:
        log_scales[has_normal, 2] = np.log(dist[has_normal] * 0.1)
    opacity = np.where(has_normal, 0.5, 0.1)
    K = (sh_degree + 1) ** 2

    def t(x: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(np.ascontiguousarray(x), dtype=torch.float32, device=device)

    return {
        "means": t(pts),
        "quats": t(quats),
        "log_scales": t(log_scales),
        "opacity_logits": t(np.log(opacity / (1 - opacity))),
        "sh_dc": rgb_to_sh_dc(t(init.colors))[:, None, :],
        "sh_rest": torch.zeros(len(pts), K - 1, 3, dtype=torch.float32, device=device),
    }
