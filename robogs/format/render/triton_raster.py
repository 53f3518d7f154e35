"""Optional ``triton`` backend: fused per-tile compositing kernels, forward and backward (CUDA).

Projection, culling, depth sort and tile binning are the torch backend's (vectorised, on the
device); compositing is one Triton program per tile, for the forward pass and for the gradient,
so a training step runs no per-tile Python and no host synchronisation inside the compositing.
Binning reads the intersection count to size its buffers (one host sync per render, as the
reference 3DGS rasterizer and gsplat do).

Forward (per tile of ``TS x TS`` pixels, the tile's depth-ordered list read ``K`` Gaussians at a
time): the exponent of every [pixel, Gaussian] pair, alpha, the transmittance after each pair as
``T * cumprod(1 - alpha)`` along the chunk, the stop rule (a pair counts only while T after it
stays >= 1e-4; the first that would push it lower ends the pixel), weights ``w = T_before alpha``,
features accumulated by one ``[P, K] x [K, D]`` product, and the median crossing of T = 0.5. The
tile stops once every pixel has ended. Same constants, support cut and stop rule as ``design.md``.

Backward: the same chunks are replayed front to back with the forward's arithmetic. With
``g_k = dL/dout . f_k`` and ``S_k`` the sum of ``w_j g_j`` over the kept pairs after k, the alpha
gradient is ``T_k g_k - S_k / (1 - alpha_k)`` (Kerbl et al. 2023, ``renderCUDA`` backward); the
suffix is the pixel's total (read from the forward's output) minus the running prefix, so the
replay can go front to back. Per-Gaussian gradients are summed over the tile's pixels and added
with one atomic add per Gaussian, tile and parameter.

Arithmetic is float32 (float64 inputs are rendered in float32 and cast back). Without a CUDA
device the backend is listed as unavailable with the reason, except under ``TRITON_INTERPRET=1``
(Triton's CPU interpreter, used by the tests on machines without a GPU).
"""

from __future__ import annotations

import os
from dataclasses import replace

import torch
import triton
import triton.language as tl

from ..errors import InputError
from .binning import TileBins, bin_tiles
from .camera import Camera
from .config import RenderConfig
from .constants import MAX_ALPHA, MEDIAN_TRANSMITTANCE, TRANSMITTANCE_THRESHOLD
from .gaussians import Gaussians
from .output import RenderOutput
from .projection import Projected, project
from .tiled import finish_output, support_radii, visible_means2d
from .triton_binning import bin_tiles_triton
from .triton_finish import FinishImages
from .triton_project import fused_projection_supports, project_fused

__all__ = ["render_triton", "unavailable_reason", "interpreting"]

#: Gaussians per chunk in the forward and backward kernels (tl.dot needs >= 16), and warps per
#: program; ``bench/triton_sweep.py`` times the alternatives on a GPU.
#: (H200, 2026-11-27: forward K 32 x 8 warps fastest or within noise in every case; backward
#: K 16 channel by channel spills almost nothing per ptxas -v, against ~2-17 KB with tl.dot)
_K_FWD = 32
_K_BWD = 16
_WARPS_FWD = 8
_WARPS_BWD = 8
#: backward: g . f by tl.dot (True) or channel by channel (False); bench/triton_sweep.py times both
_BWD_DOT = False
#: default tile edge, px (power of two: a tile's pixels are one Triton block)
_TILE_SIZE = 16
#: columns of the per-Gaussian parameter rows (see ``_pack_params``)
_Q_3DGS = 8
_Q_2DGS = 17
#: F.threshold of the torch backend keeps e - exp_min > this (the exact boundary alpha = 1/255)
_THRESHOLD_EPS = tl.constexpr(-1e-30)
#: use the fused projection of ``triton_project.py`` instead of ``project()`` where it covers the
#: render (``fused_projection_supports``: no camera-pose gradient). On by default since it was
#: timed on an H200 (issue 23, bench/RESULTS.md 2026-11-27): the torch projection's ~600 small ops
#: and their autograd bound the step there (fwd + bwd 20k at 320x240: 12.0 -> 3.95 ms)
_FUSED_PROJECTION = True
#: bin with the two Triton kernels of ``triton_binning.py`` (the same lists as ``bin_tiles`` in
#: about 14 launches instead of about 70). On since timed on an H200 (issue 23, bench/RESULTS.md
#: 2026-11-28): 3DGS fwd + bwd 20k at 320x240 5.07 -> 3.51 ms, forward 100k 3.05 -> 2.00 ms
_TRITON_BINNING = True
#: turn the tile rows into the output images with ``triton_finish.FinishImages`` (one kernel each
#: way instead of about 35 torch ops each way). On since timed on an H200 (same run): 3DGS fwd +
#: bwd 20k 5.07 -> 3.63 ms, forward 100k 3.05 -> 2.58 ms
_FUSED_FINISH = True
#: the shared constants, as compile-time values (Triton reads no other globals in kernels)
_MAX_ALPHA = tl.constexpr(MAX_ALPHA)
_T_MIN = tl.constexpr(TRANSMITTANCE_THRESHOLD)
_T_MEDIAN = tl.constexpr(MEDIAN_TRANSMITTANCE)


