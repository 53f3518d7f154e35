"""Differentiable tile-based rasterizer of 3D Gaussians (3DGS) and 2D surfels (2DGS).

Pure torch; runs on CPU and CUDA (the device of the inputs). See ``design.md`` for the layers
and conventions.
"""

from __future__ import annotations

import importlib.util

from .backends import available_backends, mark_unavailable, register_backend
from .camera import Camera
from .config import RenderConfig
from .dense import render_dense
from .gaussians import Gaussians
from .output import RenderOutput
from .pipeline import render
from .sh import eval_sh, rgb_to_sh_dc
from .tiled import render_tiled
from .validation import (
    InputProblem,
    RenderInputError,
    validate_camera,
    validate_gaussians,
)

__all__ = [
    "Camera",
    "Gaussians",
    "RenderConfig",
    "RenderOutput",
    "render",
    "available_backends",
    "register_backend",
    "validate_gaussians",
    "validate_camera",
    "InputProblem",
    "RenderInputError",
    "eval_sh",
    "rgb_to_sh_dc",
]


def _register_builtins() -> None:
    register_backend("torch", render_tiled)
    register_backend("dense", lambda g, c, cfg: render_dense(g, c, cfg))
    _register_triton()
    if importlib.util.find_spec("numba") is None:
        mark_unavailable("numba", "needs the optional package numba (pip install numba)")
        return
    try:
        from .fused import render_fused
    except Exception as exc:  # numba present but broken (e.g. numpy too new for it)
        mark_unavailable("numba", f"numba failed to load: {exc}")
    else:
        register_backend("numba", render_fused)


def _register_triton() -> None:
    """The fused GPU backend: registered where Triton and a CUDA device are present."""
    if importlib.util.find_spec("triton") is None:
        mark_unavailable(
            "triton",
            "needs triton and a CUDA GPU (triton ships with the CUDA builds of torch; "
            "pip install triton)",
        )
        return
    try:
        from .triton_raster import render_triton, unavailable_reason
    except Exception as exc:  # triton present but broken (version clash with torch)
        mark_unavailable("triton", f"triton failed to load: {exc}")
        return
    reason = unavailable_reason()
    if reason is not None:
        mark_unavailable("triton", reason)
    else:
        register_backend("triton", render_triton)


_register_builtins()
