"""Input checks of the renderer: they return problems; ``render`` raises on them.

The dataset validator turns the same problems into findings, so each problem names the
field, the first offending row and how to fix it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from ..errors import InputError
from .camera import DISTORTION_MODELS, Camera
from .gaussians import Gaussians

__all__ = [
    "RenderInputError",
    "InputProblem",
    "validate_gaussians",
    "validate_camera",
    "raise_on_problems",
]

_SH_SIZES = (1, 4, 9, 16)


class RenderInputError(InputError):
    """Gaussians or a camera given to the renderer are unusable."""


@dataclass(frozen=True)
class InputProblem:
    """One reason why an input cannot be rendered.

    Attributes:
        where: the field and first bad row, e.g. ``"gaussians.means[12]"``.
        message: what is wrong, with the value.
        hint: how to fix it.
    """

    where: str
    message: str
    hint: str

    def __str__(self) -> str:
        return f"{self.where}: {self.message} (hint: {self.hint})"


def _first_bad_row(bad: torch.Tensor) -> tuple[int, int]:
    rows = bad.reshape(bad.shape[0], -1).any(dim=1) if bad.dim() > 1 else bad
    idx = torch.nonzero(rows).flatten()
    return int(idx.numel()), int(idx[0]) if idx.numel() else -1


def _check_values(
    problems: list[InputProblem],
    name: str,
    x: torch.Tensor,
    *,
    allow_neg_inf: bool = False,
    allow_inf: bool = False,
    hint: str,
) -> None:
    if allow_inf:
        bad = torch.isnan(x)
        what = "NaN"
    elif allow_neg_inf:
        bad = torch.isnan(x) | (x == math.inf)
        what = "NaN or +inf"
    else:
        bad = ~torch.isfinite(x)
        what = "NaN or inf"
    if x.numel() and bool(bad.any()):
        count, row = _first_bad_row(bad)
        problems.append(
            InputProblem(f"gaussians.{name}[{row}]", f"{count} row(s) hold {what}", hint)
        )


def validate_gaussians(gaussians: Gaussians, kind: str | None = None) -> list[InputProblem]:
    """Check shapes, dtypes, devices and values of ``gaussians``.

    Args:
        gaussians: the set to check.
        kind: "3dgs" or "2dgs" when the render kind is known (checks the number of scales).

    Returns:
        The problems found; empty when the set can be rendered.
    """
    g = gaussians
    problems: list[InputProblem] = []
    fields = {
        "means": g.means,
        "quats": g.quats,
        "log_scales": g.log_scales,
        "opacity_logits": g.opacity_logits,
        "sh": g.sh,
    }
    if g.extra is not None:
        fields["extra"] = g.extra
    for name, x in fields.items():
        if not isinstance(x, torch.Tensor):
            problems.append(
                InputProblem(
                    f"gaussians.{name}",
                    f"is a {type(x).__name__}, not a torch.Tensor",
                    "convert with torch.as_tensor",
                )
            )
    if problems:
        return problems
    for name, x in fields.items():
        if not x.is_floating_point():
            problems.append(
                InputProblem(
                    f"gaussians.{name}",
                    f"has dtype {x.dtype}, not a floating type",
                    "use float32 or float64",
                )
            )
    if g.means.dim() != 2 or g.means.shape[1] != 3:
        problems.append(
            InputProblem(
                "gaussians.means",
                f"has shape {tuple(g.means.shape)}, not [N, 3]",
                "pass one xyz row per Gaussian",
            )
        )
        return problems
    n = g.means.shape[0]
    expected: dict[str, tuple[Sequence[int | None], str]] = {
        "quats": ((n, 4), "[N, 4] (w, x, y, z)"),
        "log_scales": ((n, None), "[N, 3] (3DGS) or [N, 2] (2DGS)"),
        "opacity_logits": ((n,), "[N]"),
        "sh": ((n, None, 3), "[N, K, 3] with K in {1, 4, 9, 16}"),
    }
    if g.extra is not None:
        expected["extra"] = ((n, None), "[N, C]")
    for name, (shape, text) in expected.items():
        x = fields[name]
        ok = x.dim() == len(shape) and all(
            s is None or x.shape[i] == s for i, s in enumerate(shape)
        )
        if not ok:
            problems.append(
                InputProblem(
                    f"gaussians.{name}",
                    f"has shape {tuple(x.shape)}, expected {text} with N = {n}",
                    "give every field one row per Gaussian",
                )
            )
    if problems:
        return problems
    if g.log_scales.shape[1] not in (2, 3):
        problems.append(
            InputProblem(
                "gaussians.log_scales",
                f"has {g.log_scales.shape[1]} columns",
                "use 3 log-scales (3DGS) or 2 (2DGS)",
            )
        )
    elif kind is not None and g.kind != kind:
        problems.append(
            InputProblem(
                "gaussians.log_scales",
                f"has {g.log_scales.shape[1]} columns but the render kind is {kind!r}",
                "set RenderConfig(kind=...) to match: 3 scales for 3dgs, 2 for 2dgs",
            )
        )
    if g.sh.shape[1] not in _SH_SIZES:
        problems.append(
            InputProblem(
                "gaussians.sh",
                f"has K = {g.sh.shape[1]} coefficients",
                "K must be 1, 4, 9 or 16 (SH degree 0..3)",
            )
        )
    devices = {str(x.device) for x in fields.values()}
    dtypes = {x.dtype for x in fields.values()}
    if len(devices) > 1:
        problems.append(
            InputProblem(
                "gaussians",
                f"fields live on several devices {sorted(devices)}",
                "move all fields to one device",
            )
        )
    if len(dtypes) > 1:
        problems.append(
            InputProblem(
                "gaussians",
                f"fields mix dtypes {sorted(map(str, dtypes))}",
                "cast all fields to one dtype",
            )
        )
    if problems:
        return problems
    _check_values(
        problems, "means", g.means, hint="drop or fix the Gaussians with non-finite positions"
    )
    _check_values(problems, "quats", g.quats, hint="rotations must be finite (w, x, y, z)")
    _check_values(
        problems,
        "log_scales",
        g.log_scales,
        allow_neg_inf=True,
        hint="log-scales must be finite (or -inf for a zero scale)",
    )
    _check_values(
        problems,
        "opacity_logits",
        g.opacity_logits,
        allow_inf=True,
        hint="opacity logits must not be NaN",
    )
    _check_values(problems, "sh", g.sh, hint="SH coefficients must be finite")
    if g.extra is not None:
        _check_values(problems, "extra", g.extra, hint="extra channels must be finite")
    if n and torch.isfinite(g.quats).all():
        zero = g.quats.norm(dim=1) < 1e-12
        if bool(zero.any()):
            count, row = _first_bad_row(zero)
            problems.append(
                InputProblem(
                    f"gaussians.quats[{row}]",
                    f"{count} quaternion(s) have zero norm",
                    "use (1, 0, 0, 0) for no rotation",
                )
            )
    return problems


def _finite(v: object) -> bool:
    try:
        return math.isfinite(float(v))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return False


def validate_camera(camera: Camera) -> list[InputProblem]:
    """Check intrinsics, extrinsics, clipping planes and distortion of ``camera``.

    Returns:
        The problems found; empty when the camera can be rendered from.
    """
    c = camera
    problems: list[InputProblem] = []
    for name in ("width", "height"):
        v = getattr(c, name)
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            problems.append(
                InputProblem(f"camera.{name}", f"is {v!r}", "image size must be a positive int, px")
            )
    for name in ("fx", "fy"):
        v = getattr(c, name)
        if not _finite(v) or float(v) <= 0:
            problems.append(
                InputProblem(
                    f"camera.{name}", f"is {v!r}", "focal lengths must be finite and > 0, px"
                )
            )
    for name in ("cx", "cy"):
        v = getattr(c, name)
        if not _finite(v):
            problems.append(
                InputProblem(
                    f"camera.{name}", f"is {v!r}", "the principal point must be finite, px"
                )
            )
    if not _finite(c.near) or float(c.near) <= 0:
        problems.append(
            InputProblem("camera.near", f"is {c.near!r}", "the near plane must be > 0, m")
        )
    if not _finite(c.far) or (_finite(c.near) and float(c.far) <= float(c.near)):
        problems.append(
            InputProblem(
                "camera.far",
                f"is {c.far!r} (near {c.near!r})",
                "the far plane must be finite and beyond near, m",
            )
        )
    if c.distortion_model not in DISTORTION_MODELS:
        problems.append(
            InputProblem(
                "camera.distortion_model",
                f"is {c.distortion_model!r}",
                f"use one of {sorted(DISTORTION_MODELS)}",
            )
        )
    else:
        want = DISTORTION_MODELS[c.distortion_model]
        if len(c.distortion) != want:
            problems.append(
                InputProblem(
                    "camera.distortion",
                    f"has {len(c.distortion)} coefficients, {c.distortion_model!r} takes {want}",
                    "plumb_bob: k1, k2, p1, p2, k3; equidistant: k1..k4; none: ()",
                )
            )
        elif not all(_finite(v) for v in c.distortion):
            problems.append(
                InputProblem(
                    "camera.distortion",
                    f"holds non-finite values {c.distortion!r}",
                    "use finite coefficients",
                )
            )
    T = c.T_world_cam
    if not isinstance(T, torch.Tensor) or tuple(T.shape) != (4, 4):
        shape = tuple(T.shape) if isinstance(T, torch.Tensor) else type(T).__name__
        problems.append(
            InputProblem(
                "camera.T_world_cam", f"is {shape}, not a [4, 4] tensor", "pass a 4x4 torch.Tensor"
            )
        )
        return problems
    Td = T.detach().to(device="cpu", dtype=torch.float64)
    if not bool(torch.isfinite(Td).all()):
        problems.append(
            InputProblem("camera.T_world_cam", "holds NaN or inf", "use a finite rigid transform")
        )
        return problems
    R = Td[:3, :3]
    ortho = float((R.T @ R - torch.eye(3, dtype=torch.float64)).abs().max())
    det = float(torch.linalg.det(R))
    bottom = float((Td[3] - torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64)).abs().max())
    if ortho > 1e-4 or det <= 0:
        problems.append(
            InputProblem(
                "camera.T_world_cam",
                f"rotation is not proper orthonormal (|R^T R - I| = {ortho:.2e}, det = {det:.4f})",
                "orthonormalise the rotation; T_world_cam must be rigid",
            )
        )
    if bottom > 1e-9:
        problems.append(
            InputProblem(
                "camera.T_world_cam",
                f"last row is {Td[3].tolist()}",
                "the last row must be (0, 0, 0, 1)",
            )
        )
    return problems


def raise_on_problems(problems: list[InputProblem]) -> None:
    """Raise a :class:`RenderInputError` naming the first problem (and how many there are)."""
    if not problems:
        return
    first = problems[0]
    more = f" ({len(problems) - 1} more problem(s))" if len(problems) > 1 else ""
    raise RenderInputError(first.message + more, where=first.where, hint=first.hint)
