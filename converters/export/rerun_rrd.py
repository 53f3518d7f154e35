"""Export a dataset as a Rerun recording (``.rrd``), via :mod:`robogs_format.qa.rerun_log`.

The recording holds the robot animated by its joint states, the scene objects, the splats,
the cameras with their frames, panoptic labels and 2D boxes, 3D boxes, end-effector frames,
joint and wrench plots and the validator findings, with a default blueprint (3D scene,
camera views, time series, findings log). Open it with ``rerun FILE.rrd`` or
``robogs view DATASET --spawn``.
"""

from __future__ import annotations

from pathlib import Path

from robogs_format import Dataset
from robogs_format.errors import InputError
from robogs_format.qa.rerun_log import write_rrd

from . import ExportReport, register_exporter

__all__ = ["export_rerun"]


def export_rerun(
    ds: Dataset,
    out: Path,
    *,
    episode: str | None = None,
    max_hz: float = 60.0,
    layers: list[str] | None = None,
) -> ExportReport:
    """Write ``ds`` to a Rerun ``.rrd`` file.

    Args:
        ds: the dataset.
        out: output ``.rrd`` file.
        episode: episode id (default: the first).
        max_hz: downsampling rate of link/object transforms and images (``<= 0``: all).
        layers: layer names of :mod:`robogs_format.qa.rerun_log` (default all).

    Returns:
        The report; ``notes`` lists what was skipped.
    """
    if out.suffix.lower() != ".rrd":
        raise InputError(f"Rerun output must end in .rrd, not {out.suffix!r}", path=out)
    notes = write_rrd(ds, out, episode=episode, max_hz=max_hz, layers=layers)
    return ExportReport(out=out, files=[out.name], notes=notes)


register_exporter(
    "rerun",
    export_rerun,
    output="file",
    suffix=".rrd",
    help="Rerun recording: animated robot, cameras, labels, boxes, splats, plots, findings",
)
