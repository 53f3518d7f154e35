"""Export a dataset as a Rerun recording (``.rrd``), via :mod:`robogs.format.qa.rerun_log`.

The recording holds the robot animated by its joint states, the scene objects, the splats,
the cameras with their frames, panoptic labels and 2D boxes, 3D boxes, end-effector frames,
joint and wrench plots and the validator findings, with a default blueprint (3D scene,
camera views, time series, findings log). With ``rerender=True`` it also holds, for every
``rerender_stride``-th labelled frame, the labels re-rendered from the bound splats next to the
recorded ones and their difference (:mod:`robogs.format.qa.rerun_rerender`; slow: seconds per
frame on a CPU). Open it with ``rerun FILE.rrd`` or
``robogs view DATASET --spawn``.
"""

from __future__ import annotations

from pathlib import Path

from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.qa.rerun_log import DEFAULT_LAYERS, write_rrd

from . import ExportReport, register_exporter

__all__ = ["export_rerun"]


def export_rerun(
    ds: Dataset,
    out: Path,
    *,
    episode: str | None = None,
    max_hz: float = 60.0,
    layers: list[str] | None = None,
    rerender: bool = False,
    rerender_stride: int = 10,
    rerender_scale: float = 1.0,
) -> ExportReport:
    """Write ``ds`` to a Rerun ``.rrd`` file.

    Args:
        ds: the dataset.
        out: output ``.rrd`` file.
        episode: episode id (default: the first).
        max_hz: downsampling rate of link/object transforms and images (``<= 0``: all).
        layers: layer names of :mod:`robogs.format.qa.rerun_log` (default all built-in).
        rerender: add the ``rerender`` layer (labels re-rendered from the splats).
        rerender_stride: re-render every k-th frame of each labelled camera.
        rerender_scale: render resolution as a fraction of the camera's.

    Returns:
        The report; ``notes`` lists what was skipped.
    """
    if out.suffix.lower() != ".rrd":
        raise InputError(f"Rerun output must end in .rrd, not {out.suffix!r}", path=out)
    if not (isinstance(rerender_stride, int) and rerender_stride >= 1):
        raise InputError(
            f"--rerender-stride must be an integer >= 1, got {rerender_stride!r}",
            where="--rerender-stride",
        )
    if not 0.0 < float(rerender_scale) <= 4.0:
        raise InputError(f"rerender scale must be in (0, 4], got {rerender_scale!r}")
    names = list(DEFAULT_LAYERS if layers is None else layers)
    if rerender and "rerender" not in names:
        names.append("rerender")
    notes = write_rrd(
        ds,
        out,
        episode=episode,
        max_hz=max_hz,
        layers=names,
        layer_options={"rerender": {"stride": rerender_stride, "scale": float(rerender_scale)}},
    )
    return ExportReport(out=out, files=[out.name], notes=notes)


register_exporter(
    "rerun",
    export_rerun,
    output="file",
    suffix=".rrd",
    help="Rerun recording: animated robot, cameras, labels, boxes, splats, plots, findings "
    "(+ labels re-rendered from the splats with --rerender)",
)
