"""Tile-chunk front-to-back compositing, vectorised over tiles, pixels and Gaussians.

All tiles of a batch advance together: each step takes the next ``chunk`` Gaussians of every
active tile ([A, K]), evaluates every pixel of the tile against them ([A, P, K]) and composites
with a cumulative product of (1 - alpha) along the chunk:

- The 3DGS exponent ln o - sigma of a pair is a quadratic polynomial in the pixel's tile-local
  coordinates, so a whole step is one matrix product of the [P, 6] monomials with [A, 6, K]
  per-pair coefficients. The 2DGS splat point h(x, y) is affine in the pixel and is obtained the
  same way (see ``projection.py``).
- A masked (alpha = 0) column is put in front of every chunk, so the cumulative product
  c = cumprod(1 - alpha) holds both the transmittance before (c[k - 1]) and after (c[k]) each
  pair, and the weight is w_k = T (c[k - 1] - c[k]) = T c[k - 1] alpha_k without a copy.
- Stop rule (3DGS reference ``renderCUDA``): a pair is composited only if the transmittance after
  it stays >= 1e-4; the first one that would push it lower ends the pixel. An ended pixel gets
  T = 0, so later chunks add nothing to it.
- Median depth: the pixel's one pair with T_before > 0.5 >= T_after. Only the few pixels that
  cross 0.5 in a step are searched.
- Tiles whose pixels have all ended or whose lists are exhausted leave the active set. Tiles are
  processed in batches so that the per-step tensors stay in cache on CPUs.

Without autograd the step works in place; with autograd every op is out-of-place so eager
autograd differentiates the loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .binning import TileBins
from .constants import MAX_ALPHA, MEDIAN_TRANSMITTANCE, TRANSMITTANCE_THRESHOLD
from .projection import Projected

__all__ = ["CompositeImages", "composite_tiles"]

#: F.threshold keeps x > t; a tiny negative t keeps the exact boundary e == exp_min (alpha = 1/255)
_THRESHOLD_EPS = -1e-30
#: rho given to ray-splat intersections that do not count (behind the near plane, parallel)
_FAR_RHO = 1e30
#: exponent given to masked pairs (see the step); exp of it is a normal float32 number
_MASKED_EXPONENT = -80.0


@dataclass(frozen=True, eq=False)
class CompositeImages:
    """Accumulated (not yet normalised) images, [H, W, ...].

    Attributes:
        features: [H, W, D] sum_i w_i f_i for the feature columns passed in.
        depth: [H, W] sum_i w_i z_i.
        median: [H, W] median depth (0 where T never drops to 0.5).
    """

    features: torch.Tensor
    depth: torch.Tensor
    median: torch.Tensor


def _tile_monomials(tile_size: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """[P, 6] (1, x, y, x^2, x y, y^2) at tile-local pixel centres (x, y in [0.5, ts - 0.5])."""
    r = torch.arange(tile_size, dtype=dtype, device=device) + 0.5
    ly, lx = torch.meshgrid(r, r, indexing="ij")
    lx, ly = lx.reshape(-1), ly.reshape(-1)
    return torch.stack([torch.ones_like(lx), lx, ly, lx * lx, lx * ly, ly * ly], dim=-1)


def _pack(proj: Projected, features: torch.Tensor) -> tuple[torch.Tensor, int]:
    """Per-Gaussian rows gathered once per step: kernel parameters, then features.

    3DGS: (mx, my, A, B, C, ln o, exp_min, z, features...).
    2DGS: (mx, my, ln o, exp_min, z, Px, Py, Pa, Tw (3 each), features...).
    """
    head = [proj.means2d, proj.log_opacity[:, None], proj.exp_min[:, None], proj.depth[:, None]]
    if proj.kind == "3dgs":
        head = [proj.means2d, proj.conic] + head[1:]  # type: ignore[list-item]
    else:
        head = head + [proj.ray.reshape(-1, 12)]  # type: ignore[union-attr]
    packed = torch.cat(head + [features], dim=1)
    return packed, packed.shape[1] - features.shape[1]


def _coefficients_3dgs(
    gp: torch.Tensor, e0: torch.Tensor, ox: torch.Tensor, oy: torch.Tensor
) -> torch.Tensor:
    """[A, 6, K] coefficients of e0 - sigma in the tile-local monomials (e0 = ln o - exp_min)."""
    ex = gp[..., 0] - ox
    ey = gp[..., 1] - oy
    cA, cB, cC = gp[..., 2], gp[..., 3], gp[..., 4]
    k1 = cA * ex + cB * ey
    k2 = cB * ex + cC * ey
    k0 = e0 - 0.5 * (k1 * ex + k2 * ey)
    return torch.stack([k0, k1, k2, -0.5 * cA, -cB, -0.5 * cC], dim=1)


def _exponent_2dgs(
    mono: torch.Tensor,
    gp: torch.Tensor,
    lo: torch.Tensor,
    ox: torch.Tensor,
    oy: torch.Tensor,
    near: float,
    s: float,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Exponent ln o - rho / 2 and depth of every 2DGS pair, [A, P, K] each.

    rho = min(u^2 + v^2, s |x - c|^2) with (u, v) from the ray-splat intersection (Huang et al.
    2024, Eq. 8-11); the intersection counts only in front of the near plane and for rays not
    parallel to the surfel. The depth is that of the intersection, or of the centre where the
    low-pass term wins. Selections are written as arithmetic on 0/1 masks: ``torch.where`` is
    ~20x slower than a multiply on CPU.
    """
    ray = gp[..., 5:17].unflatten(-1, (4, 3))
    Px, Py, Pa, Tw = ray.unbind(-2)
    h0 = Pa + ox[..., None] * Px + oy[..., None] * Py  # h at the tile origin, [A, K, 3]
    zero = torch.zeros_like(ox.expand_as(gp[..., 0]))
    ex = gp[..., 0] - ox
    ey = gp[..., 1] - oy

    def poly(c0: torch.Tensor, cx: torch.Tensor, cy: torch.Tensor) -> torch.Tensor:
        return torch.matmul(mono[:, :3], torch.stack([c0, cx, cy], dim=1))

    hx = poly(h0[..., 0], Px[..., 0], Py[..., 0])
    hy = poly(h0[..., 1], Px[..., 1], Py[..., 1])
    hz = poly(h0[..., 2], Px[..., 2], Py[..., 2])
    zn = poly((Tw * h0).sum(-1), (Tw * Px).sum(-1), (Tw * Py).sum(-1))
    rho2 = torch.matmul(
        mono,
        torch.stack(
            [s * (ex * ex + ey * ey), -2 * s * ex, -2 * s * ey, zero + s, zero, zero + s], dim=1
        ),
    )
    dtype = hx.dtype
    parallel = hz == 0
    inv = 1.0 / (hz + parallel.to(dtype))
    u = hx * inv
    v = hy * inv
    zhit = zn * inv
    off = ((zhit <= near) | parallel).to(dtype)
    rho3 = u * u + v * v + off * _FAR_RHO
    rho = torch.minimum(rho3, rho2)
    use3 = (rho3 <= rho2).to(dtype)
    zc = gp[:, None, :, 4]
    z = zc + use3 * (zhit - zc)
    return lo[:, None, :] - 0.5 * rho, z


