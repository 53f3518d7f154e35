"""The dense oracle: every pixel against every Gaussian, composited one Gaussian at a time.

Simple and slow on purpose. It shares no code with the tiled backend beyond the SH colour and the
quaternion formula (each tested on its own): the 3DGS covariance is built in the world frame and
inverted with ``torch.linalg.inv``; the 2DGS splat point is found by intersecting the pixel ray
with the surfel plane (instead of the homogeneous plane cross product); compositing is the
per-pixel loop of the 3DGS reference ``renderCUDA``, vectorised over pixels only.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..frames import quat_to_matrix as quat_to_rotmat
from .camera import Camera
from .config import RenderConfig
from .constants import (
    ALPHA_THRESHOLD,
    FOV_CLAMP_MARGIN,
    LOWPASS_2DGS_INV_SQ,
    LOWPASS_3DGS_PX2,
    MAX_ALPHA,
    MAX_EXPONENT,
    MEDIAN_TRANSMITTANCE,
    TRANSMITTANCE_THRESHOLD,
)
from .gaussians import Gaussians
from .output import RenderOutput
from .sh import eval_sh

__all__ = ["render_dense"]


#: the default options (frozen, so sharing one instance is safe)
_DEFAULT_CONFIG = RenderConfig()


def render_dense(
    gaussians: Gaussians,
    camera: Camera,
    config: RenderConfig = _DEFAULT_CONFIG,
    *,
    pixels: torch.Tensor | None = None,
) -> RenderOutput:
    """Brute-force render of a pinhole camera.

    Args:
        gaussians: N Gaussians, world frame.
        camera: the camera (its distortion is ignored unless ``pixels`` encodes it).
        config: render options.
        pixels: optional [H, W, 2] pinhole image coordinates (px) at which to evaluate each
            output pixel; default the pixel centres (x + 0.5, y + 0.5). Passing undistorted
            positions renders a distorted camera exactly.

    Returns:
        The render, same conventions as every backend.
    """
    g = gaussians
    dtype, device = g.means.dtype, g.means.device
    H, W = camera.height, camera.width
    if pixels is None:
        ys, xs = torch.meshgrid(
            torch.arange(H, dtype=dtype, device=device) + 0.5,
            torch.arange(W, dtype=dtype, device=device) + 0.5,
            indexing="ij",
        )
        pixels = torch.stack([xs, ys], dim=-1)
    H, W = pixels.shape[0], pixels.shape[1]
    pix = pixels.reshape(-1, 2).to(dtype)

    T_wc = camera.T_world_cam.to(dtype=dtype, device=device)
    W_rot = torch.linalg.inv(T_wc)[:3, :3]  # world -> camera rotation
    T_cw = torch.linalg.inv(T_wc)
    p_c = (T_cw[:3, :3] @ g.means.T).T + T_cw[:3, 3]
    in_depth = (p_c[:, 2] > camera.near) & (p_c[:, 2] < camera.far)
    z = torch.where(in_depth, p_c[:, 2], torch.ones_like(p_c[:, 2]))  # culled rows stay finite
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    R = quat_to_rotmat(g.quats)
    s = torch.exp(g.log_scales)
    o = torch.sigmoid(g.opacity_logits)
    centre = torch.stack([fx * p_c[:, 0] / z + cx, fy * p_c[:, 1] / z + cy], dim=-1)
    n_pix = pix.shape[0]

    if config.kind == "3dgs":
        S = torch.diag_embed(s)
        cov3 = R @ S @ S @ R.transpose(1, 2)  # world frame
        tan_x, tan_y = 0.5 * camera.width / fx, 0.5 * camera.height / fy
        lim = (
            cx / fx + FOV_CLAMP_MARGIN * tan_x,
            (camera.width - cx) / fx + FOV_CLAMP_MARGIN * tan_x,
            cy / fy + FOV_CLAMP_MARGIN * tan_y,
            (camera.height - cy) / fy + FOV_CLAMP_MARGIN * tan_y,
        )
        tx = torch.clamp(p_c[:, 0] / z, -lim[0], lim[1]) * z
        ty = torch.clamp(p_c[:, 1] / z, -lim[2], lim[3]) * z
        J = torch.zeros(len(g), 2, 3, dtype=dtype, device=device)
        J[:, 0, 0] = fx / z
        J[:, 0, 2] = -fx * tx / (z * z)
        J[:, 1, 1] = fy / z
        J[:, 1, 2] = -fy * ty / (z * z)
        cov2 = J @ W_rot @ cov3 @ W_rot.T @ J.transpose(1, 2)
        cov2_lp = cov2 + LOWPASS_3DGS_PX2 * config.lowpass_scale**2 * torch.eye(
            2, dtype=dtype, device=device
        )
        if config.antialiased:
            o = o * torch.sqrt(torch.linalg.det(cov2).clamp_min(0) / torch.linalg.det(cov2_lp))
        conic = torch.linalg.inv(cov2_lp)
        alive = in_depth & (o >= ALPHA_THRESHOLD)
        means2d = torch.where(alive[:, None], centre, 0.0)  # the returned tensor (see below)
        d = pix[:, None, :] - means2d[None, :, :]  # [HW, N, 2]
        power = 0.5 * torch.einsum("pni,nij,pnj->pn", d, conic, d)
        depth = z[None, :].expand(n_pix, -1)
        normal_axis = torch.gather(
            W_rot @ R, 2, g.log_scales.argmin(1)[:, None, None].expand(-1, 3, 1)
        ).squeeze(2)
    else:
        a_u = (W_rot @ R[:, :, 0:1]).squeeze(-1) * s[:, 0:1]
        a_v = (W_rot @ R[:, :, 1:2]).squeeze(-1) * s[:, 1:2]
        n = torch.linalg.cross(a_u, a_v)
        ray = torch.stack(
            [(pix[:, 0] - cx) / fx, (pix[:, 1] - cy) / fy, torch.ones_like(pix[:, 0])], -1
        )
        denom = ray @ n.T  # [HW, N]
        numer = (n * p_c).sum(-1)[None, :]
        ok = denom != 0
        t = numer / torch.where(ok, denom, torch.ones_like(denom))  # ray parameter = hit depth
        hit = t[..., None] * ray[:, None, :]  # [HW, N, 3]
        rel = hit - p_c[None]
        u = (rel * a_u[None]).sum(-1) / (s[:, 0] ** 2)[None]
        v = (rel * a_v[None]).sum(-1) / (s[:, 1] ** 2)[None]
        rho3 = u * u + v * v
        alive = in_depth & (o >= ALPHA_THRESHOLD)
        means2d = torch.where(alive[:, None], centre, 0.0)
        dd = pix[:, None, :] - means2d[None, :, :]
        rho2 = LOWPASS_2DGS_INV_SQ / config.lowpass_scale**2 * (dd * dd).sum(-1)
        use3 = ok & (t > camera.near) & (rho3 <= rho2)
        power = 0.5 * torch.where(use3, rho3, rho2)
        depth = torch.where(use3, t, z[None, :].expand(n_pix, -1))
        normal_axis = (W_rot @ R[:, :, 2:3]).squeeze(-1)

    facing = torch.where((normal_axis * p_c).sum(-1) > 0, -1.0, 1.0).to(dtype)
    normals = normal_axis * facing[:, None]
    cam_centre = T_wc[:3, 3]
    dirs = F.normalize(g.means - cam_centre, dim=-1)
    rgb_g = eval_sh(g.sh, dirs, config.sh_degree)
    extra_g = g.extra if g.extra is not None else g.means.new_zeros((len(g), 0))

    order = torch.nonzero(alive).flatten()
    order = order[torch.argsort(z.detach()[order], stable=True)]

    T = torch.ones(n_pix, dtype=dtype, device=device)
    done = torch.zeros(n_pix, dtype=torch.bool, device=device)
    rgb = torch.zeros(n_pix, 3, dtype=dtype, device=device)
    dep = torch.zeros(n_pix, dtype=dtype, device=device)
    med = torch.zeros(n_pix, dtype=dtype, device=device)
    nrm = torch.zeros(n_pix, 3, dtype=dtype, device=device)
    ext = torch.zeros(n_pix, extra_g.shape[1], dtype=dtype, device=device)
    for i in order.tolist():  # front to back, like the per-pixel reference loop
        alpha = torch.clamp(o[i] * torch.exp(-power[:, i]), max=MAX_ALPHA)
        inside = (power[:, i] <= MAX_EXPONENT) & (alpha >= ALPHA_THRESHOLD) & ~done
        T_next = T * (1.0 - alpha)
        stop = inside & (T_next < TRANSMITTANCE_THRESHOLD)
        done = done | stop
        use = inside & ~stop
        w = torch.where(use, alpha * T, 0.0)
        rgb = rgb + w[:, None] * rgb_g[i]
        dep = dep + w * depth[:, i]
        nrm = nrm + w[:, None] * normals[i]
        ext = ext + w[:, None] * extra_g[i]
        crossed = use & (T > MEDIAN_TRANSMITTANCE) & (T_next <= MEDIAN_TRANSMITTANCE)
        med = torch.where(crossed, depth[:, i], med)
        T = torch.where(use, T_next, T)

    alpha_img = 1.0 - T
    has = alpha_img > 0
    inv = 1.0 / torch.where(has, alpha_img, torch.ones_like(alpha_img))
    bg = torch.tensor(config.background, dtype=dtype, device=device)
    radii = torch.zeros(len(g), 2, dtype=dtype, device=device)
    return RenderOutput(
        rgb=(rgb + (1.0 - alpha_img)[:, None] * bg).reshape(H, W, 3),
        alpha=alpha_img.reshape(H, W),
        depth_expected=torch.where(has, dep * inv, 0.0).reshape(H, W),
        depth_median=med.reshape(H, W),
        normals=torch.where(has[:, None], nrm * inv[:, None], 0.0).reshape(H, W, 3),
        extra=ext.reshape(H, W, -1),
        # the tensor the kernels were evaluated at: its gradient is dL/d(screen mean)
        means2d=means2d,
        radii=radii,
    )
