"""Space carving of a visual hull to its photo hull (Kutulakos & Seitz 2000), for seeding.

A visual hull is as large as the silhouettes allow: where every camera sees the scene from one
side (a robot on a table, cameras above), it is a slab above the table top, and its surface is
no surface at all. Space carving removes, layer by layer, the hull voxels that some views see
but whose colours (or labels) no single surface point could explain:

* **Visibility.** Per view, a z-buffer of the remaining voxels at a resolution where a buffer
  pixel spans 1.5 voxels; a voxel is seen where it lies within 1.5 voxels of the buffer and its
  pixel shows an *unknown* foreground label (not a link already seeded from the URDF, which
  would occlude it, nor background).
* **Footprint consistency** (Kutulakos & Seitz, §5: the voxel's footprint, not its centre). A
  surface that passes through a voxel is seen somewhere in its footprint: two views agree on a
  voxel if the ranges [min, max] of the colours over its footprints (a window of about one
  projected voxel) share a colour in every channel, within ``tau``, and the footprints share a
  label. Voxel quantisation and anti-aliased edges only widen the ranges.
* **Neighbouring views only.** A voxel holding an edge between two differently shaded faces
  shows one face to the views on one side and the other face to the rest: two far-apart views
  disagree, though the voxel is on the surface, and carving it would expose an inside that
  disagrees in the same way until the object is eaten away. For a right-angled edge the views
  that see only one face and those that see only the other are 90 deg apart; views closer
  than that see the same face or the edge region of both in their footprints. So only pairs
  of views less than ``max_angle_deg`` apart (as seen from the voxel) are compared: a voxel is
  inconsistent when two such views disagree. Above a textured table neighbouring views are
  close, but their rays through the voxel meet the table centimetres apart: carved. The
  default of 35 deg keeps a six-shaded box seen from all around whole (45 deg starts to
  nibble at it, 60 deg eats it; see ``tests/reconstruct/test_carve.py``).
* **Carving.** Inconsistent voxels are removed and visibility is recomputed, until no voxel is
  carved. Voxels seen by fewer than ``min_views`` views are not judged; those judged consistent
  in the last pass are the *confirmed* surface. A verdict depends only on the set of views that
  see the voxel (its footprints are fixed), so a pass re-judges only the voxels whose set
  changed or that just reached the surface: the same result as judging all of them, 2-3x
  faster on the UR5 sample.

Only the seeds come from this: training moves them. The result is conservative (a textureless
region stays where the silhouettes put it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from .views import View

__all__ = ["CarveResult", "carve_photo_hull", "refine_along_normals"]


@dataclass
class CarveResult:
    """The carving.

    Attributes:
        occupancy: [X, Y, Z] bool, the carved hull.
        confirmed: [X, Y, Z] bool, its voxels that ``min_views`` views saw consistent in the
            last pass (the surface that the photos support; the rest is only not refuted).
        carved: voxels removed.
        iterations: passes run.
    """

    occupancy: np.ndarray
    confirmed: np.ndarray
    carved: int
    iterations: int


def _project(pts: torch.Tensor, v: View) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pixel (col, row) float coordinates and camera depth of world points [N, 3] (float64)."""
    T = v.camera.T_world_cam.to(torch.float64)
    pc = (pts - T[:3, 3]) @ T[:3, :3]
    z = pc[:, 2]
    zs = torch.where(z > 1e-9, z, torch.ones_like(z))
    return v.camera.fx * pc[:, 0] / zs + v.camera.cx, v.camera.fy * pc[:, 1] / zs + v.camera.cy, z


@dataclass
class _Footprints:
    """Per view and pixel (flattened): min and max colour over the footprint window [HW, 3]
    (uint8; only pixels of unknown labels count), which unknown labels the window holds [HW, K],
    and whether the pixel itself shows one [HW]."""

    cmin: torch.Tensor
    cmax: torch.Tensor
    labels: torch.Tensor
    usable: torch.Tensor