def composite_tiles(
    proj: Projected,
    bins: TileBins,
    features: torch.Tensor,
    width: int,
    height: int,
    *,
    chunk: int,
    near: float,
    tile_batch: int | None = None,
) -> CompositeImages:
    """Composite the binned Gaussians front to back into [H, W] images.

    Args:
        proj: projected Gaussians.
        bins: their tile lists.
        features: [N, D] per-Gaussian channels to blend (colour, 1 for alpha, normals, extras).
        width: image width, px.
        height: image height, px.
        chunk: Gaussians per tile and step.
        near: near plane, m (2DGS intersections closer than this are ignored).
        tile_batch: tiles composited together (None: all at once).

    Returns:
        The accumulated images.
    """
    device = features.device
    ts = bins.tile_size
    D = features.shape[1]
    packed, n_head = _pack(proj, features)
    grad = torch.is_grad_enabled() and packed.requires_grad
    mono = _tile_monomials(ts, features.dtype, device)
    tiles = torch.nonzero(bins.counts > 0).flatten()
    # longest lists first: batches then hold tiles of similar work
    tiles = tiles[torch.argsort(bins.counts[tiles], descending=True, stable=True)]
    batch = tiles.numel() if not tile_batch else tile_batch
    ids: list[torch.Tensor] = []
    rows: list[torch.Tensor] = []
    for b0 in range(0, tiles.numel(), max(batch, 1)):
        t_ids, t_rows = _composite_batch(
            tiles[b0 : b0 + batch],
            packed,
            n_head,
            D,
            proj,
            mono,
            bins,
            width,
            height,
            chunk,
            near,
            grad,
        )
        ids += t_ids
        rows += t_rows
    num_tiles = bins.tiles_x * bins.tiles_y
    out = features.new_zeros((num_tiles, ts * ts, D + 2))
    if ids:
        out = out.index_copy(0, torch.cat(ids), torch.cat(rows))
    img = out.reshape(bins.tiles_y, bins.tiles_x, ts, ts, D + 2).permute(0, 2, 1, 3, 4)
    img = img.reshape(bins.tiles_y * ts, bins.tiles_x * ts, D + 2)[:height, :width]
    return CompositeImages(features=img[..., :D], depth=img[..., D], median=img[..., D + 1])


