"""``robogs compare | diagnose | fit | report`` — the physics loop on the command line.

A dataset with ``object_poses`` is checked against the rigid-object model
(pushes, slides, grasps); a dataset whose ``joint_states`` carry efforts, or
that records end-effector poses (``ee_poses``) beside its joint states, is
checked against the arm model (joint torques, and end-effector poses against
forward kinematics). ``--model`` picks one when both apply.

Every "before" and "after" of the object model is a baseline
(:mod:`robogs.physics.baseline`): a physics revision with its base parameters, present effects
and per-trajectory initial poses refitted, so compare, diagnose, fit and report agree.
Exit codes: 0 done, 1 diagnose found no effect while the model does not reproduce the data
(:mod:`robogs.physics.sanity`), 2 usage error or unreadable input.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from robogs.format.errors import InputError

__all__ = ["add_arguments_for", "run"]


def add_arguments_for(verb: str, p: argparse.ArgumentParser) -> None:
    from robogs.physics.split import add_split_argument

    p.add_argument("dataset", type=Path, help="robogs dataset folder")
    p.add_argument(
        "--model",
        choices=("auto", "object", "arm"),
        default="auto",
        help="object: rigid objects vs object_poses; arm: joint torques vs efforts and "
        "end-effector poses vs forward kinematics (default auto)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object for machines")
    add_split_argument(p)
    p.add_argument(
        "--engine",
        choices=("auto", "planar", "mujoco"),
        default="planar",
        help="object model's simulator: planar (torch, one box on a plane), mujoco (3-D "
        "contacts) or auto (planar when it can represent the scene; prints the choice)",
    )
    if verb in ("compare", "diagnose", "fit"):
        p.add_argument(
            "--mask-frames",
            type=int,
            default=30,
            metavar="N",
            help="camera frames per stream re-rendered for the mask-boundary stream and "
            "camera_intrinsics (default 30; 0: none)",
        )
    if verb in ("compare", "diagnose", "fit", "report"):
        hold = p.add_mutually_exclusive_group()
        hold.add_argument(
            "--holdout",
            default=None,
            metavar="TRAJ[,TRAJ...]",
            help="trajectories held out together as one fold for the held-out error (and, in "
            "diagnose and report, the gate's statistic and null; report names the split in the "
            "HTML); an episode cut into <episode>#<k> holds "
            "out all its pieces (default folds: object model 5 of whole trajectories; arm: "
            "leave one trajectory out, 5 groups above five)",
        )
        hold.add_argument(
            "--holdout-column",
            default=None,
            metavar="segment[=V1,...]",
            help="hold out the episodes whose segment (a tabular log's segment/episode/"
            "trajectory column) is V1, V2...; without values, those of the last episode's "
            "segment (the data recorded last)",
        )
    if verb in ("diagnose", "report"):
        from robogs.physics.gate import METHODS

        p.add_argument(
            "--gate-null",
            choices=METHODS,
            default=None,
            help="object model: the evidence gate's null (default parametric: this recording's "
            "own measurement error simulated; both: the base residual sign-flipped per "
            "trajectory and white noise); sets $ROBOGS_GATE_METHOD for this run",
        )
    if verb == "compare":
        p.add_argument(
            "--mask-poses",
            choices=("model", "recorded"),
            default="model",
            help="render the object at the model's predicted poses (default) or its recorded ones",
        )
    if verb == "diagnose":
        p.add_argument(
            "--effects", default=None, help="comma-separated candidate effects (default: all)"
        )
        p.add_argument("--no-progress", action="store_true", help="no progress bar")
        p.add_argument(
            "--auto",
            action="store_true",
            help="run the selection loop to its end and print its path: each step's "
            "effect, held-out error, evidence and the null quantile it was judged against",
        )
        p.add_argument(
            "--plot",
            type=Path,
            default=None,
            help="--auto, object model: PNG of the path (default <dataset>.diagnose-auto.png)",
        )
    if verb == "fit":
        p.add_argument(
            "--add",
            action="append",
            default=[],
            metavar="EFFECT",
            help="effect to add (repeatable; none: refit the base model and present effects)",
        )
        p.add_argument("--dry-run", action="store_true", help="fit and print, write nothing")
        p.add_argument(
            "--revert",
            type=int,
            default=None,
            metavar="REV",
            help="make physics revision REV current again (kept history)",
        )
        p.add_argument("--note", default=None, help="note stored with the new physics revision")
    if verb == "report":
        p.add_argument(
            "--add",
            action="append",
            default=[],
            metavar="EFFECT",
            help="effect(s) whose refit is shown as 'after' (default: when the current revision "
            "was written by fit, that fit; otherwise the first effect diagnose reports)",
        )
        p.add_argument(
            "--effects",
            default=None,
            help="without --add: comma-separated candidates of the diagnosis that picks 'after' "
            "(default: all); the HTML shows that diagnosis on the held-out split",
        )
        p.add_argument(
            "--out", type=Path, default=None, help="HTML file (default: <dataset>.physics.html)"
        )
        p.add_argument(
            "--rrd", type=Path, default=None, help="also log the residuals into this Rerun file"
        )


def _model(ds_path: Path, choice: str) -> str:
    from robogs.format import Dataset

    if choice != "auto":
        return choice
    ds = Dataset.open(ds_path)
    has_obj = any(e.has("object_poses") for e in ds.episodes)
    has_eff = has_ee = False
    for e in ds.episodes:
        if e.has("joint_states"):
            has_eff = has_eff or any(n.startswith("effort.") for n in _columns(e))
            has_ee = has_ee or e.has("ee_poses")
    if has_obj:
        return "object"
    if has_eff or has_ee:
        return "arm"
    raise InputError(
        "nothing to compare: the dataset has neither object_poses nor joint efforts "
        "nor end-effector poses",
        path=ds_path,
        hint="record object poses (mocap), joint torques/currents or end-effector poses",
    )


def _columns(ep: Any) -> list[str]:
    import pyarrow.parquet as pq

    return pq.ParquetFile(ep.table_path("joint_states")).schema_arrow.names


def _print_json(obj: Any) -> None:
    print(json.dumps(obj, indent=2, default=float))


def _fmt(x: Any, spec: str = ".3g") -> str:
    return "—" if x is None else format(float(x), spec)


def _param_line(p: dict[str, Any]) -> str:
    """One estimate as ``fit`` prints it: name, value, 95 % interval, unit."""
    return (
        f"  {p['name']:32s} {_fmt(p['value'], '.5g')}  [{_fmt(p['low'])}, {_fmt(p['high'])}] "
        f"{p.get('unit', '')}"
    )


def _effects_table(effects: list[dict[str, Any]], title: str) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=title)
    for col in (
        "rank",
        "effect",
        "family",
        "ΔBIC",
        "held-out before → after",
        "evidence / null quantile",
        "explained",
        "parameters",
        "phases",
        "rivals",
        "verdict",
    ):
        t.add_column(col)
    for i, e in enumerate(effects, 1):
        params = ", ".join(
            f"{p['name'].split('.')[-1]}={_fmt(p['value'])} [{_fmt(p['low'])}, {_fmt(p['high'])}]"
            f"{' ' + p['unit'] if p.get('unit') else ''}"
            for p in e.get("params", [])[:4]
        )
        if len(e.get("params", [])) > 4:
            params += f" (+{len(e['params']) - 4})"
        verdict = e.get("verdict") or ("missing" if e.get("reported") else "not supported")
        style = "bold green" if e.get("reported") else None
        t.add_row(
            str(i),
            e["name"],
            e.get("family", ""),
            _fmt(e.get("delta_bic"), ".1f"),
            f"{_fmt(e.get('heldout_rms_before'))} → {_fmt(e.get('heldout_rms_after'))}"
            + (f" {e['unit']}" if e.get("unit", "mm") != "mm" else ""),
            f"{_fmt(e.get('heldout_gain_sigma2'))} / {_fmt(e.get('null_threshold_sigma2'))} σ²"
            + (f" (×{e['null_factor']:.2f})" if (e.get("null_factor") or 1.0) > 1.0 else "")
            if e.get("null_threshold_sigma2") is not None
            else "—",
            _fmt(e.get("explained"), ".0%") if e.get("explained") is not None else "—",
            params,
            ", ".join(e.get("phases", [])),
            ", ".join(e.get("rivals", [])),
            verdict,
            style=style,
        )
    console = Console()
    if not console.is_terminal:
        console = Console(width=200)  # logs and pipes: keep rows on one line
    console.print(t)


def _compare(args: argparse.Namespace, model: str) -> int:
    if model == "arm":
        from robogs.physics.arm.api import compare_arm

        if _holdout(args, "arm") is not None:
            raise InputError(
                "compare --holdout is for the object model; the arm model's held-out error "
                "is fit's",
                path=args.dataset,
                where="--holdout",
                hint="robogs fit DATASET --model arm --add EFFECT --holdout TRAJ --dry-run",
            )

        res = compare_arm(args.dataset)
        if args.json:
            _print_json(res)
            return 0
        if "joints" in res:
            _print_torque_compare(res)
        if "kinematic" in res:
            _print_pose_compare(res["kinematic"])
        for n in res.get("notes", []):
            print(f"  note: {n}")
        return 0
    from robogs.physics.api import compare, heldout_error

    holdout = _holdout(args)
    engine = _engine(args)
    res = compare(
        args.dataset,
        mask_frames=args.mask_frames,
        mask_poses=args.mask_poses,
        engine=engine,
    )
    d = res.to_dict()
    rev = _revision(args.dataset)
    d["baseline"] = {"revision": rev, "refitted": _REFITTED}
    if holdout is not None:
        d["heldout"] = heldout_error(args.dataset, holdout, engine=engine)
    if args.json:
        _print_json(d)
        return 0
    print(f"model: physics revision {rev}, refitted ({_REFITTED})")
    print(
        f"object position residual: rms {d['rms_mm']:.2f} mm, orientation {d['rms_deg']:.2f} deg; "
        f"noise floor {d['noise_floor_mm']:.2f} mm (estimated from the data)"
    )
    _print_force(d.get("force"), d.get("wrench_note"))
    if "heldout" in d:
        h = d["heldout"]
        print(
            f"held-out position RMS: {h['heldout_rms_mm']:.3f} mm ({h['split']}; held-out χ² "
            f"{h['heldout_chi2']:.1f} σ²)"
        )
    print(
        "per phase [mm]: " + ", ".join(f"{k} {v:.2f}" for k, v in d["phases_mm"].items() if v == v)
    )
    for s in d["streams"]:
        print(
            f"  {s['trajectory']:>10s} {s['stream']}: rms {s['rms_mm']:.2f} mm, max {s['max_mm']:.2f} mm"
        )
    print("worst segments:")
    for w in d["worst"][:5]:
        print(
            f"  {w['trajectory']:>10s} {w['phase']:>8s} {format_span(w['t_start'], w['t_end'])}: "
            f"{w['rms_mm']:.2f} mm, {w['rms_deg']:.2f} deg"
        )
    _print_masks(d)
    return 0


def _print_force(force: dict[str, Any] | None, note: str | None) -> None:
    """The pusher force residual [N] against the sensor's noise floor, and the wrench note."""
    if force:
        print(
            f"pusher force residual: rms {force['rms_n']:.3f} N, noise floor "
            f"{force['noise_floor_n']:.3f} N ({force['bins']} bins)"
        )
    if note:
        print(f"  {note}")