def interpreting() -> bool:
    """Whether Triton runs its CPU interpreter (``TRITON_INTERPRET=1``)."""
    return os.environ.get("TRITON_INTERPRET", "0") not in ("", "0")


def unavailable_reason() -> str | None:
    """Why this backend cannot run here, or None when it can."""
    if interpreting():
        return None
    if not torch.cuda.is_available():
        return (
            "needs a CUDA GPU (Triton compiles for the GPU); on a CPU use the 'torch' backend "
            "(or 'numba' for forward-only renders)"
        )
    return None


@triton.jit
def _col(prm_ptr, g, valid, col: tl.constexpr, Q: tl.constexpr):
    """[K] column ``col`` of the parameter rows of Gaussians ``g`` (0 where not valid)."""
    return tl.load(prm_ptr + g * Q + col, mask=valid, other=0.0)


@triton.jit
def _exponent_3dgs(prm_ptr, g, valid, x, y, Q: tl.constexpr):
    """Exponent ln o - sigma [P, K], validity, depth, and the pieces the gradient needs."""
    mx = _col(prm_ptr, g, valid, 0, Q)
    my = _col(prm_ptr, g, valid, 1, Q)
    cA = _col(prm_ptr, g, valid, 2, Q)
    cB = _col(prm_ptr, g, valid, 3, Q)
    cC = _col(prm_ptr, g, valid, 4, Q)
    lo = _col(prm_ptr, g, valid, 5, Q)
    emin = _col(prm_ptr, g, valid, 6, Q)
    zc = _col(prm_ptr, g, valid, 7, Q)
    dx = x[:, None] - mx[None, :]
    dy = y[:, None] - my[None, :]
    sigma = 0.5 * (cA[None, :] * dx * dx + cC[None, :] * dy * dy) + cB[None, :] * dx * dy
    e = lo[None, :] - sigma
    ok = valid[None, :] & ((e - emin[None, :]) > _THRESHOLD_EPS)
    z = zc[None, :] + 0.0 * e
    return e, ok, z, dx, dy, cA, cB, cC


@triton.jit
def _exponent_2dgs(prm_ptr, g, valid, x, y, near, inv_sq, Q: tl.constexpr):
    """2DGS exponent ln o - rho / 2 [P, K] with rho = min(u^2 + v^2, s |x - c|^2) (Huang et al.
    2024); the intersection counts only in front of ``near`` and off the parallel case."""
    mx = _col(prm_ptr, g, valid, 0, Q)
    my = _col(prm_ptr, g, valid, 1, Q)
    lo = _col(prm_ptr, g, valid, 2, Q)
    emin = _col(prm_ptr, g, valid, 3, Q)
    zc = _col(prm_ptr, g, valid, 4, Q)
    X = x[:, None]
    Y = y[:, None]
    h0 = X * _col(prm_ptr, g, valid, 5, Q)[None, :] + Y * _col(prm_ptr, g, valid, 8, Q)[None, :]
    h0 += _col(prm_ptr, g, valid, 11, Q)[None, :]
    h1 = X * _col(prm_ptr, g, valid, 6, Q)[None, :] + Y * _col(prm_ptr, g, valid, 9, Q)[None, :]
    h1 += _col(prm_ptr, g, valid, 12, Q)[None, :]
    h2 = X * _col(prm_ptr, g, valid, 7, Q)[None, :] + Y * _col(prm_ptr, g, valid, 10, Q)[None, :]
    h2 += _col(prm_ptr, g, valid, 13, Q)[None, :]
    tw0 = _col(prm_ptr, g, valid, 14, Q)[None, :]
    tw1 = _col(prm_ptr, g, valid, 15, Q)[None, :]
    tw2 = _col(prm_ptr, g, valid, 16, Q)[None, :]
    parallel = h2 == 0.0
    inv = 1.0 / tl.where(parallel, 1.0, h2)
    u = h0 * inv
    v = h1 * inv
    zhit = (tw0 * h0 + tw1 * h1 + tw2 * h2) * inv
    off = (zhit <= near) | parallel
    rho3 = u * u + v * v
    dxl = X - mx[None, :]
    dyl = Y - my[None, :]
    rho2 = inv_sq * (dxl * dxl + dyl * dyl)
    use3 = (rho3 <= rho2) & (off == 0)
    rho = tl.where(use3, rho3, rho2)
    z = tl.where(use3, zhit, zc[None, :])
    e = lo[None, :] - 0.5 * rho
    ok = valid[None, :] & ((e - emin[None, :]) > _THRESHOLD_EPS)
    return e, ok, z, use3, u, v, inv, zhit, rho3, dxl, dyl, h0, h1, tw0, tw1, tw2


