"""Scene generators shared by the renderer tests (small, seeded, float64 by default)."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
import torch

from robogs.format.render import Camera, Gaussians


def random_gaussians(
    n: int,
    kind: str,
    *,
    seed: int = 0,
    sh_coeffs: int = 16,
    extra: int = 2,
    dtype: torch.dtype = torch.float64,
    device: str = "cpu",
    centre_z: float = 2.0,
    spread: float = 0.3,
    scale: tuple[float, float] = (0.01, 0.09),
    opacity_shift: float = 0.0,
) -> Gaussians:
    """N random Gaussians around (0, 0, centre_z) in front of an identity camera."""
    gen = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=gen, dtype=dtype) * spread
    means[:, 2] += centre_z
    ns = 3 if kind == "3dgs" else 2
    log_scales = torch.log(
        torch.rand(n, ns, generator=gen, dtype=dtype) * (scale[1] - scale[0]) + scale[0]
    )
    g = Gaussians(
        means=means,
        quats=torch.randn(n, 4, generator=gen, dtype=dtype),
        log_scales=log_scales,
        opacity_logits=torch.randn(n, generator=gen, dtype=dtype) * 1.5 + opacity_shift,
        sh=torch.randn(n, sh_coeffs, 3, generator=gen, dtype=dtype) * 0.4,
        extra=torch.rand(n, extra, generator=gen, dtype=dtype) if extra else None,
    )
    return Gaussians(**{k: (v.to(device) if v is not None else None) for k, v in vars(g).items()})


def small_camera(
    width: int = 37,
    height: int = 29,
    *,
    dtype: torch.dtype = torch.float64,
    device: str = "cpu",
    pose: bool = True,
) -> Camera:
    """A small camera; with ``pose`` it is displaced and rotated, still looking at (0, 0, 2)."""
    T = torch.eye(4, dtype=dtype)
    if pose:
        a = 0.2
        R = torch.tensor(
            [[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]], dtype=dtype
        )
        centre = torch.tensor([0.0, 0.0, 2.0], dtype=dtype)
        cam_pos = (
            centre
            - R @ torch.tensor([0.0, 0.0, 2.0], dtype=dtype)
            + torch.tensor([0.0, 0.05, 0.0], dtype=dtype)
        )
        T[:3, :3] = R
        T[:3, 3] = cam_pos
    return Camera(
        width=width, height=height, fx=40.0, fy=42.0, cx=18.3, cy=14.1, T_world_cam=T.to(device)
    )


@pytest.fixture
def make_gaussians() -> Callable[..., Gaussians]:
    return random_gaussians


@pytest.fixture
def make_camera() -> Callable[..., Camera]:
    return small_camera


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """Small renders are fastest on one thread, and two threads stall on a loaded 2-core host."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
