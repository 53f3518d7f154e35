"""HTML report: residual-versus-time plots before and after a fit, phase by phase.

matplotlib is not a dependency of robogs, so the plots are inline SVG written here: one panel
per trajectory with the position-error norm [mm] of the model before (grey) and after (blue),
phases shaded behind, and the data-estimated noise floor as a dashed line.
"""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from robogs.physics.compare import CompareResult

__all__ = ["render_report", "svg_panel", "format_span"]

_PHASE_COLOURS = {
    "rest": "#f3f3f3",
    "contact": "#fde2c8",
    "sliding": "#d8ecd8",
    "free": "#dde6f7",
    "impact": "#f7d4d4",
    "grasp": "#ece0f5",
}


def svg_panel(
    t: np.ndarray,
    before: np.ndarray,
    after: np.ndarray,
    phases: list[str],
    floor: float,
    title: str,
    *,
    width: int = 640,
    height: int = 170,
) -> str:
    """One residual panel as an SVG string (time [s] on x, error [mm] on y)."""
    pad_l, pad_r, pad_t, pad_b = 46, 10, 22, 26
    w, h = width - pad_l - pad_r, height - pad_t - pad_b
    t0, t1 = float(t.min()), float(max(t.max(), t.min() + 1e-9))
    ymax = float(max(np.max(before), np.max(after), floor, 1e-3)) * 1.1

    def x(v: np.ndarray | float) -> np.ndarray | float:
        return pad_l + (np.asarray(v) - t0) / (t1 - t0) * w

    def y(v: np.ndarray | float) -> np.ndarray | float:
        return pad_t + h - np.asarray(v) / ymax * h

    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-size="11">'
    ]
    parts.append(f'<text x="{pad_l}" y="14" font-weight="bold">{html.escape(title)}</text>')
    # phase bands
    edges = np.concatenate([[t0], 0.5 * (t[1:] + t[:-1]), [t1]])
    start = 0
    for i in range(1, len(phases) + 1):
        if i == len(phases) or phases[i] != phases[start]:
            xa, xb = x(edges[start]), x(edges[i])
            col = _PHASE_COLOURS.get(phases[start], "#ffffff")
            parts.append(
                f'<rect x="{xa:.1f}" y="{pad_t}" width="{max(xb - xa, 0.5):.1f}" height="{h}" fill="{col}">'
                f"<title>{phases[start]}</title></rect>"
            )
            start = i
    parts.append(
        f'<rect x="{pad_l}" y="{pad_t}" width="{w}" height="{h}" fill="none" stroke="#888"/>'
    )
    for series, colour in ((before, "#888888"), (after, "#1f5fbf")):
        pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(x(t), y(series), strict=True))
        parts.append(f'<polyline points="{pts}" fill="none" stroke="{colour}" stroke-width="1.4"/>')
    yf = y(floor)
    parts.append(
        f'<line x1="{pad_l}" x2="{pad_l + w}" y1="{yf:.1f}" y2="{yf:.1f}" stroke="#c00" stroke-dasharray="4 3"/>'
    )
    for frac in (0.0, 0.5, 1.0):
        val = frac * ymax
        parts.append(f'<text x="4" y="{y(val) + 4:.1f}">{val:.1f} mm</text>')
    parts.append(f'<text x="{pad_l}" y="{height - 6}">{t0:.2f} s</text>')
    parts.append(f'<text x="{pad_l + w - 40}" y="{height - 6}">{t1:.2f} s</text>')
    parts.append("</svg>")
    return "".join(parts)


def format_span(t0: float, t1: float, *, min_digits: int = 2, sep: str = "–") -> str:
    """``"t0–t1 s"`` with the fewest decimals (at least ``min_digits``, at most 6) that keep
    the two ends apart, so a short segment never prints as a zero-length range."""
    for d in range(min_digits, 7):
        a, b = f"{t0:.{d}f}", f"{t1:.{d}f}"
        if a != b:
            return f"{a}{sep}{b} s"
    return f"{t0:.6f}{sep}{t1:.6f} s"


def _num(x: float, spec: str) -> str:
    return format(float(x), spec) if np.isfinite(x) else "—"


def _table(rows: list[list[str]], header: list[str]) -> str:
    head = "".join(f"<th>{html.escape(c)}</th>" for c in header)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><tr>{head}</tr>{body}</table>"