def _print_masks(d: dict[str, Any]) -> None:
    """The mask-boundary stream of ``compare`` (or why it is absent), per camera and label."""
    m = d.get("mask_boundary")
    if m is None:
        print(f"mask boundary: absent ({d.get('mask_boundary_absent')})")
        return
    print(
        f"mask boundary ({m['frames']} frames, objects at {m['object_poses']} poses, "
        f"{m['seconds']:.1f} s): {_fmt(m['boundary_px'])} px, {_fmt(m['boundary_mm'])} mm"
    )
    for r in m["labels"]:
        print(
            f"  {r['camera']:>8s} {r['label']:18s} {_fmt(r['boundary_px']):>6s} px "
            f"{_fmt(r['boundary_mm']):>6s} mm  IoU {_fmt(r['iou'], '.3f')}"
        )
    for n in m["notes"][:5]:
        print(f"  note: {n}")


def _print_torque_compare(res: dict[str, Any]) -> None:
    print(
        f"joint-torque residuals ({res['n_trajectories']} trajectories, {res['n_samples']} samples)"
    )
    for j, r in res["joints"].items():
        print(
            f"  {j:24s} rms {r['rms_nm']:.3f} N·m   noise {r['noise_nm']:.3f} N·m   bias {r['bias_nm']:+.3f}"
        )
    print(
        "worst phases: "
        + ", ".join(
            f"{p['phase']} {p['rms_sigma']:.1f} σ (worst {p['joint']} {p['joint_rms_sigma']:.1f} σ)"
            for p in res["worst_phases"]
        )
    )
    print("worst segments:")
    for w in res["worst_segments"][:5]:
        span = format_span(w["t_start_ns"] / 1e9, w["t_end_ns"] / 1e9)
        print(
            f"  {w['trajectory']} {w['joint']} {w['phase']:>10s}  {span}  "
            f"rms {w['rms_nm']:.3f} N·m ({w['rms_sigma']:.1f} σ)"
        )


