"""Hidden-effect suite: does diagnose find the effect hidden in generated data?

For every effect of the scenario catalogue (plus ``none``) and each noise level, ``--seeds``
scenarios (9 pushes: 3 speeds x 3 directions; drops are added for restitution) are generated
by the independent simulator in ``fixtures.scenarios`` and diagnosed with the full catalogue.
Cases the generator finds undetectable by design are excluded and listed.

Prints the pass table (right family first, exact effect first, true effect in the top 3,
false positives on null, median parameter error, time-offset error, RMS after the fix over the
noise floor) and appends it to bench/RESULTS.md; also times diagnose with the full catalogue on
one 9-push scenario.

    .venv/bin/python bench/diagnose.py --seeds 20 --jobs 2
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def _kinds(effect: str) -> tuple[str, ...]:
    return ("push", "grasp_place") if effect == "restitution" else ("push",)


def _one(args: tuple[str, str, int]) -> dict:
    import torch

    torch.set_num_threads(1)
    from fixtures.scenarios import FAMILY, make_scenario
    from reference_impl.physics.diagnose import diagnose_recording

    effect, noise, seed = args
    try:
        rec = make_scenario(effect, seed=seed, noise=noise, kinds=_kinds(effect))
    except ValueError as exc:
        return {"effect": effect, "noise": noise, "seed": seed, "excluded": str(exc)}
    t0 = time.perf_counter()
    res = diagnose_recording(rec)
    wall = time.perf_counter() - t0
    rows = res.rows
    reported = [r for r in rows if r.reported]
    top = reported[0] if reported else None
    names = [r.name for r in rows]
    out = {
        "effect": effect,
        "noise": noise,
        "seed": seed,
        "wall_s": wall,
        "reported": [r.name for r in reported],
        "top": top.name if top else None,
        "top_family": top.family if top else None,
        "rank_true": names.index(effect) + 1 if effect in names else None,
        "true_reported": any(r.name == effect for r in reported),
        "noise_floor": res.noise_floor,
        "rms_base": res.rms_base,
        "family": FAMILY[effect],
    }
    true_row = next((r for r in rows if r.name == effect), None)
    if true_row is not None:
        truth = rec.meta["true_params"]
        errs = [
            abs(p.value - truth[p.name]) / abs(truth[p.name])
            for p in true_row.params
            if truth.get(p.name)
        ]
        out["param_rel_err"] = float(np.median(errs)) if errs else None
        out["rms_after_true"] = true_row.rms_after
        if effect == "time_offset":
            out["offset_err_ms"] = abs(true_row.params[0].value - truth["delta"]) * 1000
    if top is not None:
        out["rms_after_top"] = top.rms_after
    out["rows"] = [
        {
            "name": r.name,
            "family": r.family,
            "dbic": r.delta_bic,
            "gain": r.heldout_gain,
            "size": r.effect_size,
            "ident": r.verdict != "unidentifiable",
            "reported": r.reported,
        }
        for r in rows
    ]
    best_null = rows[0] if rows else None
    if best_null is not None:
        out["best_dbic"] = best_null.delta_bic
        out["best_gain"] = best_null.heldout_gain
        out["best_size"] = best_null.effect_size
    return out


def _table(results: list[dict], noise: str) -> tuple[list[str], dict]:
    lines = [
        f"| effect ({noise}) | cases | excluded | family first | exact first | true in top 3 | "
        "median param err | offset err ms | RMS after / floor | mean wall s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    summary = {}
    effects = sorted({r["effect"] for r in results if r["noise"] == noise})
    for eff in effects:
        rs = [r for r in results if r["noise"] == noise and r["effect"] == eff]
        ok = [r for r in rs if "excluded" not in r]
        exc = len(rs) - len(ok)
        if not ok:
            lines.append(f"| {eff} | 0 | {exc} | - | - | - | - | - | - | - |")
            continue
        if eff == "none":
            fp = np.mean([bool(r["reported"]) for r in ok])
            ratio = np.median([r["rms_base"] / r["noise_floor"] for r in ok])
            lines.append(
                f"| none (false positives) | {len(ok)} | {exc} | FP {100 * fp:.0f} % | - | - | - | - | "
                f"{ratio:.2f} (base) | {np.mean([r['wall_s'] for r in ok]):.1f} |"
            )
            summary[eff] = {"fp": fp}
            continue
        fam = np.mean([r["top_family"] == r["family"] for r in ok])
        exact = np.mean([r["top"] == eff for r in ok])
        top3 = np.mean(
            [r["rank_true"] is not None and r["rank_true"] <= 3 and r["true_reported"] for r in ok]
        )
        perr = [r["param_rel_err"] for r in ok if r.get("param_rel_err") is not None]
        off = [r["offset_err_ms"] for r in ok if r.get("offset_err_ms") is not None]
        ratio = [r["rms_after_top"] / r["noise_floor"] for r in ok if r.get("rms_after_top")]
        lines.append(
            f"| {eff} | {len(ok)} | {exc} | {100 * fam:.0f} % | {100 * exact:.0f} % | {100 * top3:.0f} % | "
            f"{100 * np.median(perr):.1f} % | {np.median(off) if off else float('nan'):.2f} | "
            f"{np.median(ratio) if ratio else float('nan'):.3f} | {np.mean([r['wall_s'] for r in ok]):.1f} |"
        )
        summary[eff] = {"family": fam, "exact": exact, "top3": top3}
    return lines, summary


def _timing() -> str:
    import torch

    torch.set_num_threads(1)
    from fixtures.scenarios import make_scenario
    from reference_impl.physics.diagnose import diagnose_recording

    rec = make_scenario("viscous_damping", seed=0, kinds=("push",))
    t0 = time.perf_counter()
    res = diagnose_recording(rec)
    wall = time.perf_counter() - t0
    return (
        f"diagnose, full catalogue ({len(res.rows)} candidates), 9-push scenario: {wall:.1f} s "
        f"(target 60 s; ratio {wall / 60:.2f}); torch threads 1"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--noise", nargs="+", default=["nominal", "hard"])
    ap.add_argument("--effects", nargs="+", default=None)
    ap.add_argument("--out", default=str(ROOT / "bench" / "diagnose_results.jsonl"))
    ap.add_argument("--no-write", action="store_true")
    ap.add_argument("--report-only", action="store_true", help="tabulate --out without running")
    a = ap.parse_args()
    from fixtures.scenarios import TRUE_PARAMS

    effects = a.effects or sorted(TRUE_PARAMS)
    jobs = [(e, n, s) for s in range(a.seeds) for n in a.noise for e in effects]  # seed-major
    out = Path(a.out)
    done = []
    if out.exists():
        done = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    have = {(r["effect"], r["noise"], r["seed"]) for r in done}
    todo = [] if a.report_only else [j for j in jobs if j not in have]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=a.jobs) as ex, out.open("a") as fh:
        for i, r in enumerate(ex.map(_one, todo)):
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            done.append(r)
            print(
                f"[{i + 1}/{len(todo)}] {r['effect']} {r['noise']} seed {r['seed']}: top={r.get('top')}",
                flush=True,
            )
    results = [r for r in done if (r["effect"], r["noise"], r["seed"]) in set(jobs)]
    n_done = len(results)
    text = [
        f"### diagnose hidden-effect suite ({a.seeds} seeds per effect and noise level; "
        f"{n_done} of {len(jobs)} cases finished)",
        "",
        f"Command: `.venv/bin/python bench/diagnose.py --seeds {a.seeds} --jobs {a.jobs}`  ",
        f"Machine: {platform.processor() or platform.machine()}, {__import__('os').cpu_count()} CPUs; "
        f"torch threads 1 per worker, {a.jobs} workers; suite wall time {time.perf_counter() - t0:.0f} s",
        "",
    ]
    for n in a.noise:
        lines, _ = _table(results, n)
        text += lines + [""]
    if not a.report_only:
        text.append(_timing())
    print("\n".join(text))
    if not a.no_write:
        res_md = ROOT / "bench" / "RESULTS.md"
        head = "" if res_md.exists() else "# Bench results\n\n"
        with res_md.open("a") as fh:
            fh.write(head + "## 2026-11-22\n\n" + "\n".join(text) + "\n\n")


if __name__ == "__main__":
    main()
