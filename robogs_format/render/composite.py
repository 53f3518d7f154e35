"""Tile-chunk front-to-back compositing, vectorised over tiles, pixels and Gaussians.

All tiles still in work advance together: each step takes the next ``chunk`` Gaussians of every
active tile ([A, chunk]), evaluates every pixel of the tile against them ([A, P, chunk]) and
composites with a cumulative product of (1 - alpha) along the chunk. The exponent of each pair is a
quadratic polynomial in the pixel's tile-local coordinates, so it is evaluated for a whole step
by one matrix product of the [P, 6] monomials with [A, 6, chunk] per-pair coefficients (3DGS);
the 2DGS splat point h(x, y) is affine in the pixel and is obtained the same way.

Stop rule (3DGS reference, ``renderCUDA``): a Gaussian is composited only if the transmittance
after it stays >= 1e-4; the first one that would push it lower ends the pixel. A pixel that has
ended gets T = 0, so later chunks add nothing to it. Tiles whose pixels have all ended or whose
lists are exhausted leave the active set. Everything is out-of-place, so eager autograd
differentiates the loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .binning import TileBins
from .constants import LOWPASS_2DGS_INV_SQ, MAX_ALPHA, MEDIAN_TRANSMITTANCE, TRANSMITTANCE_THRESHOLD
from .projection import Projected

__all__ = ["CompositeImages", "composite_tiles"]

_LOG_MAX_ALPHA = math.log(MAX_ALPHA)


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


def _coefficients_3dgs(
    proj: Projected, gid: torch.Tensor, ox: torch.Tensor, oy: torch.Tensor
) -> torch.Tensor:
    """[A, 6, K] coefficients of e = ln o - sigma in the tile-local monomials."""
    m = proj.means2d[gid]
    cA, cB, cC = proj.conic[gid].unbind(-1)  # type: ignore[index]
    ex = m[..., 0] - ox
    ey = m[..., 1] - oy
    k1 = cA * ex + cB * ey
    k2 = cB * ex + cC * ey
    k0 = proj.log_opacity[gid] - 0.5 * (k1 * ex + k2 * ey)
    return torch.stack([k0, k1, k2, -0.5 * cA, -cB, -0.5 * cC], dim=1)


def _coefficients_2dgs(
    proj: Projected, gid: torch.Tensor, ox: torch.Tensor, oy: torch.Tensor
) -> torch.Tensor:
    """[A, 6, 5 K] coefficients of (h0, h1, h2, Tw.h, rho_2d) in the tile-local monomials."""
    ray = proj.ray[gid]  # type: ignore[index]  # [A, K, 4, 3]
    Px, Py, Pa, Tw = ray.unbind(-2)
    c0 = Pa + ox[..., None] * Px + oy[..., None] * Py  # h at the tile origin
    h_const, h_x, h_y = c0, Px, Py
    zc = (Tw * h_const).sum(-1)
    zx = (Tw * h_x).sum(-1)
    zy = (Tw * h_y).sum(-1)
    m = proj.means2d[gid]
    ex = m[..., 0] - ox
    ey = m[..., 1] - oy
    s = LOWPASS_2DGS_INV_SQ
    zero = torch.zeros_like(ex)
    # rho_2d = s((lx - ex)^2 + (ly - ey)^2)
    rho = torch.stack([s * (ex * ex + ey * ey), -2 * s * ex, -2 * s * ey, zero + s, zero, zero + s], dim=1)
    cols = [
        torch.stack([h_const[..., i], h_x[..., i], h_y[..., i], zero, zero, zero], dim=1) for i in range(3)
    ]
    cols.append(torch.stack([zc, zx, zy, zero, zero, zero], dim=1))
    cols.append(rho)
    return torch.cat(cols, dim=2)  # [A, 6, 5K]


def _pair_exponent_2dgs(
    q: torch.Tensor, log_o: torch.Tensor, depth_c: torch.Tensor, near: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Exponent ln o - rho/2 and depth of each 2DGS pair from the evaluated polynomials.

    Args:
        q: [A, P, 5, K] (h0, h1, h2, Tw.h, rho_2d).
        log_o: [A, 1, K] log opacity.
        depth_c: [A, 1, K] depth of the surfel centre.
        near: near plane, m.
    """
    h0, h1, h2, zn, rho2 = q.unbind(2)
    ok = h2 != 0
    h2s = torch.where(ok, h2, torch.ones_like(h2))
    u = h0 / h2s
    v = h1 / h2s
    zhit = zn / h2s
    rho3 = u * u + v * v
    use3 = ok & (zhit > near) & (rho3 <= rho2)
    rho = torch.where(use3, rho3, rho2)
    z = torch.where(use3, zhit, depth_c)
    return log_o - 0.5 * rho, z