def _print_pose_compare(k: dict[str, Any]) -> None:
    rot = f", orientation rms {k['rms_deg']:.3f} deg" if k.get("rms_deg") is not None else ""
    print(
        f"end-effector residuals of {k['link']} ({k['n_trajectories']} trajectories, {k['n_samples']} "
        f"poses): position rms {k['rms_mm']:.3f} mm (max {k['max_mm']:.3f}){rot}"
    )
    for c, r in k["channels"].items():
        print(
            f"  {c:3s} rms {r['rms']:.4f} {r['unit']}   noise {r['noise']:.4f} {r['unit']}   "
            f"bias {r['bias']:+.4f}"
        )
    print(
        "worst phases: "
        + ", ".join(
            f"{p['phase']} {p['rms_sigma']:.1f} σ ({p['rms_mm']:.3f} mm)" for p in k["worst_phases"]
        )
    )
    print("worst segments:")
    for w in k["worst_segments"][:5]:
        span = format_span(w["t_start_ns"] / 1e9, w["t_end_ns"] / 1e9)
        print(
            f"  {w['trajectory']} {w['phase']:>10s}  {span}  "
            f"rms {w['rms_mm']:.3f} mm ({w['rms_sigma']:.1f} σ, worst channel {w['channel']})"
        )


def _param_rows(params: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Arm parameters ``{name: {value, low, high, unit}}`` as the table's list of rows."""
    return [{"name": k, **v} for k, v in params.items()]


def _arm_table(d: dict[str, Any]) -> None:
    titles = {"torque": "the joint torques", "kinematic": "the end-effector poses"}
    for kind, rep in d.get("residuals", {}).items():
        rows = [
            {
                **e,
                "params": _param_rows(e["params"]),
                "verdict": (
                    f"missing (held-out gain {_fmt(e.get('heldout_gain_sigma2'))} > null "
                    f"quantile {_fmt(e.get('gate_heldout_sigma2'))} σ²)"
                )
                if e["reported"]
                else "; ".join(e.get("reasons", [])) or "not supported",
            }
            for e in d["effects"]
            if e.get("residual", "torque") == kind
        ]
        _effects_table(rows, f"candidate effects on {titles[kind]} ({rep['split']})")
        if kind == "torque":
            print(
                "noise floor [N·m]: "
                + ", ".join(f"{j} {v:.3g}" for j, v in rep["noise_floor_nm"].items())
            )
        else:
            print(
                f"noise floor of {rep['link']}: "
                + ", ".join(f"{c} {v:.3g} {rep['units'][c]}" for c, v in rep["noise_floor"].items())
            )
        for e in d["effects"]:
            bad = {k: p["why"] for k, p in e["params"].items() if p.get("identifiable") is False}
            if e.get("residual") == kind and e.get("reported") and bad:
                print(
                    f"  {e['name']}: unidentifiable "
                    + "; ".join(f"{k} ({w})" for k, w in bad.items())
                )
    for s in d.get("skipped", []):
        print(f"  skipped {s['name']}: {s['reason']}")
    found = [e["name"] for e in d["effects"] if e.get("reported")]
    print("missing effect(s): " + (", ".join(found) if found else "none above the noise"))
    if found:
        print(f"next: robogs fit DATASET --add {found[0]}")


def _holdout(args: argparse.Namespace, model: str = "object") -> list[str] | None:
    """``--holdout`` or ``--holdout-column`` as trajectory names (None: the default folds).

    ``--holdout-column`` selects episodes (:func:`robogs.physics.heldout.holdout_from_column`);
    they become the object model's names as they are (an episode cut into ``<episode>#<k>``
    holds out all its pieces) and the arm model's trajectory names (``<episode>``, or
    ``<episode>/<segment>`` where the two differ). What was selected is printed once (stderr
    with ``--json``)."""
    raw = getattr(args, "holdout", None)
    spec = getattr(args, "holdout_column", None)
    if raw is not None:
        names = [n.strip() for n in raw.split(",") if n.strip()]
        if not names:
            raise InputError(
                "--holdout names no trajectory",
                hint="--holdout TRAJ[,TRAJ...], or leave it out for the default folds",
            )
        return names
    if spec is None:
        return None
    from robogs.format import Dataset
    from robogs.physics.heldout import holdout_from_column

    eps = Dataset.open(args.dataset).episodes
    ids, what = holdout_from_column([(e.id, e.segment) for e in eps], spec)
    if not getattr(args, "_holdout_said", False):
        print(f"--holdout-column {what}", file=sys.stderr if args.json else sys.stdout)
        args._holdout_said = True
    if model == "arm":
        seg = {e.id: e.segment for e in eps}
        return [i if seg[i] == i else f"{i}/{seg[i]}" for i in ids]
    return ids


def _auto_path(d: dict[str, Any]) -> list[dict[str, Any]]:
    """The path of the arm selection loop: one row per accepted effect, then one per residual
    saying why the loop stopped (the best candidate left and the gate it failed)."""
    rows: list[dict[str, Any]] = []
    for st in d.get("steps", []):
        rows.append(
            {
                "step": len(rows) + 1,
                "effect": st["added"],
                "residual": st["residual"],
                "given": st["given"],
                "heldout_before": st["heldout_rms_before"],
                "heldout_after": st["heldout_rms_after"],
                "delta_bic": st["delta_bic"],
                "heldout_gain_sigma2": st.get("heldout_gain_sigma2"),
                "null_quantile_sigma2": st.get("gate_heldout_sigma2"),
                "verdict": "added",
            }
        )
    for kind, stop in (d.get("stop") or {}).items():
        if stop is None:
            continue
        rows.append(
            {
                "step": None,
                "effect": stop.get("best_left"),
                "residual": kind,
                "given": stop["given"],
                "heldout_gain_sigma2": stop.get("heldout_gain_sigma2"),
                "null_quantile_sigma2": stop.get("gate_heldout_sigma2"),
                "verdict": "stop: " + ("; ".join(stop["reasons"]) or "no candidate passes"),
            }
        )
    return rows


def _print_path(path: list[dict[str, Any]]) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title="selection path (diagnose --auto)")
    for col in (
        "step",
        "effect",
        "residual",
        "held-out before → after",
        "ΔBIC",
        "held-out gain",
        "null quantile",
        "verdict",
    ):
        t.add_column(col)
    for r in path:
        t.add_row(
            "—" if r["step"] is None else str(r["step"]),
            r["effect"] or "—",
            r["residual"],
            f"{_fmt(r.get('heldout_before'))} → {_fmt(r.get('heldout_after'))}",
            _fmt(r.get("delta_bic"), ".1f"),
            f"{_fmt(r.get('heldout_gain_sigma2'))} σ²",
            f"{_fmt(r.get('null_quantile_sigma2'))} σ²",
            r["verdict"],
        )
    console = Console()
    if not console.is_terminal:
        console = Console(width=200)
    console.print(t)
    steps = sum(1 for r in path if r["step"] is not None)
    print(f"loop stopped after {steps} step(s)")