@triton.jit
def _tile_pixels(t, tiles_x, width, height, TS: tl.constexpr):
    """Pixel centres (x, y) of tile ``t`` and the initial transmittance (0 off the image)."""
    p = tl.arange(0, TS * TS)
    px = (t % tiles_x) * TS + p % TS
    py = (t // tiles_x) * TS + p // TS
    T = tl.where((px < width) & (py < height), 1.0, 0.0)
    return p, px.to(tl.float32) + 0.5, py.to(tl.float32) + 0.5, T


@triton.jit
def _blend_chunk(e, ok, T):
    """Front-to-back blending of one [P, K] chunk from the pixels' transmittance T [P].

    Returns exp(e), alpha, T after and before each pair, the stop-rule mask (a pair counts while
    T after it stays >= 1e-4; T only falls, so the kept pairs are a prefix), the weights, the
    median crossing (T before > 0.5 >= T after), and the pixels' T after the chunk (0 once ended).
    """
    a_raw = tl.exp(e)
    alpha = tl.where(ok, tl.minimum(a_raw, _MAX_ALPHA), 0.0)
    Ta = T[:, None] * tl.cumprod(1.0 - alpha, axis=1)
    Tb = Ta / (1.0 - alpha)
    keep = Ta >= _T_MIN
    w = tl.where(keep, Tb * alpha, 0.0)
    cross = keep & (Tb > _T_MEDIAN) & (Ta <= _T_MEDIAN)
    T_last = tl.min(Ta, axis=1)  # a cumprod of factors <= 1 never grows: the min is the last
    return a_raw, alpha, Ta, Tb, keep, w, cross, tl.where(T_last < _T_MIN, 0.0, T_last)


@triton.jit
def _forward_kernel(
    prm_ptr,
    feat_ptr,
    gids_ptr,
    off_ptr,
    outf_ptr,
    outz_ptr,
    outm_ptr,
    tiles_x,
    width,
    height,
    near,
    inv_sq,
    Q: tl.constexpr,
    D: tl.constexpr,
    DP: tl.constexpr,
    TS: tl.constexpr,
    K: tl.constexpr,
    SURFEL: tl.constexpr,
):
    t = tl.program_id(0)
    p, x, y, T = _tile_pixels(t, tiles_x, width, height, TS)
    start = tl.load(off_ptr + t)
    end = tl.load(off_ptr + t + 1)
    kk = tl.arange(0, K)
    dd = tl.arange(0, DP)
    acc = tl.zeros([TS * TS, DP], dtype=tl.float32)
    accz = tl.zeros([TS * TS], dtype=tl.float32)
    med = tl.zeros([TS * TS], dtype=tl.float32)
    s = start
    while (s < end) & (tl.max(T, axis=0) > 0.0):
        idx = s + kk
        valid = idx < end
        g = tl.load(gids_ptr + idx, mask=valid, other=0)
        if SURFEL:
            e, ok, z, _, _, _, _, _, _, _, _, _, _, _, _, _ = _exponent_2dgs(
                prm_ptr, g, valid, x, y, near, inv_sq, Q
            )
        else:
            e, ok, z, _, _, _, _, _ = _exponent_3dgs(prm_ptr, g, valid, x, y, Q)
        _, _, _, _, _, w, cross, T = _blend_chunk(e, ok, T)
        f = tl.load(
            feat_ptr + g[:, None] * D + dd[None, :],
            mask=valid[:, None] & (dd[None, :] < D),
            other=0.0,
        )
        acc += tl.dot(w, f, input_precision="ieee")
        accz += tl.sum(w * z, axis=1)
        med += tl.sum(tl.where(cross, z, 0.0), axis=1)
        s += K
    row = t * (TS * TS) + p
    tl.store(outf_ptr + row[:, None] * DP + dd[None, :], acc)
    tl.store(outz_ptr + row, accz)
    tl.store(outm_ptr + row, med)


@triton.jit
def _backward_kernel(
    prm_ptr,
    feat_ptr,
    gids_ptr,
    off_ptr,
    outf_ptr,
    outz_ptr,
    gf_ptr,
    gz_ptr,
    gm_ptr,
    dprm_ptr,
    dfeat_ptr,
    tiles_x,
    width,
    height,
    near,
    inv_sq,
    Q: tl.constexpr,
    D: tl.constexpr,
    DP: tl.constexpr,
    TS: tl.constexpr,
    K: tl.constexpr,
    SURFEL: tl.constexpr,
    DOT: tl.constexpr,
):
    t = tl.program_id(0)
    p, x, y, T = _tile_pixels(t, tiles_x, width, height, TS)
    start = tl.load(off_ptr + t)
    end = tl.load(off_ptr + t + 1)
    kk = tl.arange(0, K)
    dd = tl.arange(0, DP)
    row = t * (TS * TS) + p
    Gf = tl.load(gf_ptr + row[:, None] * DP + dd[None, :])
    gz = tl.load(gz_ptr + row)
    gm = tl.load(gm_ptr + row)
    total = tl.sum(Gf * tl.load(outf_ptr + row[:, None] * DP + dd[None, :]), axis=1)
    total += gz * tl.load(outz_ptr + row)
    prefix = tl.zeros([TS * TS], dtype=tl.float32)
    s = start
    while (s < end) & (tl.max(T, axis=0) > 0.0):
        idx = s + kk
        valid = idx < end
        g = tl.load(gids_ptr + idx, mask=valid, other=0)
        if SURFEL:
            e, ok, z, use3, u, v, inv, zhit, rho3, dxl, dyl, h0, h1, tw0, tw1, tw2 = _exponent_2dgs(
                prm_ptr, g, valid, x, y, near, inv_sq, Q
            )
        else:
            e, ok, z, dx, dy, cA, cB, cC = _exponent_3dgs(prm_ptr, g, valid, x, y, Q)
        a_raw, alpha, _, Tb, keep, w, cross, T = _blend_chunk(e, ok, T)
        fmask = valid[:, None] & (dd[None, :] < D)
        if DOT:  # g . f of every pair as one [P, DP] x [DP, K] product
            f = tl.load(feat_ptr + g[:, None] * D + dd[None, :], mask=fmask, other=0.0)
            gk = tl.dot(Gf, tl.trans(f), input_precision="ieee") + gz[:, None] * z
        else:  # channel by channel from L1 (fewer live registers than the product's layouts)
            gk = gz[:, None] * z
            for d in tl.static_range(D):
                fd = tl.load(feat_ptr + g * D + d, mask=valid, other=0.0)
                gk += tl.load(gf_ptr + row * DP + d)[:, None] * fd[None, :]
        wg = w * gk
        incl = prefix[:, None] + tl.cumsum(wg, axis=1)
        d_alpha = tl.where(keep, Tb * gk - (total[:, None] - incl) / (1.0 - alpha), 0.0)
        de = tl.where(ok & (a_raw < _MAX_ALPHA), d_alpha * alpha, 0.0)
        dz = w * gz[:, None] + tl.where(cross, gm[:, None], 0.0)
        if DOT:
            d_f = tl.dot(tl.trans(w), Gf, input_precision="ieee")
            tl.atomic_add(dfeat_ptr + g[:, None] * D + dd[None, :], d_f, mask=fmask)
        else:
            for d in tl.static_range(D):
                gd = tl.load(gf_ptr + row * DP + d)
                tl.atomic_add(dfeat_ptr + g * D + d, tl.sum(w * gd[:, None], axis=0), mask=valid)
        base = dprm_ptr + g * Q
        if SURFEL:
            tl.atomic_add(base + 2, tl.sum(de, axis=0), mask=valid)
            d_rho = -0.5 * de
            lp = tl.where(use3, 0.0, d_rho * (-2.0 * inv_sq))
            tl.atomic_add(base + 0, tl.sum(lp * dxl, axis=0), mask=valid)
            tl.atomic_add(base + 1, tl.sum(lp * dyl, axis=0), mask=valid)
            tl.atomic_add(base + 4, tl.sum(tl.where(use3, 0.0, dz), axis=0), mask=valid)
            dzh = tl.where(use3, dz, 0.0)
            dr = tl.where(use3, d_rho, 0.0)
            dh0 = (2.0 * dr * u + dzh * tw0) * inv
            dh1 = (2.0 * dr * v + dzh * tw1) * inv
            dh2 = (-2.0 * dr * rho3 + dzh * (tw2 - zhit)) * inv
            X = x[:, None]
            Y = y[:, None]
            tl.atomic_add(base + 5, tl.sum(dh0 * X, axis=0), mask=valid)
            tl.atomic_add(base + 6, tl.sum(dh1 * X, axis=0), mask=valid)
            tl.atomic_add(base + 7, tl.sum(dh2 * X, axis=0), mask=valid)
            tl.atomic_add(base + 8, tl.sum(dh0 * Y, axis=0), mask=valid)
            tl.atomic_add(base + 9, tl.sum(dh1 * Y, axis=0), mask=valid)
            tl.atomic_add(base + 10, tl.sum(dh2 * Y, axis=0), mask=valid)
            tl.atomic_add(base + 11, tl.sum(dh0, axis=0), mask=valid)
            tl.atomic_add(base + 12, tl.sum(dh1, axis=0), mask=valid)
            tl.atomic_add(base + 13, tl.sum(dh2, axis=0), mask=valid)
            dzi = dzh * inv  # z_hit = (Tw . h) / h2
            tl.atomic_add(base + 14, tl.sum(dzi * h0, axis=0), mask=valid)
            tl.atomic_add(base + 15, tl.sum(dzi * h1, axis=0), mask=valid)
            tl.atomic_add(base + 16, tl.sum(dzh, axis=0), mask=valid)  # h2 inv = 1 where use3
        else:
            tl.atomic_add(
                base + 0, tl.sum(de * (cA[None, :] * dx + cB[None, :] * dy), 0), mask=valid
            )
            tl.atomic_add(
                base + 1, tl.sum(de * (cB[None, :] * dx + cC[None, :] * dy), 0), mask=valid
            )
            tl.atomic_add(base + 2, tl.sum(-0.5 * de * dx * dx, axis=0), mask=valid)
            tl.atomic_add(base + 3, tl.sum(-de * dx * dy, axis=0), mask=valid)
            tl.atomic_add(base + 4, tl.sum(-0.5 * de * dy * dy, axis=0), mask=valid)
            tl.atomic_add(base + 5, tl.sum(de, axis=0), mask=valid)
            tl.atomic_add(base + 7, tl.sum(dz, axis=0), mask=valid)
        prefix += tl.sum(wg, axis=1)
        s += K


def _pack_params(proj: Projected) -> torch.Tensor:
    """[N, Q] float32 kernel rows.

    3DGS: (mx, my, A, B, C, ln o, exp_min, z). 2DGS: (mx, my, ln o, exp_min, z, Px, Py, Pa, Tw).
    """
    lo, emin, z = proj.log_opacity[:, None], proj.exp_min[:, None], proj.depth[:, None]
    if proj.kind == "3dgs":
        cols = [proj.means2d, proj.conic, lo, emin, z]
    else:
        cols = [proj.means2d, lo, emin, z, proj.ray.reshape(-1, 12)]  # type: ignore[union-attr]
    return torch.cat(cols, dim=1).float().contiguous()  # type: ignore[list-item]


def _launch_meta(bins: TileBins, width: int, height: int, near: float, inv_sq: float) -> tuple:
    return (bins.tiles_x, bins.tiles_y, bins.tile_size, width, height, float(near), inv_sq)


class _Composite(torch.autograd.Function):
    """Differentiable compositing of packed rows into per-tile images (float32)."""

    @staticmethod
    def forward(ctx, prm, feats, gids, offsets, meta, surfel):  # type: ignore[override]
        tiles_x, tiles_y, ts, width, height, near, inv_sq = meta
        n_tiles = tiles_x * tiles_y
        D = feats.shape[1]
        DP = max(16, triton.next_power_of_2(D))
        P = ts * ts
        outf = prm.new_empty((n_tiles * P, DP))
        outz = prm.new_empty(n_tiles * P)
        outm = prm.new_empty(n_tiles * P)
        Q = prm.shape[1]
        _forward_kernel[(n_tiles,)](
            prm, feats, gids, offsets, outf, outz, outm,
            tiles_x, width, height, near, inv_sq,
            Q=Q, D=D, DP=DP, TS=ts, K=_K_FWD, SURFEL=surfel, num_warps=_WARPS_FWD if ts == 16 else 2,
        )  # fmt: skip
        ctx.save_for_backward(prm, feats, gids, offsets, outf, outz)
        ctx.meta, ctx.surfel = meta, surfel
        return outf, outz, outm

    @staticmethod
    def backward(ctx, gf, gz, gm):  # type: ignore[override]
        prm, feats, gids, offsets, outf, outz = ctx.saved_tensors
        tiles_x, tiles_y, ts, width, height, near, inv_sq = ctx.meta
        D = feats.shape[1]
        DP = outf.shape[1]
        dprm = torch.zeros_like(prm)
        dfeat = torch.zeros_like(feats)
        _backward_kernel[(tiles_x * tiles_y,)](
            prm, feats, gids, offsets, outf, outz,
            gf.float().contiguous(), gz.float().contiguous(), gm.float().contiguous(),
            dprm, dfeat, tiles_x, width, height, near, inv_sq,
            Q=prm.shape[1], D=D, DP=DP, TS=ts, K=_K_BWD, SURFEL=ctx.surfel, DOT=_BWD_DOT,
            num_warps=_WARPS_BWD if ts == 16 else 2,
        )  # fmt: skip
        return dprm, dfeat, None, None, None, None


def render_triton(gaussians: Gaussians, camera: Camera, config: RenderConfig) -> RenderOutput:
    """Render a pinhole camera with the fused Triton kernels (CUDA; differentiable).

    Args:
        gaussians: N Gaussians on a CUDA device (any device under ``TRITON_INTERPRET=1``).
        camera: pinhole camera.
        config: render options; ``tile_size`` must be 8 or 16 (None: 16); ``chunk`` and
            ``tile_batch`` are not used.

    Returns:
        The render, in the dtype of the inputs (computed in float32).

    Raises:
        InputError: tensors not on a CUDA device, or an unsupported tile size.
    """
    device = gaussians.means.device
    if device.type != "cuda" and not interpreting():
        raise InputError(
            f"the triton backend renders CUDA tensors; these are on {device}",
            where="render(backend='triton')",
            hint="move the Gaussians to a GPU (.to('cuda')) or use backend='torch'",
        )
    ts = config.tile_size or _TILE_SIZE
    if ts not in (8, 16):
        raise InputError(
            f"tile_size {ts} is not supported by the triton backend",
            where="RenderConfig.tile_size",
            hint="use 16 (the default) or 8",
        )
    H, W = camera.height, camera.width
    dtype = gaussians.means.dtype
    proj = None
    if _FUSED_PROJECTION and fused_projection_supports(gaussians, camera, config):
        proj = project_fused(gaussians, camera, config)
    if proj is None:
        proj = project(gaussians, camera, config)
    proj = replace(proj, means2d=visible_means2d(proj.means2d, proj.visible))
    binner = bin_tiles_triton if _TRITON_BINNING else bin_tiles
    bins = binner(proj.bbox, proj.depth, proj.visible, W, H, ts)
    ones = torch.ones_like(proj.depth)[:, None]
    feats = torch.cat([proj.rgb, ones, proj.normals, proj.extra], dim=1).float().contiguous()
    D = feats.shape[1]
    meta = _launch_meta(bins, W, H, camera.near, float(proj.lowpass_inv_sq))
    outf, outz, outm = _Composite.apply(
        _pack_params(proj), feats, bins.gaussian_ids.contiguous(), bins.offsets.contiguous(),
        meta, proj.kind == "2dgs",
    )  # fmt: skip
    ty, tx = bins.tiles_y, bins.tiles_x
    if _FUSED_FINISH:
        imgs = FinishImages.apply(outf, outz, outm, (tx, ty, ts, W, H), config.background, D - 7)
        rgb, alpha, depth, median, normals, extra = (t.to(dtype) for t in imgs)
        return RenderOutput(
            rgb=rgb, alpha=alpha, depth_expected=depth, depth_median=median, normals=normals,
            extra=extra, means2d=proj.means2d, radii=support_radii(proj.bbox, proj.visible),
        )  # fmt: skip
    img = torch.cat([outf[:, :D], outz[:, None], outm[:, None]], dim=1).to(dtype)
    img = img.reshape(ty, tx, ts, ts, D + 2).permute(0, 2, 1, 3, 4).reshape(ty * ts, tx * ts, -1)
    img = img[:H, :W]
    return finish_output(
        img[..., :D], img[..., D], img[..., D + 1], proj.means2d, proj.bbox, proj.visible, config
    )
