"""Optional ``numba`` backend: a fused, forward-only CPU kernel.

Projection and tile binning are the torch backend's; compositing is one compiled loop, parallel
over tiles, sequential over each tile's depth-ordered list (each Gaussian applied to the tile's
open pixels in turn), with the same constants, support cut, stop rule and median definition as
the other backends (a pixel stops at the first pair that would push T below 1e-4, like the 3DGS
reference, instead of evaluating whole chunks).
No gradients: use it for validation renders, not for training. Importing this module fails
without numba; the registry then lists the backend as unavailable with the reason.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import torch

from .binning import bin_tiles
from .camera import Camera
from .config import RenderConfig
from .constants import MAX_ALPHA, MEDIAN_TRANSMITTANCE, TRANSMITTANCE_THRESHOLD
from .gaussians import Gaussians
from .output import RenderOutput
from .projection import project
from .tiled import finish_output, visible_means2d

__all__ = ["render_fused"]

_CPU_TILE_SIZE = 8


@numba.njit(parallel=True, cache=True, fastmath=False)
def _composite(
    tiles: np.ndarray,
    offsets: np.ndarray,
    gids: np.ndarray,
    prm: np.ndarray,
    feats: np.ndarray,
    tiles_x: int,
    ts: int,
    width: int,
    height: int,
    surfels: bool,
    near: float,
    inv_sq: float,
    out: np.ndarray,
) -> None:
    """out[H, W, D + 2] = (sum w f, sum w z, median z) per pixel.

    Gaussian-major within a tile: each Gaussian's parameters are read once and applied to
    every pixel of the tile that is still open (T > 0), as the 3DGS reference's per-tile loop
    does; per pixel the arithmetic and its order are those of a pixel-major loop, so the sums
    are the same to the bit. Accumulators are per tile, in ``out``'s dtype.
    """
    D = feats.shape[1]
    for ti in numba.prange(tiles.shape[0]):
        t = tiles[ti]
        ox = (t % tiles_x) * ts
        oy = (t // tiles_x) * ts
        nx = min(ox + ts, width) - ox
        npx = nx * (min(oy + ts, height) - oy)
        xs = np.empty(npx)
        ys = np.empty(npx)
        for j in range(npx):
            xs[j] = (ox + j % nx) + 0.5
            ys[j] = (oy + j // nx) + 0.5
        Ts = np.ones(npx)  # transmittance; 0 once the pixel has ended
        acc = np.zeros((npx, D + 2), out.dtype)
        open_px = npx
        for k in range(offsets[t], offsets[t + 1]):
            g = gids[k]
            mx = prm[g, 0]
            my = prm[g, 1]
            if surfels:
                # h = x Px + y Py + Pa (Huang et al. 2024), rows 5..16 of prm
                p5, p6, p7, p8 = prm[g, 5], prm[g, 6], prm[g, 7], prm[g, 8]
                p9, p10, p11, p12 = prm[g, 9], prm[g, 10], prm[g, 11], prm[g, 12]
                p13, p14, p15, p16 = prm[g, 13], prm[g, 14], prm[g, 15], prm[g, 16]
                lo, e_min, zc = prm[g, 2], prm[g, 3], prm[g, 4]
            else:
                cA, cB, cC = prm[g, 2], prm[g, 3], prm[g, 4]
                lo, e_min, zc = prm[g, 5], prm[g, 6], prm[g, 7]
            for j in range(npx):
                T = Ts[j]
                if T == 0.0:
                    continue
                x = xs[j]
                y = ys[j]
                dx = x - mx
                dy = y - my
                z = zc
                if surfels:
                    h0 = x * p5 + y * p8 + p11
                    h1 = x * p6 + y * p9 + p12
                    h2 = x * p7 + y * p10 + p13
                    rho = inv_sq * (dx * dx + dy * dy)
                    if h2 != 0.0:
                        u = h0 / h2
                        v = h1 / h2
                        zh = (p14 * h0 + p15 * h1 + p16 * h2) / h2
                        r3 = u * u + v * v
                        if zh > near and r3 <= rho:
                            rho = r3
                            z = zh
                    e = lo - 0.5 * rho
                else:
                    e = lo - (0.5 * (cA * dx * dx + cC * dy * dy) + cB * dx * dy)
                if e < e_min:
                    continue
                alpha = min(MAX_ALPHA, math.exp(e))
                T_next = T * (1.0 - alpha)
                if T_next < TRANSMITTANCE_THRESHOLD:
                    Ts[j] = 0.0
                    open_px -= 1
                    continue
                w = alpha * T
                for d in range(D):
                    acc[j, d] += w * feats[g, d]
                acc[j, D] += w * z
                if T > MEDIAN_TRANSMITTANCE and T_next <= MEDIAN_TRANSMITTANCE:
                    acc[j, D + 1] = z
                Ts[j] = T_next
            if open_px == 0:
                break
        for j in range(npx):
            py = oy + j // nx
            px = ox + j % nx
            for d in range(D + 2):
                out[py, px, d] = acc[j, d]


def render_fused(gaussians: Gaussians, camera: Camera, config: RenderConfig) -> RenderOutput:
    """Forward-only render with the compiled kernel (CPU; inputs on another device are copied).

    Args:
        gaussians: N Gaussians, world frame.
        camera: pinhole camera.
        config: render options (``chunk`` and ``tile_batch`` are not used).

    Returns:
        The render, detached, on the device and dtype of the inputs.
    """
    H, W = camera.height, camera.width
    with torch.no_grad():
        proj = project(gaussians, camera, config)
        ts = config.tile_size or _CPU_TILE_SIZE
        bins = bin_tiles(proj.bbox, proj.depth, proj.visible, W, H, ts)
        ones = torch.ones_like(proj.depth)[:, None]
        feats = torch.cat([proj.rgb, ones, proj.normals, proj.extra], dim=1)
        if proj.kind == "3dgs":
            head = [
                proj.means2d,
                proj.conic,
                proj.log_opacity[:, None],
                proj.exp_min[:, None],
                proj.depth[:, None],
            ]
        else:
            head = [
                proj.means2d,
                proj.log_opacity[:, None],
                proj.exp_min[:, None],
                proj.depth[:, None],
                proj.ray.reshape(-1, 12),
            ]  # type: ignore[union-attr]
        prm = torch.cat(head, dim=1)
        np_dtype = np.float64 if feats.dtype == torch.float64 else np.float32
        D = feats.shape[1]
        out = np.zeros((H, W, D + 2), dtype=np_dtype)
        tiles = torch.nonzero(bins.counts > 0).flatten()
        numba.set_num_threads(max(1, min(torch.get_num_threads(), numba.config.NUMBA_NUM_THREADS)))
        _composite(
            tiles.cpu().numpy(),
            bins.offsets.cpu().numpy(),
            bins.gaussian_ids.cpu().numpy(),
            np.ascontiguousarray(prm.cpu().numpy().astype(np_dtype)),
            np.ascontiguousarray(feats.cpu().numpy().astype(np_dtype)),
            bins.tiles_x,
            ts,
            W,
            H,
            proj.kind == "2dgs",
            float(camera.near),
            float(proj.lowpass_inv_sq),
            out,
        )
        img = torch.from_numpy(out).to(device=feats.device, dtype=feats.dtype)
        return finish_output(
            img[..., :D],
            img[..., D],
            img[..., D + 1],
            visible_means2d(proj.means2d, proj.visible),
            proj.bbox,
            proj.visible,
            config,
        )