def _object_auto(
    args: argparse.Namespace, effects: list[str] | None, holdout: list[str] | None = None
) -> int:
    """``diagnose --auto`` for the object model: the loop to its end, its path as a table and
    a PNG (``--plot``, default ``<dataset>.diagnose-auto.png``)."""
    from robogs.physics.api import diagnose_auto
    from robogs.physics.diagnose import plot_path

    p = diagnose_auto(args.dataset, effects=effects, holdout=holdout, engine=_engine(args))
    rows = [
        {
            "step": s.step if s.verdict.startswith("added") else None,
            "effect": s.effect,
            "residual": "object poses",
            "heldout_before": s.heldout_rms_before,
            "heldout_after": s.heldout_rms_after,
            "delta_bic": s.delta_bic,
            "heldout_gain_sigma2": s.heldout_gain_sigma2,
            "null_quantile_sigma2": s.null_threshold_sigma2,
            "verdict": s.verdict,
        }
        for s in p.steps
    ]
    ds = Path(str(args.dataset)).expanduser()
    plot = getattr(args, "plot", None) or ds.parent / f"{ds.name}.diagnose-auto.png"
    plot_path(p, plot)
    d = {**p.to_dict(), "path_table": rows, "plot": str(plot)}
    if args.json:
        _print_json(d)
        return 0
    _effects_table(d["last"]["effects"], f"candidate effects left for {args.dataset}")
    _print_path(rows)
    if (d["last"].get("design") or {}).get("split"):
        print(f"held-out error and gate: {d['last']['design']['split']}")
    g = d["last"]["gate"]
    print(
        f"null calibration ({g.get('method') or 'linearised held-out null'}, family-wise "
        f"{g.get('alpha', 0.05):.0%}): {p.calibration_seconds:.1f} s "
        f"in all, {g.get('draws')} draws per step{' (cached)' if g.get('cached') else ''}"
    )
    for s in d["last"]["skipped"]:
        print(f"  skipped {s['name']}: {s['reason']}")
    print(f"accepted: {', '.join(p.accepted) or 'nothing'}; plot: {plot}")
    if d["model"]:
        print("model at the end (every effect refitted jointly with the base, all trajectories):")
        for name, ps in d["model"].items():
            print(f"{name}:")
            for q in ps:
                print(_param_line(q))
    return 0