def composite_tiles(
    proj: Projected,
    bins: TileBins,
    features: torch.Tensor,
    width: int,
    height: int,
    *,
    chunk: int,
    near: float,
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

    Returns:
        The accumulated images.
    """
    dtype, device = features.dtype, features.device
    ts = bins.tile_size
    P = ts * ts
    D = features.shape[1]
    num_tiles = bins.tiles_x * bins.tiles_y
    is_2dgs = proj.kind == "2dgs"
    mono = _tile_monomials(ts, dtype, device)
    counts = bins.counts
    tiles = torch.nonzero(counts > 0).flatten()
    start = bins.offsets[tiles]
    end = bins.offsets[tiles + 1]
    ox_t = ((tiles % bins.tiles_x) * ts).to(dtype)
    oy_t = ((tiles // bins.tiles_x) * ts).to(dtype)
    # pixels outside the image start as "ended"
    local = torch.arange(ts, device=device)
    px = ox_t.long()[:, None, None] + local[None, None, :]
    py = oy_t.long()[:, None, None] + local[None, :, None]
    T = ((px < width) & (py < height)).reshape(-1, P).to(dtype)
    acc = features.new_zeros((tiles.numel(), P, D))
    dep = features.new_zeros((tiles.numel(), P))
    med = features.new_zeros((tiles.numel(), P))
    done_tiles: list[torch.Tensor] = []
    done_parts: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []
    ar = torch.arange(chunk, device=device)
    depth_all = proj.depth
    step = 0
    while tiles.numel() > 0:
        idx = start[:, None] + step * chunk + ar
        valid = idx < end[:, None]
        gid = bins.gaussian_ids[torch.where(valid, idx, start[:, None])]
        ox = ox_t[:, None]
        oy = oy_t[:, None]
        exp_min = torch.where(valid, proj.exp_min[gid], torch.full_like(ox_t[:, None].expand_as(idx), math.inf))[:, None, :]
        if is_2dgs:
            coef = _coefficients_2dgs(proj, gid, ox, oy)
            q = torch.matmul(mono, coef).unflatten(2, (5, chunk))
            e, zp = _pair_exponent_2dgs(q, proj.log_opacity[gid][:, None, :], depth_all[gid][:, None, :], near)
        else:
            coef = _coefficients_3dgs(proj, gid, ox, oy)
            e = torch.matmul(mono, coef)
        e = torch.where(e >= exp_min, e.clamp_max(_LOG_MAX_ALPHA), -math.inf)
        alpha = torch.exp(e)
        Ta = T[:, :, None] * torch.cumprod(1.0 - alpha, dim=-1)
        Tb = torch.cat([T[:, :, None], Ta[:, :, :-1]], dim=-1)
        w = torch.where(Ta >= TRANSMITTANCE_THRESHOLD, alpha * Tb, 0.0)
        acc = acc + torch.matmul(w, features[gid])
        # median: the one pair where T crosses 0.5 (T is non-increasing along the chunk)
        n_above = (Ta > MEDIAN_TRANSMITTANCE).sum(-1, keepdim=True)
        found = (T[:, :, None] > MEDIAN_TRANSMITTANCE) & (n_above < chunk)
        cross = n_above.clamp_max(chunk - 1)
        if is_2dgs:
            dep = dep + (w * zp).sum(-1)
            z_cross = torch.gather(zp, 2, cross)
        else:
            dep = dep + torch.matmul(w, depth_all[gid][:, :, None]).squeeze(-1)
            z_cross = torch.gather(depth_all[gid][:, None, :].expand(-1, P, -1), 2, cross)
        med = med + torch.where(found, z_cross, 0.0).squeeze(-1)
        T_last = Ta[:, :, -1]
        T = torch.where(T_last < TRANSMITTANCE_THRESHOLD, 0.0, T_last)
        step += 1
        alive = (start + step * chunk < end) & (T > 0).any(dim=1)
        if not bool(alive.all()):
            gone = ~alive
            done_tiles.append(tiles[gone])
            done_parts.append((acc[gone], dep[gone], med[gone]))
            keep = torch.nonzero(alive).flatten()
            tiles, start, end = tiles[keep], start[keep], end[keep]
            ox_t, oy_t = ox_t[keep], oy_t[keep]
            T, acc, dep, med = T[keep], acc[keep], dep[keep], med[keep]
    return _assemble(done_tiles, done_parts, bins, features, width, height)


def _assemble(
    done_tiles: list[torch.Tensor],
    done_parts: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]],
    bins: TileBins,
    features: torch.Tensor,
    width: int,
    height: int,
) -> CompositeImages:
    ts = bins.tile_size
    P = ts * ts
    D = features.shape[1]
    num_tiles = bins.tiles_x * bins.tiles_y
    packed = features.new_zeros((num_tiles, P, D + 2))
    if done_tiles:
        ids = torch.cat(done_tiles)
        rows = torch.cat([torch.cat([a, d[..., None], m[..., None]], dim=-1) for a, d, m in done_parts])
        packed = packed.index_copy(0, ids, rows)
    img = packed.reshape(bins.tiles_y, bins.tiles_x, ts, ts, D + 2).permute(0, 2, 1, 3, 4)
    img = img.reshape(bins.tiles_y * ts, bins.tiles_x * ts, D + 2)[:height, :width]
    return CompositeImages(features=img[..., :D], depth=img[..., D], median=img[..., D + 1])
