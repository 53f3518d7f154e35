"""The last step of a triton render in one kernel each way: tile rows to normalised images.

The compositing kernels write per-tile rows (accumulated features, depth sum, median depth).
``render_tiled``'s ``finish_output`` turns such images into a ``RenderOutput`` with about 35
small torch ops forward (concatenation, tile-to-image permutation, background, division by
alpha) and as many backward. :class:`FinishImages` does the same in one Triton program per tile,
forward and backward, with the same arithmetic (``1 / alpha`` correctly rounded, then products):

- ``rgb = f_rgb + (1 - alpha) bg``; ``alpha = f_alpha``;
- ``depth_expected = z_sum / alpha``, ``normals = f_n / alpha`` where ``alpha > 0``, else 0;
- ``depth_median`` and ``extra`` as accumulated.

Its outputs equal ``finish_output``'s (``tests/render/test_triton_finish.py``).
"""

from __future__ import annotations

import torch
import triton
import triton.language as tl

__all__ = ["FinishImages"]


@triton.jit
def _pixels(t, tiles_x, width, height, TS: tl.constexpr):
    p = tl.arange(0, TS * TS)
    px = (t % tiles_x) * TS + p % TS
    py = (t // tiles_x) * TS + p // TS
    inside = (px < width) & (py < height)
    return p, py * width + px, inside


@triton.jit
def _finish_fwd_kernel(
    outf_ptr, outz_ptr, outm_ptr, rgb_ptr, a_ptr, z_ptr, m_ptr, n_ptr, x_ptr,
    tiles_x, width, height, bg0, bg1, bg2,
    DP: tl.constexpr, E: tl.constexpr, EP: tl.constexpr, TS: tl.constexpr,
):  # fmt: skip
    t = tl.program_id(0)
    p, pix, inside = _pixels(t, tiles_x, width, height, TS)
    row = (t * (TS * TS) + p) * DP
    a = tl.load(outf_ptr + row + 3)
    has = a > 0.0
    inv = tl.math.div_rn(1.0, tl.where(has, a, 1.0))
    bga = 1.0 - a
    tl.store(rgb_ptr + pix * 3 + 0, tl.load(outf_ptr + row + 0) + bga * bg0, mask=inside)
    tl.store(rgb_ptr + pix * 3 + 1, tl.load(outf_ptr + row + 1) + bga * bg1, mask=inside)
    tl.store(rgb_ptr + pix * 3 + 2, tl.load(outf_ptr + row + 2) + bga * bg2, mask=inside)
    tl.store(a_ptr + pix, a, mask=inside)
    zs = tl.load(outz_ptr + t * (TS * TS) + p)
    tl.store(z_ptr + pix, tl.where(has, zs * inv, 0.0), mask=inside)
    tl.store(m_ptr + pix, tl.load(outm_ptr + t * (TS * TS) + p), mask=inside)
    for k in tl.static_range(3):
        nk = tl.load(outf_ptr + row + 4 + k)
        tl.store(n_ptr + pix * 3 + k, tl.where(has, nk * inv, 0.0), mask=inside)
    if E > 0:
        e = tl.arange(0, EP)
        em = inside[:, None] & (e[None, :] < E)
        xv = tl.load(outf_ptr + row[:, None] + 7 + e[None, :], mask=em, other=0.0)
        tl.store(x_ptr + pix[:, None] * E + e[None, :], xv, mask=em)


@triton.jit
def _finish_bwd_kernel(
    outf_ptr, outz_ptr, g_rgb, g_a, g_z, g_m, g_n, g_x, gf_ptr, gz_ptr, gm_ptr,
    tiles_x, width, height, bg0, bg1, bg2,
    DP: tl.constexpr, E: tl.constexpr, EP: tl.constexpr, TS: tl.constexpr,
    H_RGB: tl.constexpr, H_A: tl.constexpr, H_Z: tl.constexpr, H_M: tl.constexpr,
    H_N: tl.constexpr, H_X: tl.constexpr,
):  # fmt: skip
    t = tl.program_id(0)
    p, pix, inside = _pixels(t, tiles_x, width, height, TS)
    r = t * (TS * TS) + p
    row = r * DP
    a = tl.load(outf_ptr + row + 3)
    has = (a > 0.0) & inside
    inv = tl.math.div_rn(1.0, tl.where(has, a, 1.0))
    zero = tl.zeros([TS * TS], dtype=tl.float32)
    ga = zero
    if H_A:
        ga += tl.load(g_a + pix, mask=inside, other=0.0)
    if H_RGB:
        g0 = tl.load(g_rgb + pix * 3 + 0, mask=inside, other=0.0)
        g1 = tl.load(g_rgb + pix * 3 + 1, mask=inside, other=0.0)
        g2 = tl.load(g_rgb + pix * 3 + 2, mask=inside, other=0.0)
        tl.store(gf_ptr + row + 0, g0)
        tl.store(gf_ptr + row + 1, g1)
        tl.store(gf_ptr + row + 2, g2)
        ga -= g0 * bg0 + g1 * bg1 + g2 * bg2
    else:
        tl.store(gf_ptr + row + 0, zero)
        tl.store(gf_ptr + row + 1, zero)
        tl.store(gf_ptr + row + 2, zero)
    gzs = zero
    if H_Z:
        gd = tl.load(g_z + pix, mask=inside, other=0.0)
        zs = tl.load(outz_ptr + r)
        gzs = tl.where(has, gd * inv, 0.0)
        ga -= tl.where(has, gzs * zs * inv, 0.0)
    tl.store(gz_ptr + r, gzs)
    for k in tl.static_range(3):
        gnk = zero
        if H_N:
            gn = tl.load(g_n + pix * 3 + k, mask=inside, other=0.0)
            nk = tl.load(outf_ptr + row + 4 + k)
            gnk = tl.where(has, gn * inv, 0.0)
            ga -= tl.where(has, gnk * nk * inv, 0.0)
        tl.store(gf_ptr + row + 4 + k, gnk)
    tl.store(gf_ptr + row + 3, ga)
    gmv = zero
    if H_M:
        gmv = tl.load(g_m + pix, mask=inside, other=0.0)
    tl.store(gm_ptr + r, gmv)
    c = tl.arange(0, DP)
    tail = c[None, :] >= 7
    gx = tl.zeros([TS * TS, DP], dtype=tl.float32)
    if H_X:
        if E > 0:
            xm = inside[:, None] & tail & (c[None, :] < 7 + E)
            gx = tl.load(g_x + pix[:, None] * E + (c[None, :] - 7), mask=xm, other=0.0)
    tl.store(gf_ptr + row[:, None] + c[None, :], gx, mask=tail & (c[None, :] < DP))


class FinishImages(torch.autograd.Function):
    """Tile rows (``outf`` [tiles * P, DP], ``outz``, ``outm`` [tiles * P], float32) to the
    images (rgb, alpha, depth_expected, depth_median, normals, extra), each [H, W, ...] float32."""

    @staticmethod
    def forward(ctx, outf, outz, outm, meta, background, n_extra):  # type: ignore[override]
        tiles_x, tiles_y, ts, width, height = meta
        DP = outf.shape[1]
        new = outf.new_empty
        rgb, a, z, m = (
            new((height, width, 3)),
            new((height, width)),
            new((height, width)),
            new((height, width)),
        )
        n, x = new((height, width, 3)), new((height, width, n_extra))
        bg = [float(b) for b in background]
        EP = max(2, triton.next_power_of_2(max(n_extra, 1)))
        _finish_fwd_kernel[(tiles_x * tiles_y,)](
            outf, outz, outm, rgb, a, z, m, n, x, tiles_x, width, height, *bg,
            DP=DP, E=n_extra, EP=EP, TS=ts, num_warps=4,
        )  # fmt: skip
        ctx.save_for_backward(outf, outz)
        ctx.meta, ctx.bg, ctx.n_extra = meta, bg, n_extra
        ctx.set_materialize_grads(False)
        return rgb, a, z, m, n, x

    @staticmethod
    def backward(ctx, g_rgb, g_a, g_z, g_m, g_n, g_x):  # type: ignore[override]
        outf, outz = ctx.saved_tensors
        tiles_x, tiles_y, ts, width, height = ctx.meta
        DP, E = outf.shape[1], ctx.n_extra
        gf = torch.empty_like(outf)
        gz = torch.empty_like(outz)
        gm = torch.empty_like(outz)
        grads = [g_rgb, g_a, g_z, g_m, g_n, g_x]
        ptrs = [g.float().contiguous() if g is not None else outz for g in grads]
        _finish_bwd_kernel[(tiles_x * tiles_y,)](
            outf, outz, *ptrs, gf, gz, gm, tiles_x, width, height, *ctx.bg,
            DP=DP, E=E, EP=max(2, triton.next_power_of_2(max(E, 1))), TS=ts,
            H_RGB=g_rgb is not None, H_A=g_a is not None, H_Z=g_z is not None,
            H_M=g_m is not None, H_N=g_n is not None, H_X=g_x is not None and E > 0,
            num_warps=4,
        )  # fmt: skip
        return gf, gz, gm, None, None, None