@contextlib.contextmanager
def _gate_null(args: argparse.Namespace) -> Iterator[None]:
    """``--gate-null``: the object model's gate reads it as ``$ROBOGS_GATE_METHOD``, set for
    this command only (the previous value is restored)."""
    from robogs.physics.diagnose import GATE_METHOD_ENV

    new, old = getattr(args, "gate_null", None), os.environ.get(GATE_METHOD_ENV)
    if not new:
        yield
        return
    os.environ[GATE_METHOD_ENV] = new
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(GATE_METHOD_ENV, None)
        else:
            os.environ[GATE_METHOD_ENV] = old


def _diagnose(args: argparse.Namespace, model: str) -> int:
    if model == "arm" and getattr(args, "gate_null", None):
        raise InputError(
            "--gate-null picks the object model's gate null; the arm model's gate has its own",
            where="--gate-null",
            hint="leave --gate-null out with the arm model, or use --model object",
        )
    with _gate_null(args):
        return _diagnose_run(args, model)


def _diagnose_run(args: argparse.Namespace, model: str) -> int:
    from robogs.physics.sanity import none_found_text, note_diagnosis

    effects = [e.strip() for e in args.effects.split(",")] if args.effects else None
    if model == "arm":
        from robogs.physics.arm.api import diagnose_arm

        d = diagnose_arm(args.dataset, candidates=effects, holdout=_holdout(args, "arm"))
        if getattr(args, "auto", False):
            d["path"] = _auto_path(d)
        if not args.json:
            _arm_table(d)
            if getattr(args, "auto", False):
                _print_path(d["path"])
            return 0
    else:
        from robogs.physics.api import diagnose

        holdout = _holdout(args)
        if getattr(args, "auto", False):
            return _object_auto(args, effects, holdout)

        if args.no_progress or args.json:
            d = diagnose(
                args.dataset,
                effects=effects,
                mask_frames=args.mask_frames,
                engine=_engine(args),
                holdout=holdout,
            ).to_dict()
        else:
            from rich.progress import Progress

            with Progress(transient=True) as bar:
                task = bar.add_task("fitting candidate effects", total=None)
                d = diagnose(
                    args.dataset,
                    effects=effects,
                    progress=lambda i, n: bar.update(task, completed=i, total=n),
                    mask_frames=args.mask_frames,
                    engine=_engine(args),
                    holdout=holdout,
                ).to_dict()
    note_diagnosis(d)
    if args.json:
        _print_json(d)
        return 0
    _effects_table(d["effects"], f"candidate effects for {args.dataset}")
    if d.get("path_note"):
        print(f"note: {d['path_note']}")
    print(
        f"base model (physics revision {_revision(args.dataset)}, refitted): object position "
        f"rms {d['rms_base_mm']:.2f} mm, noise floor {d['noise_floor_mm']:.2f} mm"
    )
    if (d.get("design") or {}).get("split"):
        print(f"held-out error and gate: {d['design']['split']}")
    g = d.get("gate") or {}
    if "draws" in g:
        print(
            f"gate: {g.get('method')}, family-wise {g.get('alpha', 0.05):.0%}; calibration "
            f"{g.get('seconds', 0.0):.1f} s, {g.get('draws')} draws"
            + (" (cached)" if g.get("cached") else "")
        )
    chk = g.get("linearisation_check") or {}
    scaled = {n: c["factor"] for n, c in (chk.get("candidates") or {}).items() if c["factor"] > 1}
    if chk:
        print(
            "  linearisation check on null draws: "
            + (", ".join(f"{n} threshold ×{f:.2f}" for n, f in scaled.items()) or "no change")
            + f"; {len(chk['candidates'])} candidate(s), {chk['rollouts']} rollouts, "
            f"{chk['seconds']:.1f} s" + (" (cached)" if chk.get("cached") else "")
        )
    if (d.get("design") or {}).get("wrench_note"):
        print(f"  {d['design']['wrench_note']}")
    for s in d.get("skipped", []):
        print(f"  skipped {s['name']}: {s['reason']}")
    for e in d["effects"]:
        if e.get("reported") and e.get("undetermined"):
            print(
                f"  {e['name']}: partly identified, {', '.join(e['undetermined'])} not "
                f"determined (interval unbounded); to determine: {e.get('separate_by')}"
            )
    found = [e["name"] for e in d["effects"] if e.get("reported")]
    print("missing effect(s): " + (", ".join(found) if found else none_found_text()))
    if found:
        print(
            f"next: robogs fit {args.dataset} --add {found[0]}, then diagnose again: an effect "
            "a stronger missing one masks is judged only once that one is in the model "
            f"(robogs diagnose {args.dataset} --auto runs the loop to its end)"
        )
    return 0


