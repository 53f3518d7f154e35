"""HTML overview of a dataset and its validation findings, with plots.

Plots: joint positions over time, sample intervals per stream (jitter and
gaps at a glance), object paths on the table seen from above, and camera
frames with their panoptic labels overlaid.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..dataset import Dataset
from ..errors import RobogsError
from .html import HtmlReport, new_figure

__all__ = ["write_dataset_report"]

_SEV_ORDER = {"error": 0, "warning": 1, "info": 2}


def _findings_section(rep: HtmlReport, findings: Sequence[dict[str, Any]]) -> None:
    rep.heading("Validation findings")
    counts = {s: sum(f["severity"] == s for f in findings) for s in ("error", "warning", "info")}
    css = "error" if counts["error"] else "ok"
    rep.paragraph(
        f"{counts['error']} errors, {counts['warning']} warnings, {counts['info']} notes", css=css
    )
    if not findings:
        return
    rows, styles = [], []
    for f in sorted(findings, key=lambda f: (_SEV_ORDER.get(f["severity"], 3), f["code"])):
        loc = ", ".join(f"{k}={v}" for k, v in (f.get("location") or {}).items() if v is not None)
        val = "" if f.get("value") is None else f"{f['value']:.4g} {f.get('unit') or ''}".strip()
        bud = "" if f.get("budget") is None else f"{f['budget']:.4g} {f.get('unit') or ''}".strip()
        rows.append(
            [f["code"], f["severity"], loc, val, bud, f.get("message", ""), f.get("hint", "")]
        )
        styles.append(f["severity"])
    rep.table(
        ["code", "severity", "location", "measured", "budget", "message", "hint"],
        rows,
        row_css=styles,
    )


def _stream_rows(ds: Dataset) -> list[list[Any]]:
    rows = []
    for ep in ds.episodes:
        for name, st in sorted(ep.streams.items()):
            rel = st.get("path") or st.get("frames")
            n = ds.files.get(rel, {}).get("rows") if rel else None
            rows.append(
                [
                    ep.id,
                    name,
                    st.get("kind"),
                    n,
                    st.get("nominal_rate_hz"),
                    st.get("stamp_source"),
                    st.get("offset_ns"),
                ]
            )
    return rows


def _plot_joints(rep: HtmlReport, ds: Dataset) -> None:
    ep = ds.episodes[0]
    if not ep.has("joint_states"):
        return
    tab = ep.table("joint_states")
    t = (tab.column("t_ns").to_numpy() - ep.start_ns) * 1e-9
    fig, ax = new_figure(figsize=(9, 3.2))
    for name in tab.column_names:
        if name.startswith("position."):
            ax.plot(t, tab.column(name).to_numpy(), lw=1, label=name[len("position.") :])
    ax.set_xlabel("time since episode start [s]")
    ax.set_ylabel("joint position [rad]")
    ax.legend(fontsize=7, ncol=3)
    rep.figure(fig, f"Joint positions, episode {ep.id}")


def _plot_intervals(rep: HtmlReport, ds: Dataset) -> None:
    ep = ds.episodes[0]
    fig, ax = new_figure(figsize=(9, 3.2))
    plotted = False
    for name, st in sorted(ep.streams.items()):
        try:
            if st.get("kind") == "camera" and "frames" in st:
                t = ep.frames(st["camera"]).column("t_ns").to_numpy()
            elif st.get("kind") in ("joint_states", "actions"):
                t = ep.table(name, columns=["t_ns"]).column("t_ns").to_numpy()
            else:
                continue
        except RobogsError:
            continue
        if len(t) < 3:
            continue
        dt_ms = np.diff(t) * 1e-6
        ax.plot((t[1:] - ep.start_ns) * 1e-9, dt_ms, ".", ms=2, label=name)
        plotted = True
    if plotted:
        ax.set_yscale("log")
        ax.set_xlabel("time since episode start [s]")
        ax.set_ylabel("interval to previous sample [ms]")
        ax.legend(fontsize=7)
        rep.figure(
            fig, "Sample intervals per stream: flat bands are healthy, spikes are gaps or jitter"
        )


def _plot_objects(rep: HtmlReport, ds: Dataset) -> None:
    ep = ds.episodes[0]
    if not ep.has("object_poses"):
        return
    tab = ep.table("object_poses")
    objs = np.asarray(tab.column("object").to_pylist())
    x, y = tab.column("x").to_numpy(), tab.column("y").to_numpy()
    fig, ax = new_figure(figsize=(4.5, 4.5))
    for o in np.unique(objs):
        m = objs == o
        ax.plot(x[m] * 1e3, y[m] * 1e3, "-", lw=1.5, label=str(o))
        ax.plot(x[m][:1] * 1e3, y[m][:1] * 1e3, "o", ms=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.legend(fontsize=7)
    rep.figure(fig, "Object paths on the table seen from above (dot = start)")


def _plot_frames(rep: HtmlReport, ds: Dataset) -> None:
    ep = ds.episodes[0]
    for cam in sorted(ep.camera_streams):
        st = ep.camera_streams[cam]
        if "video" not in st:
            continue
        frames = list(ep.iter_video(cam))
        if not frames:
            continue
        labels = dict(ep.iter_labels(cam)) if "labels" in st else {}
        picks = sorted({0, len(frames) // 2, len(frames) - 1})
        fig, axes = new_figure(1, len(picks), figsize=(3.3 * len(picks), 2.8))
        axes = np.atleast_1d(axes)
        for ax, i in zip(axes, picks, strict=True):
            ax.imshow(frames[i])
            if i in labels:
                lab = labels[i].astype(float)
                lab[lab == 0] = np.nan
                ax.imshow(lab % 20, cmap="tab20", alpha=0.45, interpolation="nearest")
            ax.set_title(f"frame {i}", fontsize=8)
            ax.axis("off")
        rep.figure(fig, f"Camera {cam}: frames with panoptic labels overlaid")


def write_dataset_report(ds: Dataset, findings: Sequence[dict[str, Any]], out: str | Path) -> Path:
    """Write an HTML overview of ``ds`` with ``findings`` (validator JSON items) to ``out``."""
    rep = HtmlReport(f"robogs report — {ds.name}")
    rep.table(
        ["spec", "episodes", "cameras", "assets", "files"],
        [
            [
                ds.spec_version,
                len(ds.episodes),
                ", ".join(ds.camera_names),
                ", ".join(sorted(ds.assets)),
                len(ds.files),
            ]
        ],
    )
    _findings_section(rep, findings)
    rep.heading("Streams")
    rep.table(
        ["episode", "stream", "kind", "rows", "nominal Hz", "stamp source", "offset ns"],
        _stream_rows(ds),
    )
    if ds.episodes:
        rep.heading("Plots")
        for plot in (_plot_joints, _plot_intervals, _plot_objects, _plot_frames):
            try:
                plot(rep, ds)
            except RobogsError as exc:
                rep.paragraph(f"{plot.__name__[6:]}: not plotted ({exc.one_line()})", css="warning")
    return rep.save(out)
