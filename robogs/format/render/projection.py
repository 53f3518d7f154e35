"""Per-Gaussian projection: screen-space kernels, extents, colours and culling.

3DGS follows EWA splatting as in Kerbl et al. 2023 (Zwicker et al. 2001): the camera-frame
covariance is pushed through the Jacobian of the pinhole projection at the mean, with tx/tz and
ty/tz clamped to the widened field of view (gsplat's asymmetric form), and a 0.3 px^2 low-pass
is added to the 2D covariance.

2DGS follows Huang et al. 2024: a surfel P(u, v) = p + s_u t_u u + s_v t_v v is mapped to the
image by the 3x3 "ray transform" ``Tm = K [R s_u t_u, R s_v t_v, p_c]`` with rows Tu, Tv, Tw. The
pixel (x, y) is the intersection of the planes (x Tw - Tu) and (y Tw - Tv), so the splat point is
``h = (x Tw - Tu) x (y Tw - Tv) = x (Tv x Tw) + y (Tw x Tu) + Tu x Tv``, affine in (x, y), with
u = h0 / h2 and v = h1 / h2. The screen bounding box is that of the projected 3-sigma disk,
obtained from the dual conic ``Tm diag(r^2, r^2, -1) Tm^T`` (as in the 2DGS reference
``compute_aabb``), joined with the low-pass circle.

Support: a pair contributes only where its exponent sigma <= min(4.5, ln(255 o)), i.e. inside
the 3-sigma ellipse and where alpha >= 1/255. The bounding boxes enclose exactly this region, so
results do not depend on the tile size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from ..frames import quat_to_matrix as quat_to_rotmat
from .camera import Camera
from .config import RenderConfig
from .constants import (
    ALPHA_THRESHOLD,
    FOV_CLAMP_MARGIN,
    LOG_ALPHA_THRESHOLD,
    LOWPASS_2DGS_INV_SQ,
    LOWPASS_3DGS_PX2,
    MAX_EXPONENT,
)
from .gaussians import Gaussians
from .sh import eval_sh

__all__ = ["Projected", "project", "lowpass_inv_sq"]


@dataclass(frozen=True, eq=False)
class Projected:
    """Screen-space data of N Gaussians for one camera.

    Attributes:
        kind: "3dgs" or "2dgs".
        lowpass_inv_sq: 2DGS screen filter coefficient k of rho_2d = k |x - c|^2.
        means2d: [N, 2] projected means, px.
        depth: [N] camera-frame z of the means, m (the sort key).
        log_opacity: [N] log of the (possibly anti-aliased) opacity.
        exp_min: [N] smallest admissible exponent ln(alpha_raw): max(ln(1/255), ln o - 4.5).
        conic: [N, 3] (A, B, C) of the inverse 2D covariance, 1/px^2 (3DGS;
            sigma = 0.5 (A dx^2 + C dy^2) + B dx dy), else None.
        ray: [N, 4, 3] rows Px, Py, Pa, Tw with h(x, y) = x Px + y Py + Pa and z = Tw.h / h2
            (2DGS), else None.
        bbox: [N, 4] (xmin, xmax, ymin, ymax) of the support, px (detached).
        visible: [N] bool: in front of the camera, within near/far, opaque enough, on screen.
        rgb: [N, 3] view-dependent colour.
        normals: [N, 3] unit normals in the camera frame, facing the camera.
        extra: [N, C] extra channels.
    """

    kind: str
    lowpass_inv_sq: float
    means2d: torch.Tensor
    depth: torch.Tensor
    log_opacity: torch.Tensor
    exp_min: torch.Tensor
    conic: torch.Tensor | None
    ray: torch.Tensor | None
    bbox: torch.Tensor
    visible: torch.Tensor
    rgb: torch.Tensor
    normals: torch.Tensor
    extra: torch.Tensor


def _fov_limits(camera: Camera) -> tuple[float, float, float, float]:
    tan_x = 0.5 * camera.width / camera.fx
    tan_y = 0.5 * camera.height / camera.fy
    return (
        camera.cx / camera.fx + FOV_CLAMP_MARGIN * tan_x,
        (camera.width - camera.cx) / camera.fx + FOV_CLAMP_MARGIN * tan_x,
        camera.cy / camera.fy + FOV_CLAMP_MARGIN * tan_y,
        (camera.height - camera.cy) / camera.fy + FOV_CLAMP_MARGIN * tan_y,
    )


def project(gaussians: Gaussians, camera: Camera, config: RenderConfig) -> Projected:
    """Project ``gaussians`` into ``camera`` (pinhole; distortion is handled by the caller).

    Args:
        gaussians: N Gaussians, world frame; the kind follows ``config.kind``.
        camera: the camera; its distortion is ignored here.
        config: render options (kind, SH degree, anti-aliasing).

    Returns:
        The per-Gaussian screen-space data, differentiable w.r.t. all Gaussian fields.
    """
    g = gaussians
    dtype, device = g.means.dtype, g.means.device
    R_cw, t_cw, cam_centre = camera.world_to_cam(dtype, device)
    p_c = g.means @ R_cw.T + t_cw
    z = p_c[:, 2]
    in_depth = (z > camera.near) & (z < camera.far)
    zs = torch.where(in_depth, z, torch.ones_like(z))
    fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
    means2d = torch.stack([fx * p_c[:, 0] / zs + cx, fy * p_c[:, 1] / zs + cy], dim=-1)

    R = quat_to_rotmat(g.quats)
    R_c = R_cw @ R  # [N, 3, 3] Gaussian axes in the camera frame
    scales = torch.exp(g.log_scales)
    log_o = F.logsigmoid(g.opacity_logits)

    normal_axis = R_c[:, :, 2] if config.kind == "2dgs" else _shortest_axis(R_c, g.log_scales)
    facing = torch.where((normal_axis * p_c).sum(-1) > 0, -1.0, 1.0).to(dtype)
    normals = normal_axis * facing[:, None]

    dirs = g.means - cam_centre
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    rgb = eval_sh(g.sh, dirs, config.sh_degree)
    extra = g.extra if g.extra is not None else g.means.new_zeros((len(g), 0))

    conic = ray = None
    if config.kind == "3dgs":
        xn, xp, yn, yp = _fov_limits(camera)
        txz = (p_c[:, 0] / zs).clamp(-xn, xp)
        tyz = (p_c[:, 1] / zs).clamp(-yn, yp)
        zero = torch.zeros_like(zs)
        J = torch.stack(
            [fx / zs, zero, -fx * txz / zs, zero, fy / zs, -fy * tyz / zs], dim=-1
        ).reshape(-1, 2, 3)
        JM = J @ (R_c * scales[:, None, :])
        cov = JM @ JM.transpose(1, 2)
        lowpass = LOWPASS_3DGS_PX2 * config.lowpass_scale**2
        a = cov[:, 0, 0] + lowpass
        b = cov[:, 0, 1]
        c = cov[:, 1, 1] + lowpass
        det = a * c - b * b
        det_safe = det.clamp_min(1e-30)
        if config.antialiased:
            ratio = (cov[:, 0, 0] * cov[:, 1, 1] - b * b).clamp_min(0.0) / det_safe
            log_o = log_o + 0.5 * torch.log(ratio.clamp_min(1e-30))
        conic = torch.stack([c / det_safe, -b / det_safe, a / det_safe], dim=-1)
        with torch.no_grad():
            s_max = _exponent_range(log_o)
            rx = torch.sqrt(2.0 * s_max * a.clamp_min(0))
            ry = torch.sqrt(2.0 * s_max * c.clamp_min(0))
            m = means2d.detach()
            bbox = torch.stack([m[:, 0] - rx, m[:, 0] + rx, m[:, 1] - ry, m[:, 1] + ry], dim=-1)
            ok = det > 0
    else:
        col_u = R_c[:, :, 0] * scales[:, 0:1]
        col_v = R_c[:, :, 1] * scales[:, 1:2]
        Tm = torch.stack(
            [_apply_K(col_u, camera), _apply_K(col_v, camera), _apply_K(p_c, camera)], dim=-1
        )
        Tu, Tv, Tw = Tm[:, 0, :], Tm[:, 1, :], Tm[:, 2, :]
        ray = torch.stack(
            [
                torch.linalg.cross(Tv, Tw),
                torch.linalg.cross(Tw, Tu),
                torch.linalg.cross(Tu, Tv),
                Tw,
            ],
            dim=1,
        )
        with torch.no_grad():
            s_max = _exponent_range(log_o)
            bbox = _surfel_bbox(
                Tm.detach(), means2d.detach(), 2.0 * s_max, camera, lowpass_inv_sq(config)
            )
            ok = torch.ones_like(in_depth)

    with torch.no_grad():
        exp_min = torch.maximum(
            torch.full_like(log_o, LOG_ALPHA_THRESHOLD), log_o - MAX_EXPONENT
        ).detach()
        on_screen = (
            (bbox[:, 1] > 0)
            & (bbox[:, 0] < camera.width)
            & (bbox[:, 3] > 0)
            & (bbox[:, 2] < camera.height)
        )
        visible = in_depth & ok & (log_o >= math.log(ALPHA_THRESHOLD)) & on_screen
        visible &= torch.isfinite(bbox).all(dim=1)
    return Projected(
        kind=config.kind,
        lowpass_inv_sq=lowpass_inv_sq(config),
        means2d=means2d,
        depth=z,
        log_opacity=log_o,
        exp_min=exp_min,
        conic=conic,
        ray=ray,
        bbox=bbox,
        visible=visible,
        rgb=rgb,
        normals=normals,
        extra=extra,
    )


def _exponent_range(log_o: torch.Tensor) -> torch.Tensor:
    """Largest exponent sigma of the support: min(4.5, ln(255 o)), clamped at 0."""
    return torch.clamp(log_o - LOG_ALPHA_THRESHOLD, min=0.0, max=MAX_EXPONENT)


def _shortest_axis(R_c: torch.Tensor, log_scales: torch.Tensor) -> torch.Tensor:
    idx = log_scales.detach().argmin(dim=1)
    return torch.gather(R_c, 2, idx[:, None, None].expand(-1, 3, 1)).squeeze(2)


def _apply_K(v: torch.Tensor, camera: Camera) -> torch.Tensor:
    """K @ v for [N, 3] camera-frame vectors."""
    return torch.stack(
        [
            camera.fx * v[:, 0] + camera.cx * v[:, 2],
            camera.fy * v[:, 1] + camera.cy * v[:, 2],
            v[:, 2],
        ],
        dim=-1,
    )


def lowpass_inv_sq(config: RenderConfig) -> float:
    """Coefficient of the 2DGS screen filter rho_2d = k |x - c|^2 on the render grid."""
    return LOWPASS_2DGS_INV_SQ / config.lowpass_scale**2


def _surfel_bbox(
    Tm: torch.Tensor, centre: torch.Tensor, rho_max: torch.Tensor, camera: Camera, inv_sq: float
) -> torch.Tensor:
    """Bounding box of {rho <= rho_max}: the projected disk u^2 + v^2 <= rho_max joined with the
    low-pass circle 2 |x - c|^2 <= rho_max. Disks reaching behind the camera get the full screen."""
    r2 = rho_max[:, None, None]
    c0, c1, c2 = Tm[:, :, 0], Tm[:, :, 1], Tm[:, :, 2]
    D = (
        r2 * (c0[:, :, None] * c0[:, None, :] + c1[:, :, None] * c1[:, None, :])
        - c2[:, :, None] * c2[:, None, :]
    )
    d22 = D[:, 2, 2]
    bounded = d22 < 0
    d22s = torch.where(bounded, d22, -torch.ones_like(d22))
    xc, yc = D[:, 0, 2] / d22s, D[:, 1, 2] / d22s
    hx = torch.sqrt((xc * xc - D[:, 0, 0] / d22s).clamp_min(0))
    hy = torch.sqrt((yc * yc - D[:, 1, 1] / d22s).clamp_min(0))
    rl = torch.sqrt(rho_max / inv_sq)
    box = torch.stack(
        [
            torch.minimum(xc - hx, centre[:, 0] - rl),
            torch.maximum(xc + hx, centre[:, 0] + rl),
            torch.minimum(yc - hy, centre[:, 1] - rl),
            torch.maximum(yc + hy, centre[:, 1] + rl),
        ],
        dim=-1,
    )
    screen = box.new_tensor([0.0, float(camera.width), 0.0, float(camera.height)]).expand_as(box)
    return torch.where(bounded[:, None], box, screen)
