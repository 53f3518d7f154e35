"""``robogs demo [OUT]``: the main job on the bundled default scene, in about a minute.

1. synthesise the default scene (UR5 pushing a box, one camera) into ``OUT/scene``;
2. validate it (the validator's default: re-rendering checks subsampled to their time budget)
   and save ``OUT/validation.json``;
3. write ``OUT/report.html`` with the findings and plots;
4. write a scenario with a hidden effect (``OUT/hidden``: six pushes when they reveal the
   effect, the full design otherwise), then run the physics loop on it:
5. compare, 6. diagnose, 7. fit the effect it finds, 8. write ``OUT/physics_report.html``.

Every step prints its name, the time it took, the time elapsed and an estimate of the time
left. The estimate scales the typical step times (:data:`TYPICAL_S`) by how fast the steps so
far ran. The physics steps share one baseline (:mod:`robogs.physics.baseline`). The before
and after that the terminal prints are the ones ``OUT/physics_report.html`` and
``OUT/physics.json`` hold, to the printed digit.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["add_arguments", "run", "Steps", "TYPICAL_S"]

#: seconds per step with the default arguments: one run on the 2-core development machine
#: (load average 5 from other jobs; 68 s in all). Only their ratios matter: the ETA rescales
#: them by how fast the finished steps ran.
TYPICAL_S: dict[str, float] = {
    "synthesise the default scene": 0.9,
    "validate it": 7.6,
    "write the dataset report": 1.1,
    "write the hidden-effect scenario": 4.9,
    "compare": 8.5,
    "diagnose": 24.9,
    "fit": 17.6,
    "write the physics report": 0.1,
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "out", nargs="?", default="out/demo", type=Path, help="output folder (default out/demo)"
    )
    p.add_argument("--seed", type=int, default=0, help="random seed of the scenes")
    p.add_argument(
        "--effect",
        default="table_tilt",
        help="hidden effect of the physics scenario (default table_tilt; 'none' for null data)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


class Steps:
    """Numbered steps with their time, the time elapsed and the estimated time left.

    Args:
        names: the step names, in order (their typical seconds come from ``typical``).
        typical: typical seconds per step name (unknown names: no ETA).
        say: where lines go (stderr).
        clock: seconds (``time.perf_counter``).
    """

    def __init__(
        self,
        names: list[str],
        typical: dict[str, float] | None = None,
        say: Callable[[str], None] = _say,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.names = list(names)
        self.typical = dict(TYPICAL_S if typical is None else typical)
        self.say, self.clock = say, clock
        self.t0 = clock()
        self.done: list[tuple[str, float]] = []
        self._current: tuple[str, float] | None = None

    def elapsed(self) -> float:
        return self.clock() - self.t0

    def eta(self) -> float | None:
        """Seconds left: typical times of the steps left, scaled by the speed so far."""
        left = self.names[len(self.done) :]
        if any(n not in self.typical for n in left):
            return None
        typical_done = sum(self.typical.get(n, 0.0) for n, _ in self.done)
        actual_done = sum(s for _, s in self.done)
        speed = actual_done / typical_done if typical_done > 0 and actual_done > 0 else 1.0
        return sum(self.typical[n] for n in left) * speed

    def start(self, name: str, detail: str = "") -> None:
        """Announce step ``name`` (one of ``names``)."""
        k = self.names.index(name) + 1
        eta = self.eta()
        when = f"elapsed {self.elapsed():.0f} s" + (
            f", about {eta:.0f} s left" if eta is not None else ""
        )
        self.say(f"[{k}/{len(self.names)}] {name}{' ' + detail if detail else ''} ({when})")
        self._current = (name, self.clock())

    def end(self, summary: str = "") -> None:
        """Close the current step, with a one-line summary."""
        if self._current is None:
            raise RuntimeError("no step started")
        name, t = self._current
        took = self.clock() - t
        self.done.append((name, took))
        self._current = None
        self.say(f"      {summary + '; ' if summary else ''}{name}: {took:.1f} s")


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from robogs.format.dataset import Dataset
    from robogs.format.qa.dataset_report import write_dataset_report
    from robogs.format.report_formats import render_text
    from robogs.format.validate import validate
    from robogs.synth.scene import synthesize

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    progress = not args.no_progress
    steps = Steps(list(TYPICAL_S))
    scene = out / "scene"
    steps.start("synthesise the default scene", f"into {scene}")
    synthesize(scene, seed=args.seed, size="small", overwrite=True, progress=progress)
    steps.end()
    steps.start("validate it")
    report = validate(scene, progress=progress)
    render_text(report, Console())
    (out / "validation.json").write_text(json.dumps(report.to_dict(), indent=2) + "\n")
    steps.end(", ".join(f"{v} {k}" for k, v in report.counts().items()))
    steps.start("write the dataset report")
    html = write_dataset_report(
        Dataset.open(scene), report.to_dict()["findings"], out / "report.html"
    )
    steps.end(str(html))
    status = 1 if report.failed("error") else 0
    status = max(status, physics_demo(out, args.seed, args.effect, progress, steps))
    _say(
        f"done in {steps.elapsed():.0f} s: open {out / 'report.html'}"
        + (f" and {out / 'physics_report.html'}" if (out / "physics_report.html").exists() else "")
    )
    return status


def _scenario(effect: str, seed: int) -> tuple[Any, str]:
    """Eight pushes when they reveal ``effect`` by design, else the full design.

    Eight, not fewer: the gate's trajectory-level null (a wild cluster bootstrap, see
    :mod:`robogs.physics.gate`) has 2^7 = 128 sign patterns at eight trajectories; with six,
    Webb's weights keep its size but a large hidden tilt (46 % of the held-out error) stays under
    its threshold (786 vs 830 sigma^2), so the demo would show nothing.
    """
    from robogs.synth.scenarios import make_scenario

    try:
        small = dict(kinds=("push",), n_speeds=2, n_dirs=4)
        return make_scenario(effect, seed=seed, noise="nominal", **small), "8 pushes"
    except ValueError:  # not detectable with pushes alone
        return make_scenario(effect, seed=seed, noise="nominal"), "the full design"


def physics_demo(
    out: Path, seed: int, effect: str, progress: bool, steps: Steps | None = None
) -> int:
    """Steps 4-8: the physics loop on a scenario with a hidden effect, in ``out/hidden``.

    Writes ``out/physics_report.html`` and ``out/physics.json`` (compare, diagnose, fit and
    report, each with its before and after in mm).
    """
    from robogs.format.dataset import Dataset
    from robogs.physics.api import compare, diagnose, fit, report, report_baselines
    from robogs.synth.scenarios import write_scenario

    steps = steps or Steps([n for n in TYPICAL_S if n in _PHYSICS_STEPS])
    scenario = out / "hidden"
    out.mkdir(parents=True, exist_ok=True)
    steps.start("write the hidden-effect scenario", f"({effect}) into {scenario}")
    rec, design = _scenario(effect, seed)
    write_scenario(rec, scenario, overwrite=True)
    steps.end(f"{len(rec.trajectories)} trajectories ({design})")

    steps.start("compare")
    before = compare(scenario, progress=_fit_progress(progress))
    rev = Dataset.open(scenario).physics().get("revision")
    steps.end(
        f"object position RMS {before.rms_mm:.2f} mm (physics revision {rev}, refitted; noise "
        f"floor {before.noise_floor_mm:.2f} mm, estimated from the data)"
    )

    steps.start("diagnose")
    result = diagnose(scenario, progress=_fit_progress(progress))
    found = [r.name for r in result.reported]
    steps.end(
        (f"missing effect {found[0]!r}" if found else "no missing effect above the noise")
        + f" (base model {result.rms_base:.2f} mm)"
    )
    summary: dict[str, Any] = {
        "hidden_effect": effect,
        "design": design,
        "compare": {"rms_mm": before.rms_mm, "noise_floor_mm": before.noise_floor_mm},
        "diagnose": result.to_dict(),
        "reported": found,
    }

    steps.start("fit", f"--add {found[0]}" if found else "(no effect: refit the base model)")
    res = fit(
        scenario,
        found[:1],
        note=f"demo: add {found[0]}" if found else "demo: refit the base",
        progress=_fit_progress(progress),
    )
    steps.end(
        f"RMS {res.rms_before:.2f} -> {res.rms_after:.2f} mm (noise floor "
        f"{res.noise_floor:.2f} mm), physics revision {res.from_revision} -> {res.revision}"
    )
    summary["fit"] = res.to_dict()

    steps.start("write the physics report")
    pair = report_baselines(scenario)
    html = report(scenario, out / "physics_report.html", pair=pair)
    steps.end(
        f"RMS {pair.before.rms_mm:.2f} -> {pair.after.rms_mm:.2f} mm "
        f"(before: {pair.before_label}; after: {pair.after_label}): {html}"
    )
    summary["report"] = {"html": str(html), **pair.to_dict()}
    (out / "physics.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")
    return 0


_PHYSICS_STEPS = (
    "write the hidden-effect scenario",
    "compare",
    "diagnose",
    "fit",
    "write the physics report",
)


def _fit_progress(show: bool) -> Callable[[int, int], None] | None:
    """A one-line progress of a batched fit: LM iteration (at most 20) and fits running
    (a fit with an effect runs three in turn: before, the fit, after)."""
    if not show:
        return None

    def cb(iteration: int, running: int) -> None:
        end = "\n" if running == 0 else ""
        print(
            f"\r      fitting: iteration {iteration}/<=20, {running} fits still running ",
            end=end,
            file=sys.stderr,
            flush=True,
        )

    return cb