def _fit(args: argparse.Namespace, model: str) -> int:
    if args.revert is not None:
        from robogs.physics.api import revert

        rev = revert(args.dataset, args.revert)
        print(f"physics revision {args.revert} restored as revision {rev}")
        return 0
    if model == "arm":
        if not args.add:
            raise InputError(
                "nothing to fit", hint="name the effect(s) with --add EFFECT (see robogs diagnose)"
            )
        from robogs.physics.arm.api import fit_arm

        d = fit_arm(
            args.dataset,
            args.add,
            write=not args.dry_run,
            note=args.note,
            holdout=_holdout(args, "arm"),
        )
        if args.json:
            _print_json(d)
            return 0
        if "rms_before_nm" in d:
            print(
                "joint-torque RMS [N·m] before → after in-sample, held-out before → after "
                f"({d.get('heldout_split', '')}), noise floor:"
            )
            for j, before in d["rms_before_nm"].items():
                print(
                    f"  {j:24s} {before:.4g} → {d['rms_after_nm'][j]:.4g}  held-out "
                    f"{d['heldout_rms_before_nm'][j]:.4g} → {d['heldout_rms_after_nm'][j]:.4g}  "
                    f"({d['noise_floor_nm'][j]:.3g})"
                )
        if "ee" in d:
            ee = d["ee"]
            print(
                f"end-effector ({ee['link']}) position RMS: {ee['rms_before_mm']:.3f} → {ee['rms_after_mm']:.3f} mm"
                + (
                    f", orientation RMS: {ee['rms_before_deg']:.3f} → {ee['rms_after_deg']:.3f} deg"
                    if ee.get("rms_before_deg") is not None
                    else ""
                )
            )
        for eff, params in d["params"].items():
            print(f"{eff}:")
            for p in _param_rows(params):
                print(_param_line(p))
        if d["clamped"]:
            print("written as 0 (fitted negative): " + ", ".join(d["clamped"]))
        for eff, bad in d.get("unidentifiable", {}).items():
            print(
                f"unidentifiable (not written) in {eff}: "
                + "; ".join(f"{k} ({w})" for k, w in bad.items())
            )
        print(
            "dry run: nothing written"
            if args.dry_run
            else f"wrote physics revision {d.get('revision')}"
        )
        return 0
    else:
        from robogs.physics.api import fit

        res = fit(
            args.dataset,
            args.add,
            write=not args.dry_run,
            note=args.note,
            mask_frames=args.mask_frames,
            engine=_engine(args),
            holdout=_holdout(args),
        )
        if args.dry_run and (err := res.refusal(args.dataset)) is not None:
            raise err  # as the written fit: an added effect of which nothing is determined
        d = res.to_dict()
        if args.json:
            _print_json(d)
            return 0
        if d["rms_before_mm"] is not None:
            after = f"revision {d['from_revision']}" + "".join(f" + {a}" for a in args.add)
            print(
                f"object position RMS: {d['rms_before_mm']:.3f} → {d['rms_after_mm']:.3f} mm "
                f"(noise floor {d['noise_floor_mm']:.3f} mm; before: revision "
                f"{d['from_revision']}, after: {after}, each refitted)"
            )
            objects = d.get("objects") or {}
            for name, o in objects.items() if len(objects) > 1 else ():
                held = ""
                if o.get("heldout_rms_before_mm") is not None:
                    held = (
                        f"; held-out {o['heldout_rms_before_mm']:.3f} → "
                        f"{o['heldout_rms_after_mm']:.3f} mm"
                    )
                print(
                    f"  {name}: position RMS {o['rms_before_mm']:.3f} → {o['rms_after_mm']:.3f} mm "
                    f"(noise floor {o['noise_floor_mm']:.3f} mm{held})"
                )
            fb, fa = d.get("force_before"), d.get("force_after")
            if fb and fa:
                print(
                    f"pusher force RMS: {fb['rms_n']:.3f} → {fa['rms_n']:.3f} N "
                    f"(noise floor {fa['noise_floor_n']:.3f} N)"
                )
            if d.get("wrench_note"):
                print(f"  {d['wrench_note']}")
            if d.get("heldout_rms_before_mm") is not None:
                print(
                    f"held-out position RMS: {d['heldout_rms_before_mm']:.3f} → "
                    f"{d['heldout_rms_after_mm']:.3f} mm ({d['heldout_split']}; held-out χ² "
                    f"{d['heldout_chi2_before']:.1f} → {d['heldout_chi2_after']:.1f} σ²)"
                )
            for name, text in d.get("notes", {}).items():
                print(f"  {name}: {text}")
        for c in d["cameras"]:
            b, a = c["before"], c["after"]
            print(
                f"camera {c['camera']}: fx {b['fx']:.3f} → {a['fx']:.3f}, fy {b['fy']:.3f} → "
                f"{a['fy']:.3f}, cx {b['cx']:.3f} → {a['cx']:.3f}, cy {b['cy']:.3f} → {a['cy']:.3f} px; "
                f"mask boundary {c['boundary_px_before']:.3f} → {c['boundary_px_after']:.3f} px "
                f"(noise {c['noise_px']:.3f} px; diagnosis: {c['verdict']})"
            )
        if d["unidentifiable"]:
            print("unidentifiable (not written): " + ", ".join(d["unidentifiable"]))
    for p in d["params"]:
        print(_param_line(p))
    print(
        "dry run: nothing written"
        if args.dry_run
        else f"wrote physics revision {d.get('revision')}"
    )
    return 0


