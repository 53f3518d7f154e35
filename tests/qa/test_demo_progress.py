"""``robogs demo`` progress: every step says its name, the time elapsed and the time left.

Oracle: a fake clock; the estimate is the typical time of the steps left, scaled by how much
slower or faster the finished steps ran (closed form).
"""

from __future__ import annotations

import pytest

from robogs.cli.demo_cmd import TYPICAL_S, Steps, add_arguments


def test_eta_scales_the_typical_times_by_the_speed_so_far() -> None:
    now = [100.0]
    lines: list[str] = []
    steps = Steps(["a", "b", "c"], {"a": 1.0, "b": 2.0, "c": 3.0}, lines.append, lambda: now[0])
    assert steps.eta() == pytest.approx(6.0)  # nothing done yet: the typical times
    steps.start("a")
    now[0] += 2.0  # twice as slow as typical
    steps.end("done a")
    assert steps.eta() == pytest.approx((2.0 + 3.0) * 2.0)
    steps.start("b", "with detail")
    now[0] += 1.0  # 3 s for 3 typical s: speed 1
    steps.end()
    assert steps.eta() == pytest.approx(3.0)
    assert lines == [
        "[1/3] a (elapsed 0 s, about 6 s left)",
        "      done a; a: 2.0 s",
        "[2/3] b with detail (elapsed 2 s, about 10 s left)",
        "      b: 1.0 s",
    ]


def test_unknown_step_times_give_no_eta() -> None:
    lines: list[str] = []
    steps = Steps(["a", "new"], {"a": 1.0}, lines.append, lambda: 0.0)
    steps.start("a")
    assert steps.eta() is None and lines == ["[1/2] a (elapsed 0 s)"]
    with pytest.raises(RuntimeError):
        Steps(["a"], {}, lines.append).end()


def test_the_demo_steps_all_have_typical_times() -> None:
    import argparse

    p = argparse.ArgumentParser()
    add_arguments(p)
    assert p.parse_args([]).effect == "table_tilt"
    assert len(TYPICAL_S) == 8 and all(v > 0 for v in TYPICAL_S.values())