def _composite_batch(
    tiles: torch.Tensor,
    packed: torch.Tensor,
    n_head: int,
    D: int,
    proj: Projected,
    mono: torch.Tensor,
    bins: TileBins,
    width: int,
    height: int,
    chunk: int,
    near: float,
    grad: bool,
) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """Run the chunk loop over one batch of tiles; returns finished tile ids and their rows
    [A, P, D + 2] (features, depth sum, median)."""
    dtype, device = packed.dtype, packed.device
    ts = bins.tile_size
    P = ts * ts
    is_3dgs = proj.kind == "3dgs"
    inv_sq = proj.lowpass_inv_sq
    start = bins.offsets[tiles]
    end = bins.offsets[tiles + 1]
    ox = ((tiles % bins.tiles_x) * ts).to(dtype)[:, None]
    oy = ((tiles // bins.tiles_x) * ts).to(dtype)[:, None]
    local = torch.arange(ts, device=device)
    px = ox.long()[:, :, None] + local[None, None, :]
    py = oy.long()[:, :, None] + local[None, :, None]
    T = ((px < width) & (py < height)).reshape(-1, P).to(dtype)  # pixels off the image: ended
    acc = packed.new_zeros((tiles.numel(), P, D + 1))  # (sum w z, sum w f)
    acc_med = packed.new_zeros((tiles.numel(), P))
    ar = torch.arange(-1, chunk, device=device)  # column -1 is the masked leading column
    done_ids: list[torch.Tensor] = []
    done_rows: list[torch.Tensor] = []
    step = 0
    lo_col, emin_col = (5, 6) if is_3dgs else (2, 3)
    while tiles.numel() > 0:
        idx = start[:, None] + step * chunk + ar
        valid = (idx < end[:, None]) & (ar >= 0)
        gid = bins.gaussian_ids.index_select(0, torch.where(valid, idx, start[:, None]).flatten())
        gp = packed.index_select(0, gid).unflatten(0, idx.shape)  # [A, K + 1, Q]
        # masked columns get ln o = -inf (alpha 0); e is measured from exp_min: pair valid iff >= 0
        lo = gp[..., lo_col].masked_fill(~valid, -math.inf)
        exp_min = gp[..., emin_col].masked_fill(~valid, 0.0)
        if is_3dgs:
            e = torch.matmul(mono, _coefficients_3dgs(gp, lo - exp_min, ox, oy))
            zp = None
        else:
            e, zp = _exponent_2dgs(mono, gp, lo, ox, oy, near, inv_sq)
            e = e - exp_min[:, None, :]
        # Boolean-mask ops (where, masked_fill) are ~30x slower than arithmetic on CPU: mask by
        # F.threshold (x if x > t else value) and scale by exp(exp_min) instead. Masked pairs
        # get exp(-80) ~ 2e-35, so 1 - alpha rounds to exactly 1 (float32 and float64) and they
        # add exactly nothing; -inf or denormal results would make exp ~10x slower.
        scale = torch.exp(exp_min)[:, None, :]
        if grad:
            alpha = (torch.exp(F.threshold(e, _THRESHOLD_EPS, _MASKED_EXPONENT)) * scale).clamp_max(
                MAX_ALPHA
            )
            c = torch.cumprod(1.0 - alpha, dim=-1)
            w = c[..., :-1] - c[..., 1:]
        else:
            c = F.threshold(e, _THRESHOLD_EPS, _MASKED_EXPONENT, inplace=True).exp_().mul_(scale)
            c = c.clamp_max_(MAX_ALPHA).neg_().add_(1.0)
            c = (
                torch.cumprod(c, dim=-1, out=c)
                if c.device.type == "cpu"
                else torch.cumprod(c, dim=-1)
            )
            w = torch.sub(c[..., :-1], c[..., 1:])
        w = _apply_stop_rule(w, T, c, grad)
        if is_3dgs:
            inc = torch.matmul(w, gp[:, 1:, n_head - 1 :])  # [A, P, 1 + D]: (z, features)
        else:
            dsum = (w * zp[..., 1:]).sum(-1, keepdim=True)  # type: ignore[index]
            inc = torch.cat([dsum, torch.matmul(w, gp[:, 1:, n_head:])], dim=-1)
        T_raw = T * c[..., -1]
        med = _median_step(T, T_raw, c, gp, zp, is_3dgs)
        acc = acc + T[..., None] * inc
        acc_med = acc_med + med
        T = torch.where(T_raw < TRANSMITTANCE_THRESHOLD, 0.0, T_raw)
        step += 1
        alive = (start + step * chunk < end) & (T > 0).any(dim=1)
        if not bool(alive.all()):
            gone = ~alive
            done_ids.append(tiles[gone])
            done_rows.append(
                torch.cat([acc[gone][..., 1:], acc[gone][..., :1], acc_med[gone][..., None]], -1)
            )
            keep = torch.nonzero(alive).flatten()
            tiles, start, end, ox, oy = tiles[keep], start[keep], end[keep], ox[keep], oy[keep]
            T, acc, acc_med = T[keep], acc[keep], acc_med[keep]
    return done_ids, done_rows


def _apply_stop_rule(w: torch.Tensor, T: torch.Tensor, c: torch.Tensor, grad: bool) -> torch.Tensor:
    """Zero the weights from the first pair that would push T below 1e-4 on.

    Only pixels whose transmittance ends below the threshold in this step can be affected, and
    each pixel ends once, so only their rows are masked (a gather, not a full pass).
    """
    T_raw = T * c[..., -1]
    sel = torch.nonzero(((T_raw < TRANSMITTANCE_THRESHOLD) & (T > 0)).flatten()).flatten()
    if sel.numel() == 0:
        return w
    K = w.shape[-1]
    rows = w.reshape(-1, K)[sel]
    keep = (T.flatten()[sel, None] * c.reshape(-1, K + 1)[sel, 1:]) >= TRANSMITTANCE_THRESHOLD
    rows = rows * keep.to(rows.dtype)
    if grad:
        return w.reshape(-1, K).index_put((sel,), rows).reshape(w.shape)
    w.reshape(-1, K)[sel] = rows
    return w


def _median_step(
    T: torch.Tensor,
    T_raw: torch.Tensor,
    c: torch.Tensor,
    gp: torch.Tensor,
    zp: torch.Tensor | None,
    is_3dgs: bool,
) -> torch.Tensor:
    """[A, P] depth of the pair at which T crosses 0.5 in this step (0 elsewhere)."""
    cross = (T > MEDIAN_TRANSMITTANCE) & (T_raw <= MEDIAN_TRANSMITTANCE)
    sel = torch.nonzero(cross.flatten()).flatten()
    out = T.new_zeros(T.numel())
    if sel.numel() == 0:
        return out.reshape(T.shape)
    K1 = c.shape[-1]
    P = T.shape[1]
    crow = c.reshape(-1, K1)[sel, 1:]
    k = ((T.flatten()[sel, None] * crow) > MEDIAN_TRANSMITTANCE).sum(-1) + 1  # column index
    if is_3dgs:
        z = gp[sel // P, k, 7]
    else:
        z = zp.reshape(-1, K1)[sel, k]  # type: ignore[union-attr]
    return out.index_put((sel,), z).reshape(T.shape)
