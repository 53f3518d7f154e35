"""The re-render time budget: which frames are chosen, the note that says so, and ``--full``.

Frame counts are asserted with a fixed per-frame cost (``frame_cost_s``), so they do not depend
on the machine; the expected frames are worked out by hand from the rule (an even grid with both
ends, the frames that matter swapped in for their nearest grid points). No test here is timed.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from robogs.format.checks import CheckContext, InputReported, get_check
from robogs.format.checks.binding import PASS_SHARE, _frames, _pass, label_summary, run_notes
from robogs.format.rerender import (
    DEFAULT_BUDGET_S,
    FIT_FRAME_RENDERS,
    MIN_FIT_FRAMES,
    MIN_PASS_FRAMES,
    RerenderOptions,
    compare_frame,
    fit_frame_count,
    plan_frames,
    read_label_frames,
    spread_frames,
)
from robogs.format.validate import Progress


@pytest.fixture(scope="module")
def synth_scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from robogs.synth.scene import synthesize

    root = tmp_path_factory.mktemp("budget") / "small"
    synthesize(root, seed=0, size="small", progress=False)
    return root


# ------------------------------------------------------------------------------ planning


def test_budget_over_cost_sets_the_count_and_the_must_frames_replace_their_nearest() -> None:
    # 1.6 s at 0.2 s per frame: 8 of 120; grid round(0, 17, 34, ..., 119)
    plan = plan_frames(120, 0.2, 1.6, min_frames=6, must=[37, 80])
    assert plan.count == 8 and plan.total == 120 and plan.subsampled and not plan.floor
    # 37 replaces 34 (3 away), 80 replaces 85 (5 away; 68 is 12 away); both ends stay
    assert plan.chosen.tolist() == [0, 17, 37, 51, 68, 80, 102, 119]
    assert plan.expected_s == pytest.approx(1.6)


def test_a_must_frame_on_the_grid_or_at_an_end_changes_nothing() -> None:
    assert spread_frames(120, 8, must=[0, 51, 119]).tolist() == [0, 17, 34, 51, 68, 85, 102, 119]
    # grid 0, 5, 10: 4 takes 5; no free grid point is left for 6 (the count stays 3)
    assert spread_frames(11, 3, must=[4, 6]).tolist() == [0, 4, 10]


def test_two_must_frames_near_one_grid_point() -> None:
    # grid of 4 over 31: 0, 10, 20, 30; 9 takes 10, 11 takes the next nearest free point (20)
    assert spread_frames(31, 4, must=[9, 11]).tolist() == [0, 9, 11, 30]


def test_the_minimum_count_overrides_a_tiny_budget_and_says_so() -> None:
    plan = plan_frames(120, 1.0, 2.0, min_frames=6)
    assert plan.count == 6 and plan.floor
    assert plan.chosen.tolist() == [0, 24, 48, 71, 95, 119]  # floor(k * 119 / 5 + 0.5)


def test_no_budget_or_few_frames_take_every_frame() -> None:
    assert plan_frames(120, 0.2, math.inf).chosen.tolist() == list(range(120))
    assert plan_frames(5, 10.0, 0.1, min_frames=6).chosen.tolist() == [0, 1, 2, 3, 4]
    assert plan_frames(0, 0.2, 1.0).count == 0


def test_frames_are_chosen_deterministically() -> None:
    a = plan_frames(1800, 0.07, 1.6, must=[733, 12]).chosen
    b = plan_frames(1800, 0.07, 1.6, must=[733, 12]).chosen
    assert np.array_equal(a, b) and len(a) == 22 and {733, 12} <= set(a.tolist())
    assert np.all(np.diff(a) > 0)


def test_fit_frame_count_follows_the_render_cost() -> None:
    budget = DEFAULT_BUDGET_S * (1 - PASS_SHARE)  # 2.4 s
    assert FIT_FRAME_RENDERS == 8.0
    assert fit_frame_count(0.05, budget, 8) == 6  # 2.4 / (8 x 0.05)
    assert fit_frame_count(0.001, budget, 8) == 8  # capped by fit_frames
    assert fit_frame_count(0.2, budget, 8) == MIN_FIT_FRAMES  # 1.5 -> the minimum, 2
    assert fit_frame_count(0.2, budget, 1) == 1
    assert fit_frame_count(0.2, math.inf, 8) == 8


def test_bad_budget_options_are_input_errors() -> None:
    from robogs.format.errors import InputError

    for bad in ({"budget_s": 0.0}, {"budget_s": -1.0}, {"frame_cost_s": 0.0}):
        with pytest.raises(InputError):
            RerenderOptions(**bad)


# ------------------------------------------------------------------------------ on a scene


def _run(root: Path, codes: list[str], **options: object) -> tuple[list, CheckContext]:
    ctx = CheckContext(root, options=dict(options))
    out = []
    for code in codes:
        try:
            out.extend(get_check(code).run(ctx))
        except InputReported:
            pass
    return out, ctx


def _job(ctx: CheckContext):
    from robogs.format.checks.binding import _camera_jobs

    (job,) = list(_camera_jobs(ctx))
    return job


def test_fake_cost_chooses_8_of_120_frames_and_2_fit_frames_and_says_so(
    synth_scene: Path,
) -> None:
    """Default budget 4 s, one camera: the pass gets 1.6 s (8 frames at 0.2 s), the fit 2.4 s
    (1.5 frames at 8 renders of 0.2 s: the minimum, 2, which costs more than its share). The
    clean scene stays clean in the budgeted mode."""
    findings, ctx = _run(synth_scene, ["B002", "B003", "B004"], frame_cost_s=0.2)
    assert [f for f in findings if f.severity != "info"] == [], findings
    job = _job(ctx)
    ps = _pass(ctx, job)
    assert ps.plan is not None and (ps.plan.count, ps.plan.total) == (8, 120)
    assert len(ps.frame_index) == 8 and ps.frame_index[0] == 0 and ps.frame_index[-1] == 119
    (note,) = run_notes(ctx)
    assert note.startswith("binding re-render ep000/camera/cam0: labels compared on 8 of 120")
    assert note.endswith("to stay within the 4 s re-render budget; --full for all")

    findings, ctx = _run(synth_scene, ["B005", "B006"], frame_cost_s=0.2)
    assert findings == [], findings
    (note,) = run_notes(ctx)
    assert "the time offset and camera fitted on 2 of 8 fast-moving frames" in note
    assert note.endswith("the minimum counts, over the 4 s re-render budget; --full for all")


def test_full_compares_every_candidate_frame_like_before(synth_scene: Path) -> None:
    """``full``: the pass covers every ``stride``-th frame, and its pooled IoU equals a brute-force
    loop that renders and compares each of those frames; no note is left."""
    _f, ctx = _run(synth_scene, ["B002"], full=True, stride=24)
    job = _job(ctx)
    ps = _pass(ctx, job)
    t, fi = _frames(ctx, job)
    assert ps.frame_index.tolist() == fi.tolist() == list(range(0, 120, 24))
    assert run_notes(ctx) == []
    rr, lut = ps.rr, ps.lut
    C = rr.channels.count
    inter, union = np.zeros(C), np.zeros(C)
    labels = dict(read_label_frames(ctx.existing(job.entry["labels"]), fi))
    for k, i in enumerate(fi):
        out = rr.render(int(t[k]))
        m = compare_frame(
            rr.probabilities(out), out.depth_median.detach().cpu().numpy(), lut[labels[int(i)]], C
        )
        inter += m.inter
        union += m.union
    summary = {s.name: s for s in label_summary(ctx, job.ep.id, job.stream)}
    for c, name in enumerate(rr.channels.names):
        if union[c]:
            assert summary[name].iou == pytest.approx(inter[c] / union[c], rel=1e-12)
    assert MIN_PASS_FRAMES == 6


# ------------------------------------------------------------------------------ progress


def test_progress_is_weighted_by_expected_seconds() -> None:
    calls: list[tuple[str, float, float]] = []
    bar = Progress(lambda title, done, total: calls.append((title, done, total)), [1.0, 8.0, 1.0])
    bar.start(0, "A001 a")
    bar.start(1, "B002 long")
    bar.fraction(0.5)
    bar("re-rendering ep/cam")
    bar.start(3, "done")
    assert [c[1] for c in calls] == [0.0, 1.0, 5.0, 1.0, 10.0]
    assert all(c[2] == 10.0 for c in calls)
    assert calls[3][0] == "B002 re-rendering ep/cam"
    bar.close()