def _report(args: argparse.Namespace, model: str) -> int:
    if model == "arm":
        raise InputError(
            "the HTML report covers the object model", hint="use robogs compare --model arm"
        )
    with _gate_null(args):
        return _report_run(args)


def _report_run(args: argparse.Namespace) -> int:
    from robogs.physics.api import diagnose, report, report_baselines

    add = list(args.add)
    engine = _engine(args)
    holdout = _holdout(args)  # checked by diagnose and report_baselines before any fit
    diag = None
    if not add and not _written_by_fit(args.dataset):
        effects = [e.strip() for e in args.effects.split(",")] if args.effects else None
        diag = diagnose(args.dataset, effects=effects, engine=engine, holdout=holdout)
        add = [r.name for r in diag.reported][:1]
    elif args.effects:
        raise InputError(
            "--effects picks the candidates of the diagnosis that chooses 'after'; none runs "
            "here (--add is given, or the current revision was written by fit)",
            where="--effects",
            hint="leave --effects out, or --add out on a revision not written by fit",
        )
    out = args.out or args.dataset.with_name(args.dataset.name + ".physics.html")
    pair = report_baselines(args.dataset, add=add, engine=engine, holdout=holdout)
    path = report(args.dataset, out, pair=pair, diagnosis=diag)
    if args.json:
        _print_json({"html": str(path), **pair.to_dict()})
        return 0
    print(
        f"object position RMS: {pair.before.rms_mm:.2f} → {pair.after.rms_mm:.2f} mm "
        f"(before: {pair.before_label}; after: {pair.after_label})"
    )
    print(
        f"held-out position RMS: {pair.heldout_rms_before:.3f} → {pair.heldout_rms_after:.3f} mm "
        f"({pair.heldout_split}, as diagnose)"
    )
    for name, text in pair.notes.items():
        print(f"  {name}: {text}")
    print(f"wrote {path}")
    if args.rrd is not None:
        _residuals_rrd({"before": pair.before.series, "after": pair.after.series}, args.rrd)
        print(f"wrote {args.rrd}")
    return 0


