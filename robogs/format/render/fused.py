"""Optional ``numba`` backend: a fused, forward-only CPU kernel.

Projection and tile binning are the torch backend's; compositing is one compiled loop, parallel
over tiles, sequential over each pixel's depth-ordered list, with the same constants, support
cut, stop rule and median definition as the other backends (it stops at the first pair that
would push T below 1e-4, like the 3DGS reference, instead of evaluating whole chunks).
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
    """out[H, W, D + 2] = (sum w f, sum w z, median z) per pixel."""
    D = feats.shape[1]
    for ti in numba.prange(tiles.shape[0]):
        t = tiles[ti]
        ox = (t % tiles_x) * ts
        oy = (t // tiles_x) * ts
        s0 = offsets[t]
        s1 = offsets[t + 1]
        for py in range(oy, min(oy + ts, height)):
            y = py + 0.5
            for px in range(ox, min(ox + ts, width)):
                x = px + 0.5
                T = 1.0
                for k in range(s0, s1):
                    g = gids[k]
                    if surfels:
                        # h = x Px + y Py + Pa (Huang et al. 2024), rows 5..16 of prm
                        h0 = x * prm[g, 5] + y * prm[g, 8] + prm[g, 11]
                        h1 = x * prm[g, 6] + y * prm[g, 9] + prm[g, 12]
                        h2 = x * prm[g, 7] + y * prm[g, 10] + prm[g, 13]
                        dx = x - prm[g, 0]
                        dy = y - prm[g, 1]
                        rho = inv_sq * (dx * dx + dy * dy)
                        z = prm[g, 4]
                        if h2 != 0.0:
                            u = h0 / h2
                            v = h1 / h2
                            zh = (prm[g, 14] * h0 + prm[g, 15] * h1 + prm[g, 16] * h2) / h2
                            r3 = u * u + v * v
                            if zh > near and r3 <= rho:
                                rho = r3
                                z = zh
                        e = prm[g, 2] - 0.5 * rho
                        e_min = prm[g, 3]
                    else:
                        dx = x - prm[g, 0]
                        dy = y - prm[g, 1]
                        e = prm[g, 5] - (
                            0.5 * (prm[g, 2] * dx * dx + prm[g, 4] * dy * dy) + prm[g, 3] * dx * dy
                        )
                        e_min = prm[g, 6]
                        z = prm[g, 7]
                    if e < e_min:
                        continue
                    alpha = min(MAX_ALPHA, math.exp(e))
                    T_next = T * (1.0 - alpha)
                    if T_next < TRANSMITTANCE_THRESHOLD:
                        break
                    w = alpha * T
                    for d in range(D):
                        out[py, px, d] += w * feats[g, d]
                    out[py, px, D] += w * z
                    if T > MEDIAN_TRANSMITTANCE and T_next <= MEDIAN_TRANSMITTANCE:
                        out[py, px, D + 1] = z
                    T = T_next


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