def _footprints(v: View, k: int, unknown: torch.Tensor) -> _Footprints:
    lab = torch.from_numpy(v.labels).clamp(0, (1 << 16) - 1)
    idx = unknown[lab]  # [H, W] 0..K-1, -1 = known link or background
    K = int(unknown.max()) + 1
    ok = idx >= 0
    rgb = v.rgb.to(torch.float32)
    big = torch.tensor(4.0)
    lo = torch.where(ok[..., None], rgb, big).permute(2, 0, 1)[None]
    hi = torch.where(ok[..., None], rgb, -big).permute(2, 0, 1)[None]
    onehot = torch.zeros(v.labels.shape + (K,), dtype=torch.float32)
    onehot[ok] = F.one_hot(idx[ok], K).to(torch.float32)
    pad = k // 2
    cmin = -F.max_pool2d(-lo, k, stride=1, padding=pad)[0].permute(1, 2, 0)
    cmax = F.max_pool2d(hi, k, stride=1, padding=pad)[0].permute(1, 2, 0)
    labs = F.max_pool2d(onehot.permute(2, 0, 1)[None], k, stride=1, padding=pad)[0]
    labs = labs.permute(1, 2, 0) > 0
    H, W = v.labels.shape

    def q(x: torch.Tensor) -> torch.Tensor:  # 1/255 steps in a byte (4 and -4 mark "none")
        return (x[:H, :W].clamp(0, 1) * 255).round().to(torch.uint8).reshape(-1, 3)

    return _Footprints(q(cmin), q(cmax), labs[:H, :W].reshape(H * W, K), ok.reshape(-1))


