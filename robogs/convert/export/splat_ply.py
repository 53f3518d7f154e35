"""Export all splats of a dataset, posed at one time, as one PLY in the plain 3DGS layout.

The file is what the reference 3DGS code (graphdeco-inria/gaussian-splatting,
``GaussianModel.save_ply``) writes and what standard viewers read: binary little-endian,
one ``vertex`` element, float32 properties in the order

    x y z nx ny nz f_dc_0 f_dc_1 f_dc_2 f_rest_0 .. f_rest_{3(K-1)-1} opacity
    scale_0 scale_1 scale_2 rot_0 rot_1 rot_2 rot_3

(``f_rest`` channel-major, opacity a logit, log-scales, ``rot`` = (w, x, y, z); normals 0).

* The robot's and every asset's Gaussians are merged; SH of lower degree is zero-padded to
  the highest degree present.
* 2DGS surfels get a third log-scale of ``FLAT_LOG_SCALE`` = log(1e-7 m): a flat Gaussian
  whose thin axis is the surfel normal (the rotation's third column), as 3DGS viewers need.
* ``t_ns=None`` writes the stored rest state unchanged; a stamp poses every bound Gaussian
  with :class:`robogs.format.binding.Binding` (links by forward kinematics of the
  interpolated joint states, objects by their interpolated pose, SH rotated with them).
* ``sh_degree=D`` writes SH of degree ``D`` (``3 (D+1)^2 - 3`` ``f_rest`` properties), padding
  the higher bands with zeros. Loaders that size their SH from a fixed degree (the reference
  3DGS ``load_ply`` asserts ``len(f_rest) == 3 (max_sh_degree + 1)^2 - 3``, degree 3 by
  default) need the file written at their degree. Zero bands add no colour, so the rendered
  result is unchanged. A degree below the data's is refused (it would drop colour).
* ``with_binding=True`` appends ``bind_id bind_face bind_u bind_v bind_offset`` (int32,
  int32, float32 x3; names that cannot collide with the ``scale_``/``rot`` prefixes) and a
  header comment ``robogs_targets [...]`` (JSON list) giving the merged ``bind_id`` targets.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.splats import write_splat_arrays_ply

from . import ExportReport, register_exporter

__all__ = ["FLAT_LOG_SCALE", "export_ply", "ply_property_names"]

FLAT_LOG_SCALE = math.log(1e-7)


def ply_property_names(sh_coeffs: int, *, with_binding: bool = False) -> list[str]:
    """The property names, in file order, for ``sh_coeffs`` SH coefficients per channel."""
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * (sh_coeffs - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    if with_binding:
        names += ["bind_id", "bind_face", "bind_u", "bind_v", "bind_offset"]
    return names


def _sh_coeffs(k_data: int, sh_degree: int | None) -> int:
    """Coefficients per channel of the file: ``(sh_degree + 1)^2``, or ``k_data`` if None."""
    if sh_degree is None:
        return k_data
    data_degree = round(math.sqrt(k_data)) - 1
    if not isinstance(sh_degree, int) or not 0 <= sh_degree <= 4:
        raise InputError(
            f"sh_degree must be an integer in 0..4, not {sh_degree!r}", where="--sh-degree"
        )
    if sh_degree < data_degree:
        raise InputError(
            f"--sh-degree {sh_degree} is below the splats' SH degree {data_degree}",
            where="--sh-degree",
            hint=f"pass --sh-degree {data_degree} or more (higher bands are zero-padded)",
        )
    return (sh_degree + 1) ** 2


def _owners(ds: Dataset) -> list[str]:
    owners = ["robot"] if "splats" in (ds.manifest.get("robot") or {}) else []
    return owners + [name for name, entry in sorted(ds.assets.items()) if "splats" in entry]


def _posed(ds: Dataset, owner: str, t_ns: int | None, episode: str | None) -> dict[str, np.ndarray]:
    s = ds.splats(owner)
    part = {
        "means": s.means,
        "quats": s.quats,
        "log_scales": s.log_scales,
        "opacity": s.opacity_logits,
        "sh": s.sh,
    }
    if t_ns is not None:
        import torch

        from robogs.format.binding import Binding

        g = Binding(ds, episode, owners=[owner], dtype=torch.float64).pose(int(t_ns))
        part.update(means=g.means.numpy(), quats=g.quats.numpy(), sh=g.sh.numpy())
    return part


def export_ply(
    ds: Dataset,
    out: Path,
    *,
    t_ns: int | None = None,
    episode: str | None = None,
    with_binding: bool = False,
    sh_degree: int | None = None,
) -> ExportReport:
    """Write the merged splats of ``ds`` as one 3DGS PLY.

    Args:
        ds: the dataset (must hold splats).
        out: output ``.ply`` file.
        t_ns: dataset time to pose the Gaussians at; None = their stored rest state.
        episode: episode whose streams pose them (default: the only one).
        with_binding: append the binding columns.
        sh_degree: SH degree of the file (0..4), higher bands zero-padded; None = the highest
            degree in the data.

    Returns:
        The report; ``facts`` has ``gaussians``, ``sh_degree`` and per-owner counts.
    """
    owners = _owners(ds)
    if not owners:
        raise InputError(
            "dataset has no splats (no robot.splats or assets.*.splats in the manifest)",
            path=ds.manifest_path,
            hint="the ply export needs reconstructed splats",
        )
    parts, targets, counts = [], [], {}
    for owner in owners:
        entry = ds.splat_entry(owner)
        part = _posed(ds, owner, t_ns, episode)
        s = ds.splats(owner)
        part["bind_id"] = np.where(s.bind_id >= 0, s.bind_id + len(targets), -1).astype(np.int32)
        part.update(bind_face=s.bind_face, bind_uv=s.bind_uv, bind_offset=s.bind_offset)
        targets += list(entry.get("targets", []))
        counts[owner] = len(s)
        parts.append(part)
    k = max(p["sh"].shape[1] for p in parts)
    k = _sh_coeffs(k, sh_degree)
    n = sum(len(p["means"]) for p in parts)

    def cat(key: str) -> np.ndarray:
        return np.concatenate([p[key] for p in parts])

    sh = np.concatenate(
        [np.pad(p["sh"], ((0, 0), (0, k - p["sh"].shape[1]), (0, 0))) for p in parts]
    )
    scales = np.concatenate(
        [p["log_scales"] if p["log_scales"].shape[1] == 3
         else np.concatenate([p["log_scales"], np.full((len(p["log_scales"]), 1), FLAT_LOG_SCALE)], 1)
         for p in parts]
    )  # fmt: skip
    comments = [
        f"robogs export of {ds.name}; rot_* is (w,x,y,z); "
        + ("rest state" if t_ns is None else f"posed at t_ns {int(t_ns)}")
    ]
    if with_binding:
        comments.append("robogs_targets " + json.dumps(targets, ensure_ascii=True))
    write_splat_arrays_ply(
        out,
        means=cat("means"),
        quats=cat("quats"),
        log_scales=scales,
        opacity_logits=cat("opacity"),
        sh=sh,
        binding=(cat("bind_id"), cat("bind_face"), cat("bind_uv"), cat("bind_offset"))
        if with_binding
        else None,
        comments=comments,
    )
    return ExportReport(
        out=out,
        files=[out.name],
        facts={
            "gaussians": n,
            "sh_degree": int(round(math.sqrt(k))) - 1,
            "f_rest": 3 * (k - 1),
            "owners": counts,
        },
    )


register_exporter(
    "ply",
    export_ply,
    output="file",
    suffix=".ply",
    help="all splats posed at one time, merged into one standard 3DGS PLY",
)