_REFITTED = "base parameters, present effects and each trajectory's initial pose"


def _engine(args: argparse.Namespace) -> str:
    """The object-model engine of ``--engine`` (``auto`` resolved; the choice and the reason
    printed, on stderr with ``--json``, and the objects simulated as their mesh's convex hull
    with the hull substitutions, :mod:`robogs.format.shapes`)."""
    from robogs.format import Dataset

    name = getattr(args, "engine", "planar")
    out = sys.stderr if args.json else sys.stdout
    if name == "auto":  # the scene and the recorded motion, as the fitting engine resolves it
        from robogs.physics.engine import recording_backend
        from robogs.physics.recording import load_recording

        rec = load_recording(Dataset.open(args.dataset))
        name, why = recording_backend(rec, "auto")
        print(f"engine: {name} (auto: {why})", file=out)
        notes = rec.shapes().notes
    else:
        from robogs.format.shapes import BOX_BUDGET, load_object_meshes, object_shapes

        ds = Dataset.open(args.dataset)
        meshes = load_object_meshes(ds)
        notes = object_shapes(ds.physics(), meshes, ds.budgets[BOX_BUDGET]).notes if meshes else []
    for line in notes:  # objects simulated as their mesh's hull (robogs.format.shapes)
        print(f"  shape: {line}", file=out)
    return name


def _revision(ds_path: Path) -> int | None:
    from robogs.format import Dataset

    rev = Dataset.open(ds_path).physics().get("revision")
    return rev if isinstance(rev, int) else None


def format_span(t0: float, t1: float) -> str:
    from robogs.physics.report import format_span as fmt

    return fmt(t0, t1)


def _written_by_fit(ds_path: Path) -> bool:
    """Whether the current physics revision records the revision it was fitted from."""
    from robogs.format import Dataset

    return isinstance((Dataset.open(ds_path).physics().get("fit") or {}).get("from_revision"), int)


def _residuals_rrd(models: dict[str, list[dict[str, Any]]], path: Path) -> None:
    """Log position and orientation residuals of each model ("before", "after") per
    trajectory on a 'since_start' timeline."""
    import os

    import rerun as rr

    rec = rr.RecordingStream("robogs", recording_id="robogs-residuals", send_properties=False)
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    tmp = path.with_name(f".{path.name}.part")
    rec.save(str(tmp))
    for model, series in models.items():
        for s in series:
            _log_series(rec, rr, s, f"residuals/{model}/{s['trajectory']}")
    rec.flush()
    rec.disconnect()
    os.replace(tmp, path)


def _log_series(rec: Any, rr: Any, s: dict[str, Any], base: str) -> None:
    import numpy as np

    t = rr.TimeColumn("since_start", duration=np.asarray(s["t"], np.float64))
    err_mm = np.linalg.norm(np.asarray(s["residual_mm"]), axis=-1)
    rec.send_columns(f"{base}/position_mm", indexes=[t], columns=rr.Scalars.columns(scalars=err_mm))
    rec.send_columns(
        f"{base}/orientation_deg",
        indexes=[t],
        columns=rr.Scalars.columns(scalars=np.asarray(s["residual_deg"], np.float64)),
    )


def run(args: argparse.Namespace) -> int:
    from robogs.physics.sanity import finish_command
    from robogs.physics.split import split_option

    if not args.dataset.exists():
        raise InputError("dataset folder does not exist", path=args.dataset)
    model = _model(args.dataset, args.model)
    verb = {"compare": _compare, "diagnose": _diagnose, "fit": _fit, "report": _report}[args.verb]
    with split_option(getattr(args, "split", "auto")):  # cut + sanity: robogs.physics.split
        return finish_command(args, verb(args, model))
