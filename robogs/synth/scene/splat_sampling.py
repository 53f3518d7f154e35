"""Gaussians sampled on mesh surfaces, bound to their faces (2DGS-like surfels).

Faces are drawn with probability proportional to their area and points
uniformly inside them with the square-root barycentric map (Osada et al. 2002,
"Shape distributions"). Each Gaussian lies in the plane of its face (local x
along the first edge, z along the face normal), like the surfels of 2DGS
(Huang et al. 2024), with DC-only SH colour (Kerbl et al. 2023: colour = 0.5 +
C0 * f_dc).

Colour space: as in 3DGS, the SH colour is the image colour itself (the
renderer applies no linear/sRGB conversion). Each Gaussian therefore carries the
colour its face shows in the frames: the sRGB-encoded, Lambert-shaded uint8
colour of :meth:`~robogs.synth.scene.render_scene.MeshPart.face_colors` divided by
255, not the linear base colour. The shading is evaluated at the rest pose (the
episode start). The light is fixed in the world, so this is exact for the table.
For the moving links and the box it is only approximate: a face's shade in the
frames drifts as the part rotates away from its rest pose, and DC-only splats
cannot follow that drift.

Density: one Gaussian per ``spacing**2`` of surface (:func:`splat_count`). The spacing sets how
finely a silhouette is resolved: a surfel cloud's edge wanders by about one spacing, so the
spacing projected at the camera (``spacing * f / depth``, px) should not exceed about a pixel
where boundaries are measured at the pixel level (``robogs synth --splat-spacing``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robogs.format.errors import InputError

from .rigid import matrix_to_quat

__all__ = [
    "SH_C0",
    "SPACING_RANGE_M",
    "COUNT_RANGE",
    "SurfaceSamples",
    "check_spacing",
    "splat_count",
    "sample_surface",
    "concat_samples",
]

SH_C0 = 0.28209479177387814
#: Gaussian standard deviation as a fraction of the mean sample spacing
SIGMA_FACTOR = 0.55
#: accepted surfel spacings, m (at 1 mm the generated arm alone has ~670k surfels)
SPACING_RANGE_M = (0.001, 0.1)
#: Gaussians per target (link or object), clipped to this range: a floor for tiny parts, a
#: memory cap for large ones (the 2.5 m^2 table reaches it below ~6.4 mm spacing)
COUNT_RANGE = (200, 60_000)


def check_spacing(spacing_m: float) -> float:
    """``spacing_m`` (m) as a float; :class:`InputError` unless finite and in :data:`SPACING_RANGE_M`."""
    lo, hi = SPACING_RANGE_M
    try:
        s = float(spacing_m)
    except (TypeError, ValueError):
        s = math.nan
    if not (math.isfinite(s) and lo <= s <= hi):
        raise InputError(
            f"splat spacing {spacing_m!r} m is out of range",
            hint=f"give a spacing in metres between {lo:g} and {hi:g} (e.g. 0.005 for 5 mm)",
        )
    return s


def splat_count(area_m2: float, spacing_m: float) -> int:
    """Gaussians for a surface of ``area_m2`` (m^2) at mean spacing ``spacing_m`` (m): one per
    ``spacing_m**2``, clipped to :data:`COUNT_RANGE`."""
    lo, hi = COUNT_RANGE
    return int(np.clip(area_m2 / check_spacing(spacing_m) ** 2, lo, hi))


@dataclass
class SurfaceSamples:
    """Gaussians of one or more targets (arrays aligned on the first axis).

    Attributes:
        means: [N, 3] world frame at the rest state, m (float64 before writing).
        quats: [N, 4] (w, x, y, z), world frame at rest.
        log_scales: [N, 2] log m.
        sh_dc: [N, 3] SH degree-0 coefficients (colour = 0.5 + SH_C0 * sh_dc, image space).
        bind_id: [N] int32; bind_face: [N] int32; bind_uv: [N, 2] weights of face vertices 1 and 2.
    """

    means: np.ndarray
    quats: np.ndarray
    log_scales: np.ndarray
    sh_dc: np.ndarray
    bind_id: np.ndarray
    bind_face: np.ndarray
    bind_uv: np.ndarray


def sample_surface(
    vertices: np.ndarray,
    faces: np.ndarray,
    T_world_owner: np.ndarray,
    n: int,
    face_rgb: np.ndarray,
    bind_id: int,
    rng: np.random.Generator,
) -> SurfaceSamples:
    """Sample ``n`` Gaussians on a mesh given in its owner frame and place them in the world.

    Args:
        vertices: [V, 3] m, owner (link or object) frame.
        faces: [F, 3] vertex indices.
        T_world_owner: [4, 4] owner pose at the rest state.
        n: number of Gaussians.
        face_rgb: [F, 3] colour of each face as the images show it (sRGB-encoded, shaded), in
            [0, 1]; stored as the SH DC term of the Gaussians on that face.
        bind_id: index of the owner in the manifest ``targets`` list.
        rng: random generator (deterministic for a seed).
    """
    tri = vertices[faces]  # [F, 3, 3]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    cr = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(cr, axis=1)
    area = np.where(area > 1e-14, area, 0.0)
    face = rng.choice(faces.shape[0], size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    u, v = s * (1.0 - r2), s * r2
    w0 = 1.0 - u - v
    t = tri[face]
    local = w0[:, None] * t[:, 0] + u[:, None] * t[:, 1] + v[:, None] * t[:, 2]
    R, p = T_world_owner[:3, :3], T_world_owner[:3, 3]
    means = local @ R.T + p
    x_axis = e1[face] / np.linalg.norm(e1[face], axis=1, keepdims=True)
    z_axis = cr[face] / np.linalg.norm(cr[face], axis=1, keepdims=True)
    y_axis = np.cross(z_axis, x_axis)
    frame = np.stack([x_axis, y_axis, z_axis], axis=-1)  # columns
    quats = matrix_to_quat(R @ frame)
    sigma = SIGMA_FACTOR * np.sqrt(area.sum() / n)
    log_scales = np.full((n, 2), np.log(sigma))
    dc = (np.asarray(face_rgb, dtype=np.float64)[face] - 0.5) / SH_C0
    return SurfaceSamples(
        means=means,
        quats=quats,
        log_scales=log_scales,
        sh_dc=dc,
        bind_id=np.full(n, bind_id, np.int32),
        bind_face=face.astype(np.int32),
        bind_uv=np.stack([u, v], axis=1),
    )


def concat_samples(parts: list[SurfaceSamples]) -> SurfaceSamples:
    """Concatenate samples of several targets (in ``targets`` order)."""
    return SurfaceSamples(
        *(
            np.concatenate([getattr(p, f) for p in parts])
            for f in SurfaceSamples.__dataclass_fields__
        )
    )