def carve_photo_hull(
    occupancy: np.ndarray,
    lo: np.ndarray,
    voxel: float,
    views: list[View],
    known: set[int],
    *,
    tau: float = 0.03,
    min_views: int = 3,
    max_angle_deg: float = 35.0,
    max_iterations: int = 64,
) -> CarveResult:
    """Carve ``occupancy`` (voxel (i, j, k) centred at ``lo + (ijk + 0.5) voxel``) to its photo hull.

    Args:
        occupancy: [X, Y, Z] bool visual hull of the unknown parts.
        lo: [3] grid corner, m (world).
        voxel: voxel edge, m.
        views: labelled training views (views without labels are not used).
        known: label ids of parts seeded otherwise (URDF links): their pixels occlude.
        tau: colour tolerance in [0, 1] RGB.
        min_views: views that must see a voxel before it may be carved.
        max_angle_deg: views farther apart than this (seen from the voxel) are not compared.
        max_iterations: carving passes at most.
    """
    occ = occupancy.copy()
    idx = np.argwhere(occ)
    views = [v for v in views if v.labels is not None]
    none = np.zeros_like(occ)
    if not len(idx) or len(views) < 2:
        return CarveResult(occ, none, 0, 0)
    P = torch.as_tensor(lo + (idx + 0.5) * voxel, dtype=torch.float64)
    max_label = max(int(v.labels.max()) for v in views)
    unknown = torch.full((max(max_label + 1, 1 << 16),), -1, dtype=torch.long)
    ids = sorted(
        {int(x) for v in views for x in np.unique(v.labels)} - set(known) - {0}
    )  # labels a voxel of the unknown parts may show
    if not ids:
        return CarveResult(occ, none, 0, 0)
    unknown[torch.tensor(ids)] = torch.arange(len(ids))
    # per view: footprint tables and z-buffer geometry (projections are redone per pass)
    tables = []
    for v in views:
        _, _, z = _project(P, v)
        zin = z[z > v.camera.near]
        if not len(zin):
            continue
        px_per_voxel = voxel * v.camera.fx / float(zin.median())
        k = max(3, int(np.ceil(px_per_voxel)) | 1)  # odd window of about a projected voxel
        s = float(np.clip(1.0 / (1.5 * px_per_voxel), 0.01, 1.0))  # buffer pixel: 1.5 voxels
        tables.append((v, s, _footprints(v, k, unknown)))
    # pairs of views that may be within max_angle_deg of each other for some voxel: the angle
    # at the scene centre plus the largest angle the box subtends at a camera
    C = torch.stack([v.camera.T_world_cam[:3, 3].to(torch.float64) for v, _, _ in tables])
    centre, radius = P.mean(0), float((P - P.mean(0)).norm(dim=1).max())
    dirs = C - centre
    dist = dirs.norm(dim=1)
    dirs = dirs / dist[:, None]
    slack = torch.asin((radius / dist).clamp(max=1.0))
    ang = torch.acos((dirs @ dirs.T).clamp(-1, 1))
    near = ang <= np.radians(max_angle_deg) + slack[:, None] + slack[None, :]
    cos_max = float(np.cos(np.radians(max_angle_deg)))
    V = len(tables)
    # every view's footprint tables end to end: view t's pixel p is row offsets[t] + p
    sizes = torch.tensor([len(fp.usable) for _, _, fp in tables])
    offsets = torch.cumsum(sizes, 0) - sizes
    all_cmin = torch.cat([fp.cmin for _, _, fp in tables])
    all_cmax = torch.cat([fp.cmax for _, _, fp in tables])
    all_labs = torch.cat([fp.labels for _, _, fp in tables])
    partners = [  # per view i: the views j > i it is compared with
        torch.as_tensor([j for j in range(i + 1, V) if near[i, j]], dtype=torch.long)
        for i in range(V)
    ]
    alive = torch.ones(len(P), dtype=torch.bool)
    # a voxel's verdict depends only on which views see it (its footprints are fixed), and
    # carving only uncovers: a voxel is judged again only when that set changes
    words = (V + 61) // 62
    seen_sig = torch.zeros(len(P), words, dtype=torch.int64)
    judged_once = torch.zeros(len(P), dtype=torch.bool)
    consistent = torch.zeros(len(P), dtype=torch.bool)
    bit = torch.tensor([1 << (t % 62) for t in range(V)], dtype=torch.int64)
    grid = torch.full(occ.shape, -1, dtype=torch.long)
    grid[tuple(torch.as_tensor(idx).T)] = torch.arange(len(P))
    carved_total = 0
    iterations = 0
    tol = round(tau * 255)
    for _ in range(max_iterations):
        iterations += 1
        # only the shell of the remaining voxels can be first along a ray
        vol = torch.zeros(occ.shape, dtype=torch.float32)
        vol[tuple(torch.as_tensor(idx[alive.numpy()]).T)] = 1.0
        empty_near = F.max_pool3d(1.0 - F.pad(vol, (1,) * 6)[None, None], 3, stride=1)[0, 0]
        act_idx = grid[(vol > 0) & (empty_near > 0)]
        Pa = P[act_idx]
        M = len(Pa)
        seen_by = torch.zeros(V, M, dtype=torch.bool)
        pix_by = torch.zeros(V, M, dtype=torch.long)
        sig = torch.zeros(M, words, dtype=torch.int64)
        for t, (v, s, fp) in enumerate(tables):
            u, w, z = _project(Pa, v)
            H, W = v.labels.shape
            inside = (z > v.camera.near) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
            Ws, Hs = max(1, int(W * s)), max(1, int(H * s))
            bpix = (w * s).clamp(0, Hs - 1).long() * Ws + (u * s).clamp(0, Ws - 1).long()
            zbuf = torch.full((Hs * Ws,), float("inf"), dtype=torch.float64)
            zbuf.scatter_reduce_(0, bpix[inside], z[inside], reduce="amin")
            seen = inside & (z <= zbuf[bpix] + 1.5 * voxel)
            pix = w.long().clamp(0, H - 1) * W + u.long().clamp(0, W - 1)
            seen &= fp.labels[pix].any(1)
            seen_by[t] = seen
            pix_by[t] = pix
            sig[:, t // 62] |= seen.to(torch.int64) * bit[t]
        todo = ~judged_once[act_idx] | (sig != seen_sig[act_idx]).any(1)
        sub = torch.nonzero(todo)[:, 0]
        S = seen_by[:, sub]
        D = C[:, None, :] - Pa[sub][None]  # [V, Ms, 3] unit directions voxel -> camera
        D /= D.norm(dim=2, keepdim=True)
        bad = torch.zeros(len(sub), dtype=torch.bool)
        for i, js in enumerate(partners):
            if not len(js):
                continue
            jj, m = torch.nonzero(S[i][None] & S[js], as_tuple=True)
            if not len(m):
                continue
            j = js[jj]
            close = (D[i, m] * D[j, m]).sum(1) >= cos_max
            j, m = j[close], m[close]
            gi = offsets[i] + pix_by[i, sub[m]]
            gj = offsets[j] + pix_by[j, sub[m]]
            gap = torch.maximum(all_cmin[gi], all_cmin[gj]).to(torch.int16) - torch.minimum(
                all_cmax[gi], all_cmax[gj]
            ).to(torch.int16)
            differ = (gap > tol).any(1) | ~(all_labs[gi] & all_labs[gj]).any(1)
            bad[m[differ]] = True
        judged = S.sum(0) >= min_views
        bad &= judged
        g = act_idx[sub]
        seen_sig[g] = sig[sub]
        judged_once[g] = True
        consistent[g] = judged & ~bad
        nb_bad = int(bad.sum())
        if nb_bad == 0:
            break
        alive[g[bad]] = False
        carved_total += nb_bad
    confirmed = torch.zeros(len(P), dtype=torch.bool)
    confirmed[act_idx] = consistent[act_idx]
    out = np.zeros_like(occ)
    out[tuple(idx[alive.numpy()].T)] = True
    conf = np.zeros_like(occ)
    conf[tuple(idx[(alive & confirmed).numpy()].T)] = True
    return CarveResult(out, conf, carved_total, iterations)


def _bilinear(img: torch.Tensor, u: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Colours [N, 3] of ``img`` [H, W, 3] at pixel-edge coordinates (col ``u``, row ``w``)."""
    H, W = img.shape[:2]
    x = (u - 0.5).clamp(0, W - 1)
    y = (w - 0.5).clamp(0, H - 1)
    x0 = x.floor().long().clamp(max=W - 2) if W > 1 else x.floor().long()
    y0 = y.floor().long().clamp(max=H - 2) if H > 1 else y.floor().long()
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x1, y1 = (x0 + 1).clamp(max=W - 1), (y0 + 1).clamp(max=H - 1)
    im = img.to(torch.float64)
    top = im[y0, x0] * (1 - fx) + im[y0, x1] * fx
    bot = im[y1, x0] * (1 - fx) + im[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def refine_along_normals(
    points: np.ndarray,
    normals: np.ndarray,
    views: list[View],
    voxel: float,
    *,
    occluders: np.ndarray | None = None,
    reach_voxels: float = 1.0,
    steps: int = 9,
    min_views: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Slide surface seeds along their normals to where the views agree best (sub-voxel).

    The carving keeps a voxel when its footprints agree, so the photo hull's surface voxels lie
    up to a voxel outside the true surface (measured: the sample's table seeds 9 mm = one voxel
    above its top). Each seed is moved by the offset in [-reach, +reach] voxels along its
    normal whose colours, sampled bilinearly in the views that see the seed (frontmost in a
    z-buffer of the seeds and ``occluders``, facing the camera), have the least variance: a
    plane sweep per seed (Collins 1996, "A space-sweep approach to true multi-image
    matching"). Seeds without a normal, seen by fewer than ``min_views`` views, or whose best
    offset does not lower the variance at the voxel centre by a fifth (a textureless surface)
    stay.

    Args:
        points: [N, 3] seeds, m (world).
        normals: [N, 3] outward unit normals (NaN rows: no normal).
        views: the views (full resolution is best: the sweep is sub-voxel).
        voxel: voxel edge of the carving, m.
        occluders: [K, 3] other seed points that hide seeds (e.g. on the URDF meshes).

    Returns:
        The moved points [N, 3] and each one's offset along its normal [N], m.
    """
    P = torch.as_tensor(points, dtype=torch.float64)
    Nrm = torch.as_tensor(np.nan_to_num(normals), dtype=torch.float64)
    has_n = Nrm.norm(dim=1) > 0.5
    M = len(P)
    if M == 0 or not views:
        return np.asarray(points, np.float64).copy(), np.zeros(M)
    allp = (
        P
        if occluders is None or not len(occluders)
        else torch.cat([P, torch.as_tensor(occluders, dtype=torch.float64)])
    )
    offsets = torch.linspace(-reach_voxels, reach_voxels, steps, dtype=torch.float64) * voxel
    s1 = torch.zeros(steps, M, 3, dtype=torch.float64)
    s2 = torch.zeros(steps, M, 3, dtype=torch.float64)
    cnt = torch.zeros(M, dtype=torch.float64)
    for v in views:
        u, w, z = _project(allp, v)
        H, W = v.rgb.shape[:2]
        inside = (z > v.camera.near) & (u >= 0) & (u < W) & (w >= 0) & (w < H)
        if not inside[:M].any():
            continue
        px_per_voxel = voxel * v.camera.fx / float(z[inside].median())
        sc = float(np.clip(1.0 / (1.5 * px_per_voxel), 0.01, 1.0))  # buffer pixel: 1.5 voxels
        Ws, Hs = max(1, int(W * sc)), max(1, int(H * sc))
        bpix = (w * sc).clamp(0, Hs - 1).long() * Ws + (u * sc).clamp(0, Ws - 1).long()
        zbuf = torch.full((Hs * Ws,), float("inf"), dtype=torch.float64)
        zbuf.scatter_reduce_(0, bpix[inside], z[inside], reduce="amin")
        C = v.camera.T_world_cam[:3, 3].to(torch.float64)
        seen = inside[:M] & (z[:M] <= zbuf[bpix[:M]] + 1.5 * voxel)
        seen &= has_n & (((C - P) * Nrm).sum(1) > 0)
        idx = torch.nonzero(seen)[:, 0]
        if not len(idx):
            continue
        cnt[idx] += 1
        for k in range(steps):
            uq, wq, _ = _project(P[idx] + offsets[k] * Nrm[idx], v)
            col = _bilinear(v.rgb, uq, wq)
            s1[k, idx] += col
            s2[k, idx] += col * col
    n = cnt.clamp(min=1)[None, :, None]
    var = (s2 / n - (s1 / n) ** 2).sum(2)  # [steps, M]
    best = var.argmin(0)
    delta = offsets[best]
    # a flat score (a textureless surface agrees at every offset) moves nothing: the best
    # offset must lower the variance at the voxel centre by a fifth
    flat = var.gather(0, best[None])[0] >= 0.8 * var[steps // 2]
    delta[(cnt < min_views) | ~has_n | flat] = 0.0
    moved = P + delta[:, None] * Nrm
    return moved.numpy(), delta.numpy()