def render_report(
    before: CompareResult,
    after: CompareResult,
    out_html: str | Path,
    *,
    title: str,
    added: list[str],
    params: list[tuple[str, float, float, float, str]],
    labels: tuple[str, str] = ("stored physics", "refitted"),
    heldout: tuple[float, float] | None = None,
    notes: Sequence[str] = (),
    split: str = "",
    holdout: Sequence[str] = (),
    diagnosis: Sequence[tuple[str, float, float, str, float, float, str]] = (),
) -> Path:
    """Write the report (atomically); ``params`` rows are (name, value, low, high, unit), an
    infinite interval end printed as unbounded; ``labels`` say which models "before" and
    "after" are (e.g. "revision 1, refitted"); ``heldout``: held-out position RMS [mm] before
    and after, by diagnose's procedure on the split ``split`` describes
    (:func:`robogs.physics.heldout.split_label`) with ``holdout`` the trajectories a held-out
    choice held out (empty: the default folds); ``notes``: one line per effect not fully
    determined (e.g. partly identified: which parameters, what is determined); ``diagnosis``:
    the diagnosis the "after" effect was chosen from, on the same split, one row per effect:
    (name, held-out RMS before, after, their unit (mm, or px for an effect seen in mask
    boundaries), held-out gain [sigma^2], the gate's null quantile [sigma^2], verdict)."""
    out = Path(out_html)
    phase_rows = [
        [
            p,
            f"{before.phases_mm.get(p, float('nan')):.2f}",
            f"{after.phases_mm.get(p, float('nan')):.2f}",
        ]
        for p in _PHASE_COLOURS
        if p in before.phases_mm
    ]
    worst = [
        [s.trajectory, s.phase, format_span(s.t_start, s.t_end), f"{s.rms_mm:.2f}"]
        for s in before.worst
    ]
    prm = [
        [n, f"{v:.5g}", f"[{lo:.4g}, {hi:.4g}]" if np.isfinite([lo, hi]).all() else "unbounded", u]
        for n, v, lo, hi, u in params
    ]
    held = ""
    if holdout:  # one fold: the named trajectories held out, the others train it
        which = split or f"held out: {', '.join(holdout)}"
    else:
        which = "default folds" + (f" ({split})" if split else "")
    if heldout is not None and np.isfinite(heldout).all():
        held = (
            f"<p>Held-out RMS position error (as diagnose, on this split): "
            f"{heldout[0]:.3f} mm &rarr; {heldout[1]:.3f} mm.</p>"
        )
    held = (
        f'<p class="split">Split of the held-out error and the gate: {html.escape(which)}.</p>'
        + held
    )
    diag = ""
    if diagnosis:
        diag_rows = [
            [n, f"{_num(b, '.3f')} → {_num(a, '.3f')} {u}", _num(g, ".3g"), _num(q, ".3g"), v]
            for n, b, a, u, g, q, v in diagnosis
        ]
        diag = f"<h2>Diagnosis on the same split ({html.escape(which)})</h2>" + _table(
            diag_rows,
            ["effect", "held-out RMS", "held-out gain σ²", "null quantile σ²", "verdict"],
        )
    note_html = (
        "<h2>Not fully determined by this data</h2><ul>"
        + "".join(f"<li>{html.escape(n)}</li>" for n in notes)
        + "</ul>"
        if notes
        else ""
    )
    panels = []
    for sb, sa in zip(before.series, after.series, strict=True):
        nb = np.linalg.norm(sb["residual_mm"], axis=-1)
        na = np.linalg.norm(sa["residual_mm"], axis=-1)
        panels.append(
            svg_panel(sb["t"], nb, na, sb["phase"], after.noise_floor_mm, sb["trajectory"])
        )
    if before.masks is not None:
        m = before.masks
        mask_rows = [
            [r.camera, r.label, f"{r.boundary_px:.3g}", f"{r.boundary_mm:.3g}", f"{r.iou:.3f}"]
            for r in m.labels
        ]
        masks = (
            f"<p>{m.frames} frames re-rendered, objects at {html.escape(m.object_poses)} poses: "
            f"{m.boundary_px:.3g} px, {m.boundary_mm:.3g} mm.</p>"
            + _table(mask_rows, ["camera", "link/object", "boundary px", "boundary mm", "IoU"])
        )
    else:
        masks = f"<p>No mask-boundary stream: {html.escape(before.masks_absent)}.</p>"
    legend = " ".join(
        f'<span style="background:{c};padding:1px 6px;border:1px solid #ccc">{p}</span>'
        for p, c in _PHASE_COLOURS.items()
    )
    doc = f"""<!DOCTYPE html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>body{{font-family:sans-serif;margin:24px;max-width:1000px}}table{{border-collapse:collapse;margin:8px 0}}
td,th{{border:1px solid #ccc;padding:3px 8px;text-align:right}}th{{background:#eee}}</style></head><body>
<h1>{html.escape(title)}</h1>
<p>Position error before (grey: {html.escape(labels[0])}) and after (blue: {html.escape(labels[1])}{", adding " + html.escape(", ".join(added)) if added else ""}).
Both refit the base parameters, the effects present and each trajectory's initial pose.
Dashed red: noise floor estimated from the data ({after.noise_floor_mm:.2f} mm; source {html.escape(str(after.noise.get("source")))}).</p>
<p>RMS position error: {before.rms_mm:.2f} mm &rarr; {after.rms_mm:.2f} mm; yaw {before.rms_deg:.2f}&deg; &rarr; {after.rms_deg:.2f}&deg;.</p>
{held}
{diag}
<h2>Per phase (RMS, mm)</h2>{_table(phase_rows, ["phase", "before", "after"])}
<h2>Mask boundary of the stored model (mean symmetric distance)</h2>{masks}
<h2>Worst segments before</h2>{_table(worst, ["trajectory", "phase", "time", "RMS mm"])}
<h2>Fitted parameters after (95 % interval)</h2>{_table(prm, ["parameter", "value", "interval", "unit"])}
{note_html}
<h2>Residuals per trajectory</h2><p>{legend}</p>
{"".join(f"<div>{p}</div>" for p in panels)}
<p>Plots: inline SVG generated by robogs (matplotlib is not used).</p>
</body></html>"""
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    tmp.write_text(doc, encoding="utf-8")
    os.replace(tmp, out)
    return out
