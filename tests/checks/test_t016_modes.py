"""T016 reads how the robot pushes from the dataset (the ``actions`` stream's ``command_kind``)
and judges the lag of the force rises behind the object's motion onsets by it.

Position-controlled pushes (``position``/``velocity`` commands) load and move the object at
once: a wrench early or late is an error. Force-controlled pushes (``effort`` commands) build
the force up before the object breaks away: a lead is a note; a late wrench is an error under
any control. Without a command kind a lead is a note that says both readings.

Fixtures: the closed-form pushes of :mod:`tests.checks.test_lag_pairs` (a 2 ms force rise as
the object starts to move; the delay applied to the closed form) and the force-controlled
pushes of :mod:`robogs.synth.scenarios.force_push` (a force ramp to breakaway: the force leads
the motion by ~58 ms on clean stamps).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from robogs.format.checks.lag_pairs import contact_lag
from robogs.format.validate import validate

from .test_lag_pairs import _contact_dataset, _contact_series

EP = "episodes/ep000"


def _dataset(root: Path, t_w, f, t_o, p_o, command_kind: str | None) -> Path:
    """Object poses, forces and, when ``command_kind`` is given, a joint command stream."""
    return _contact_dataset(root, t_w, f, t_o, p_o, rates=(None, None), command_kind=command_kind)


def _t016(root: Path) -> list:
    return [f for f in validate(root, select=["T016"]).findings if f.code == "T016"]


def _force_push(shift_ms: float = 0.0):
    from robogs.synth.scenarios.force_push import make_force_push

    trajs = make_force_push(seed=0).trajectories
    t_o = np.concatenate([tr.t_ns for tr in trajs])
    p_o = np.concatenate([tr.object_pos for tr in trajs])
    t_w = np.concatenate([tr.wrench_t_ns for tr in trajs]) + int(shift_ms * 1e6)
    f = np.concatenate([tr.wrench_tool for tr in trajs])
    return t_w, f, t_o, p_o


@pytest.mark.parametrize(
    ("command_kind", "delay_ms", "severity"),
    [
        ("position", -20.0, "error"),  # early under position control: the stamps are off
        ("velocity", -20.0, "error"),
        ("position", 20.0, "error"),  # late: always an error
        ("effort", 20.0, "error"),
        ("effort", -20.0, "info"),  # a lead is what force control does
        (None, -20.0, "info"),  # unknown control: ambiguous, a note with its sign
        (None, 20.0, "error"),
    ],
)
def test_position_pushes_judged_by_the_recorded_mode(
    tmp_path: Path, command_kind: str | None, delay_ms: float, severity: str
) -> None:
    root = _dataset(tmp_path / "ds", *_contact_series(delay_ms), command_kind)
    (f,) = _t016(root)
    assert f.severity == severity and f.value == pytest.approx(delay_ms, abs=1.5)
    if delay_ms < 0:
        want = {"position": "stamped early", "velocity": "stamped early"}.get(
            command_kind, "force-controlled"
        )
        assert want in f.message and "ahead of" in f.message


@pytest.mark.parametrize("command_kind", ["position", "effort", None])
def test_clean_position_pushes_give_no_t016(tmp_path: Path, command_kind: str | None) -> None:
    assert _t016(_dataset(tmp_path / "ds", *_contact_series(0.0), command_kind)) == []


def test_force_controlled_lead_is_a_note_under_effort_commands(tmp_path: Path) -> None:
    (f,) = _t016(_dataset(tmp_path / "ds", *_force_push(), "effort"))
    assert f.severity == "info" and -70.0 < f.value < -45.0
    assert "expected of force-controlled pushes (actions command_kind effort)" in f.message


def test_force_controlled_data_declared_position_is_caught(tmp_path: Path) -> None:
    """Mutation: the same force-led pushes recorded as position-controlled are an error."""
    (f,) = _t016(_dataset(tmp_path / "ds", *_force_push(), "position"))
    assert f.severity == "error" and f.value < -45.0 and "stamped early" in f.message


def test_force_controlled_wrench_stamped_late_is_caught(tmp_path: Path) -> None:
    """Mutation: the force-led wrench stamped 150 ms late follows the motion by 150 ms less
    its clean lead (every force rise moves by the shift; the object's rest, taken in a window
    around the rise, moves the onsets by about 1 ms)."""
    clean = contact_lag(*_force_push())
    (f,) = _t016(_dataset(tmp_path / "ds", *_force_push(150.0), "effort"))
    assert clean is not None and clean.lag_ms < -45.0
    assert f.severity == "error" and f.value == pytest.approx(clean.lag_ms + 150.0, abs=2.0)
