"""Default budgets (tolerances) of the validator, each with its reason.

Budgets are in mm, ms, px, dB or plain ratios. A dataset may override any of them
in ``manifest.json`` under ``budgets``; users may override them again on the
command line. Names are stable and listed in ``spec/FORMAT.md``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .errors import FormatError

__all__ = ["Budget", "DEFAULT_BUDGETS", "resolve_budgets"]


@dataclass(frozen=True)
class Budget:
    """One named tolerance: its value, its unit and why it is what it is."""

    name: str
    value: float
    unit: str
    reason: str


DEFAULT_BUDGETS: dict[str, Budget] = {
    b.name: b
    for b in [
        Budget(
            "time.gap_factor",
            2.5,
            "periods",
            "a gap longer than 2.5 nominal periods means at least one lost sample",
        ),
        Budget(
            "time.jitter_p99_ms",
            5.0,
            "ms",
            "p99 stamp error against the stream's fitted clock; consumer cameras and ROS stamping "
            "stay below it",
        ),
        Budget(
            "time.jitter_max_ms",
            20.0,
            "ms",
            "a single late sample beyond this breaks ms-level alignment",
        ),
        Budget(
            "time.rate_tolerance",
            0.05,
            "ratio",
            "measured rate within 5 % of the declared nominal rate",
        ),
        Budget(
            "time.coverage_ms",
            100.0,
            "ms",
            "every stream starts and ends within this of the episode bounds",
        ),
        Budget(
            "time.sync_ms",
            5.0,
            "ms",
            "declared offsets between streams must be known to this precision",
        ),
        Budget(
            "time.offset_ms", 1.0, "ms", "re-render time offset against the declared one (binding)"
        ),
        Budget(
            "time.lag_ms",
            2.0,
            "ms",
            "lag between two streams of the same motion (T013); at 0.5 m/s, a brisk tool speed, "
            "2 ms moves a pose by 1 mm, half of geometry.fk_ee_mm",
        ),
        Budget(
            "time.held_share",
            0.01,
            "ratio",
            "share of samples that repeat a held value while the signal moves (T014); a healthy "
            "driver publishes fresh values, so more than 1 % means a resampled or stalling source",
        ),
        Budget(
            "geometry.fk_ee_mm",
            2.0,
            "mm",
            "recorded end-effector vs forward kinematics; encoder and calibration error of industrial arms",
        ),
        Budget(
            "geometry.joint_limit_rad", 1e-3, "rad", "encoder noise may read slightly past a limit"
        ),
        Budget("geometry.box2d_px", 2.0, "px", "2D box edges vs the labelled pixels"),
        Budget(
            "geometry.box3d_mm", 2.0, "mm", "object mesh may stick out of its 3D box by this much"
        ),
        Budget(
            "geometry.penetration_mm",
            2.0,
            "mm",
            "object below the table top by more than this is a pose or mesh error",
        ),
        Budget(
            "geometry.com_outside_mm",
            5.0,
            "mm",
            "link CoM outside the convex hull of its collision/visual mesh",
        ),
        Budget(
            "geometry.inertia_rel",
            1e-6,
            "ratio",
            "relative slack on positive-definiteness and the triangle inequality",
        ),
        Budget(
            "binding.face_distance_mm",
            1.0,
            "mm",
            "bound Gaussian centre to its face plus declared offset",
        ),
        Budget("binding.iou_min", 0.9, "ratio", "per link/object label IoU of the re-render"),
        Budget("binding.boundary_px", 1.5, "px", "mean label boundary distance of the re-render"),
        Budget(
            "binding.boundary_mm",
            2.0,
            "mm",
            "boundary distance converted to metric at the object depth",
        ),
        Budget(
            "binding.extrinsic_mm",
            2.0,
            "mm",
            "systematic boundary shift expressed as camera pose error",
        ),
        Budget(
            "binding.psnr_min_db",
            20.0,
            "dB",
            "floor on the mean foreground PSNR of the re-rendered colour; the clean synthetic scenes give 26-28 dB (21.5 dB at --scale 0.25), splats in linear instead of image (sRGB) colour 12-14 dB",
        ),
    ]
}


def resolve_budgets(
    overrides: dict[str, Any] | None = None, *, source: str | None = None
) -> dict[str, float]:
    """Merge dataset or CLI overrides into the defaults; unknown names are an error."""
    values = {name: b.value for name, b in DEFAULT_BUDGETS.items()}
    for name, value in (overrides or {}).items():
        if name not in values:
            raise FormatError(
                f"unknown budget {name!r}",
                path=source,
                where="budgets",
                hint=f"known budgets: {', '.join(sorted(values))}",
            )
        if (
            not isinstance(value, int | float)
            or isinstance(value, bool)
            or value != value
            or value < 0
        ):
            raise FormatError(
                f"budget {name!r} must be a non-negative number, got {value!r}",
                path=source,
                where=f"budgets/{name}",
            )
        values[name] = float(value)
    return values
