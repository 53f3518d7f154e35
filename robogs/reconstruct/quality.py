"""Floors a trained reconstruction must clear before it is written into the dataset.

Checked after training and segmentation, before the commit:

* the cleaned mesh has faces;
* every link has at least ``max(min_gaussians, min_density * A / s²)`` Gaussians, A its URDF
  visual mesh area (m²) and s the seed spacing (m): ``A / s²`` is what the seeding puts on a
  fully visible link, and a quarter of it leaves gaps larger than the splats;
* the mean held-out PSNR (the trained model rendered into the views left out of training) is at
  least ``min_psnr_db``. 20 dB is an RMS error of 10 % of full scale; the benches reach 28-36 dB
  and the one-camera manipulation scene that motivated this check 12 dB.

A failure raises :class:`ReconstructionRejected` (the CLI exits 1 with the figures) and leaves
the dataset untouched; the training checkpoint is kept, so ``--force`` writes the result without
training again.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

from robogs.format.errors import RobogsError

__all__ = ["QualityFloors", "QualityReport", "ReconstructionRejected", "assess_quality"]


class ReconstructionRejected(RobogsError):
    """A trained reconstruction fell below a floor; ``figures`` holds the measurements."""

    def __init__(self, message: str, *, figures: dict[str, Any], **kw: Any) -> None:
        self.figures = figures
        super().__init__(message, **kw)


@dataclass(frozen=True)
class QualityFloors:
    """Floors of a reconstruction (see the module docstring).

    Attributes:
        min_psnr_db: mean held-out PSNR, dB.
        min_gaussians: Gaussians per link, absolute.
        min_density: fraction of ``area / spacing²`` Gaussians per link.
    """

    min_psnr_db: float = 20.0
    min_gaussians: int = 8
    min_density: float = 0.25


@dataclass
class QualityReport:
    """The measured figures and what fell short.

    Attributes:
        mesh_faces: faces of the cleaned mesh.
        heldout_psnr_db: mean held-out PSNR (nan without held-out views).
        gaussians: link -> (count, required).
        failures: one phrase per failure.
        floors: the floors applied.
    """

    mesh_faces: int
    heldout_psnr_db: float
    gaussians: dict[str, tuple[int, int]]
    failures: list[str] = field(default_factory=list)
    floors: QualityFloors = field(default_factory=QualityFloors)

    @property
    def passed(self) -> bool:
        return not self.failures

    def to_json(self) -> dict[str, Any]:
        return {
            "mesh_faces": self.mesh_faces,
            "heldout_psnr_db": _finite(self.heldout_psnr_db),
            "gaussians": {k: {"count": c, "required": r} for k, (c, r) in self.gaussians.items()},
            "failures": list(self.failures),
            "floors": asdict(self.floors),
        }

    def raise_if_failed(self) -> None:
        """Raise :class:`ReconstructionRejected` naming every failure, if any."""
        if self.failures:
            raise ReconstructionRejected(
                "the reconstruction is below its floors: "
                + "; ".join(self.failures)
                + f" (mesh {self.mesh_faces} faces, held-out PSNR {self.heldout_psnr_db:.1f} dB)",
                figures=self.to_json(),
                hint="capture more views around the scene, train longer (--iterations), or "
                "write it anyway with --force (the checkpoint is kept: no retraining)",
            )


def _finite(x: float) -> float | None:
    """``x``, or None for nan/inf (the manifest holds JSON, which has no nan)."""
    return float(x) if math.isfinite(x) else None


def assess_quality(
    *,
    mesh_faces: int,
    heldout_psnr_db: float,
    link_gaussians: dict[str, int],
    link_areas_m2: dict[str, float],
    spacing_m: float,
    floors: QualityFloors = QualityFloors(),
) -> QualityReport:
    """Compare a result's figures with ``floors``.

    Args:
        mesh_faces: faces of the cleaned scene mesh.
        heldout_psnr_db: mean held-out PSNR, dB (nan: no held-out views, not checked).
        link_gaussians: link -> Gaussians assigned to it (every link of the segments; 0 allowed).
        link_areas_m2: link -> area of its URDF visual mesh, m² (missing: absolute floor only).
        spacing_m: seed spacing, m.
        floors: the floors.
    """
    fails: list[str] = []
    if mesh_faces == 0:
        fails.append("the mesh is empty (0 faces)")
    if math.isfinite(heldout_psnr_db) and heldout_psnr_db < floors.min_psnr_db:
        fails.append(f"held-out PSNR {heldout_psnr_db:.1f} dB < {floors.min_psnr_db:g} dB")
    req: dict[str, tuple[int, int]] = {}
    for name, n in link_gaussians.items():
        area = link_areas_m2.get(name)
        need = floors.min_gaussians
        if area is not None and spacing_m > 0:
            need = max(need, int(math.ceil(floors.min_density * area / spacing_m**2)))
        req[name] = (int(n), int(need))
    short = sorted((n - r, k) for k, (n, r) in req.items() if n < r)
    for _, k in short:
        n, r = req[k]
        fails.append(f"link {k} has {n} Gaussians < {r}")
    return QualityReport(mesh_faces, heldout_psnr_db, req, fails, floors)
