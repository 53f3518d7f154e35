"""``render``: validate, pick the backend, handle lens distortion."""

from __future__ import annotations

from dataclasses import replace

import torch

from .backends import get_backend
from .camera import Camera
from .config import RenderConfig
from .distortion import pinhole_render_camera, remap
from .gaussians import Gaussians
from .output import RenderOutput
from .validation import InputProblem, raise_on_problems, validate_camera, validate_gaussians

__all__ = ["render"]


#: the default options (frozen, so sharing one instance is safe)
_DEFAULT_CONFIG = RenderConfig()


def render(
    gaussians: Gaussians,
    camera: Camera,
    *,
    config: RenderConfig = _DEFAULT_CONFIG,
    backend: str = "torch",
) -> RenderOutput:
    """Render Gaussians into a camera: colour, alpha, depths, normals and extra channels.

    Outputs live on the device and dtype of ``gaussians.means``. Distorted cameras are rendered
    on a pinhole grid and warped (see ``distortion.py``).

    Args:
        gaussians: N Gaussians (3DGS or 2DGS), world frame.
        camera: OpenCV camera with ``T_world_cam``.
        config: render options.
        backend: a name from :func:`available_backends` ("torch" or "dense" built in).

    Returns:
        The render, see :class:`RenderOutput`.

    Raises:
        RenderInputError: degenerate Gaussians or camera (NaN, bad shapes, fx <= 0, ...).
        RobogsError: unknown or unavailable backend.

    Example:
        >>> import torch
        >>> from robogs.format.render import Camera, Gaussians, render
        >>> g = Gaussians(means=torch.tensor([[0.0, 0.0, 2.0]]), quats=torch.tensor([[1.0, 0, 0, 0]]),
        ...               log_scales=torch.full((1, 3), -3.0), opacity_logits=torch.tensor([5.0]),
        ...               sh=torch.zeros(1, 1, 3))
        >>> cam = Camera(width=32, height=24, fx=30.0, fy=30.0, cx=16.5, cy=12.5, T_world_cam=torch.eye(4))
        >>> out = render(g, cam)
        >>> round(float(out.alpha[12, 16]), 2), round(float(out.depth_median[12, 16]), 3)
        (0.99, 2.0)
    """
    if config.validate:
        problems: list[InputProblem] = validate_camera(camera) + validate_gaussians(
            gaussians, config.kind
        )
        problems += _config_problems(config)
        raise_on_problems(problems)
    fn = get_backend(backend)
    if not camera.is_distorted:
        return fn(gaussians, camera, config)
    pin_cam, grid, ok = pinhole_render_camera(camera, config.undistort_scale)
    out = fn(
        gaussians,
        pin_cam,
        replace(config, lowpass_scale=config.lowpass_scale * config.undistort_scale),
    )
    return _warp(out, grid.to(out.alpha.device), ok.to(out.alpha.device), config)


def _config_problems(config: RenderConfig) -> list[InputProblem]:
    problems = []
    if config.kind not in ("3dgs", "2dgs"):
        problems.append(InputProblem("config.kind", f"is {config.kind!r}", 'use "3dgs" or "2dgs"'))
    if config.tile_size is not None and (
        not isinstance(config.tile_size, int) or config.tile_size <= 0
    ):
        problems.append(
            InputProblem(
                "config.tile_size",
                f"is {config.tile_size!r}",
                "use None or a positive int (8 or 16)",
            )
        )
    if config.tile_batch is not None and (
        not isinstance(config.tile_batch, int) or config.tile_batch <= 0
    ):
        problems.append(
            InputProblem(
                "config.tile_batch", f"is {config.tile_batch!r}", "use None or a positive int"
            )
        )
    if not isinstance(config.chunk, int) or config.chunk <= 0:
        problems.append(
            InputProblem("config.chunk", f"is {config.chunk!r}", "use a positive int (16 or 32)")
        )
    if len(config.background) != 3:
        problems.append(
            InputProblem("config.background", f"is {config.background!r}", "give 3 floats")
        )
    if not config.undistort_scale > 0:
        problems.append(
            InputProblem(
                "config.undistort_scale", f"is {config.undistort_scale!r}", "use a value > 0"
            )
        )
    return problems


def _warp(
    out: RenderOutput, grid: torch.Tensor, ok: torch.Tensor, config: RenderConfig
) -> RenderOutput:
    """Resample a pinhole render at the undistorted positions of the output pixels."""
    a = out.alpha
    bg = torch.tensor(config.background, dtype=a.dtype, device=a.device)
    premult = torch.cat(
        [
            out.rgb - (1.0 - a)[..., None] * bg,
            a[..., None],
            (out.depth_expected * a)[..., None],
            out.normals * a[..., None],
            out.extra,
        ],
        dim=-1,
    )
    s = remap(premult, grid) * ok[..., None].to(a.dtype)
    alpha = s[..., 3]
    has = alpha > 0
    inv = 1.0 / torch.where(has, alpha, torch.ones_like(alpha))
    median = remap(out.depth_median[..., None], grid, mode="nearest")[..., 0] * ok.to(a.dtype)
    return RenderOutput(
        rgb=s[..., 0:3] + (1.0 - alpha)[..., None] * bg,
        alpha=alpha,
        depth_expected=torch.where(has, s[..., 4] * inv, 0.0),
        depth_median=median,
        normals=torch.where(has[..., None], s[..., 5:8] * inv[..., None], 0.0),
        extra=s[..., 8:],
        means2d=out.means2d,
        radii=out.radii,
    )
