"""Physical priors from semantics: density and friction per material, mass and inertia from volume.

A :class:`PriorProvider` turns a material name into a :class:`MaterialPrior` (nominal values and
bounds). :class:`MaterialTable` is the default provider, reading :data:`MATERIALS`; a provider
backed by a language model (or a lab's own measurements) implements the same protocol and is
passed to :func:`robogs.physics.init.init_physics` without any change to the callers.

Priors are **starting values and bounds** for the fit, never results: every value written from
here is labelled ``prior(<material>)`` in physics.json's ``sources``.

Sources of :data:`MATERIALS` (ranges collated from these published tables; the nominal value is
a typical mid-range value, the bounds span the tabulated range):

* densities: CRC Handbook of Chemistry and Physics (W. M. Haynes, ed., 97th ed., CRC Press
  2016), "Density of various solids"; The Engineering ToolBox, "Densities of Solids",
  https://www.engineeringtoolbox.com/density-solids-d_1265.html ;
* dry friction coefficients: Marks' Standard Handbook for Mechanical Engineers (11th ed.,
  McGraw-Hill 2007), section "Friction"; The Engineering ToolBox, "Friction and Friction
  Coefficients", https://www.engineeringtoolbox.com/friction-coefficients-d_778.html ;
  R. A. Serway & J. W. Jewett, Physics for Scientists and Engineers, table "Coefficients of
  friction". The coefficients are against a dry, hard tabletop (wood, laminate, steel); the
  pair actually in contact is unknown here, hence the wide bounds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from robogs.format.errors import InputError

__all__ = [
    "MaterialPrior",
    "PriorProvider",
    "MaterialTable",
    "MATERIALS",
    "DEFAULT_MATERIAL",
    "box_mass_properties",
    "mesh_mass_properties",
]


@dataclass(frozen=True)
class MaterialPrior:
    """Prior of one material (SI).

    Attributes:
        name: material name as the user writes it.
        density_kgm3: nominal density [kg/m^3] of the solid material.
        density_bounds: (low, high) [kg/m^3].
        friction_static: nominal static Coulomb coefficient against a dry tabletop [-].
        friction_dynamic: nominal dynamic (kinetic) coefficient [-] (<= static).
        friction_bounds: (low, high) for either coefficient [-].
        source: where the numbers come from (short citation).
    """

    name: str
    density_kgm3: float
    density_bounds: tuple[float, float]
    friction_static: float
    friction_dynamic: float
    friction_bounds: tuple[float, float]
    source: str


@runtime_checkable
class PriorProvider(Protocol):
    """Anything that maps a material name to a :class:`MaterialPrior`."""

    def material(self, name: str) -> MaterialPrior:
        """The prior of ``name``; raises :class:`InputError` listing the known names if unknown."""
        ...

    def known(self) -> list[str]:
        """Names this provider answers for (for error messages and ``--help``)."""
        ...


_HB = "CRC Handbook; Engineering ToolBox; Marks' Handbook (friction)"

#: The default table (see the module docstring for the sources). Densities are of the solid
#: material: a hollow object (an empty carton, a bottle) weighs far less than volume x density,
#: so give its mass with ``robogs physics set DATASET objects.<obj>.mass_kg=...``.
MATERIALS: dict[str, MaterialPrior] = {
    m.name: m
    for m in (
        # density: pine ~500, oak ~750, beech ~700; friction wood on wood 0.25-0.5 static, ~0.2 kinetic
        MaterialPrior("wood", 600.0, (350.0, 900.0), 0.40, 0.30, (0.2, 0.6), _HB),
        # density: PP ~900, ABS ~1050, PLA ~1250, PVC ~1400; hard plastics on wood/steel 0.2-0.5
        MaterialPrior("plastic", 1050.0, (900.0, 1400.0), 0.35, 0.30, (0.15, 0.6), _HB),
        # density 2640-2810 (alloys); aluminium on steel 0.61 static / 0.47 kinetic
        MaterialPrior("aluminium", 2700.0, (2640.0, 2810.0), 0.55, 0.45, (0.3, 1.1), _HB),
        # density 7750-8050 (carbon and stainless steels); steel on wood 0.2-0.6, steel on steel 0.74/0.57
        MaterialPrior("steel", 7850.0, (7750.0, 8050.0), 0.50, 0.40, (0.2, 0.8), _HB),
        # density 920 (natural) to 1500 (filled); rubber on dry hard surfaces 0.6-1.0 static
        MaterialPrior("rubber", 1150.0, (920.0, 1500.0), 0.80, 0.60, (0.5, 1.2), _HB),
        # soda-lime glass 2400-2800; glass on wood/glass 0.2-1.0 (dry glass on glass ~0.9 static)
        MaterialPrior("glass", 2500.0, (2400.0, 2800.0), 0.50, 0.40, (0.2, 1.0), _HB),
        # solid paperboard 500-900 (an empty corrugated carton is far lighter: set its mass)
        MaterialPrior("cardboard", 700.0, (500.0, 900.0), 0.40, 0.35, (0.2, 0.6), _HB),
        # expanded polystyrene 15-35, rigid polyurethane foam 30-100
        MaterialPrior("foam", 40.0, (15.0, 150.0), 0.60, 0.50, (0.3, 1.0), _HB),
    )
}

DEFAULT_MATERIAL = "plastic"
"""Material assumed when the user names none (reported as ``prior(plastic, default)``)."""


class MaterialTable:
    """The default :class:`PriorProvider`: a lookup in a table of :class:`MaterialPrior`."""

    def __init__(self, table: dict[str, MaterialPrior] | None = None) -> None:
        self._table = dict(MATERIALS if table is None else table)

    def known(self) -> list[str]:
        return sorted(self._table)

    def material(self, name: str) -> MaterialPrior:
        key = name.strip().lower().replace("aluminum", "aluminium")
        if key not in self._table:
            raise InputError(
                f"unknown material {name!r}",
                where="--object NAME=material:...",
                hint=f"known materials: {', '.join(self.known())}",
            )
        return self._table[key]


def box_mass_properties(
    size_m: tuple[float, float, float], density_kgm3: float
) -> tuple[float, np.ndarray]:
    """Mass [kg] and 3x3 inertia about the centre [kg m^2] of a solid box (edges along axes).

    ``I_xx = m (y^2 + z^2) / 12`` and permutations (any dynamics textbook, e.g. Meriam & Kraige).
    """
    sx, sy, sz = (float(s) for s in size_m)
    m = density_kgm3 * sx * sy * sz
    return m, np.diag([m * (sy**2 + sz**2), m * (sx**2 + sz**2), m * (sx**2 + sy**2)]) / 12.0


def mesh_mass_properties(mesh, density_kgm3: float) -> tuple[float, np.ndarray, np.ndarray, str]:
    """Mass [kg], centre of mass [3] m and inertia about it [3x3 kg m^2] of a solid mesh.

    Uses trimesh's exact polyhedral integrals (Mirtich 1996 style, via divergence theorem) for a
    watertight mesh; a mesh with holes is replaced by its convex hull, and the note says so.

    Returns:
        (mass, com in the mesh frame, inertia about the com in mesh axes, note).
    """
    note = ""
    m = mesh
    if not m.is_watertight:
        m = mesh.convex_hull
        note = "mesh not watertight: convex hull volume used"
    if m.volume <= 0:  # inverted winding
        m = m.copy()
        m.invert()
    mass = float(m.volume) * density_kgm3
    inertia = np.asarray(m.moment_inertia, dtype=float) * density_kgm3  # unit-density integrals
    return mass, np.asarray(m.center_mass, dtype=float), inertia, note
