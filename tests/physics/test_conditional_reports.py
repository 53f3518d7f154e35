"""A second reported effect must also pass its gate given the stronger reported one(s)
(:func:`robogs.physics.diagnose._conditional`, parametric null only).

Oracles: the rule itself on synthetic rows with a stand-in conditional diagnosis (withdrawn
where the conditional gate fails, kept where it passes, the strongest never touched, the
stronger effects handed to the base at their fitted values); and the independent scenario
generator (:mod:`robogs.synth.scenarios`): where it hides only a table tilt, a Stribeck report
beside it is false; where it hides a centre-of-mass offset and Stribeck friction together, both
reports are true and the rule must keep the second.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

import robogs.physics.diagnose as dg
from robogs.physics.diagnose import EffectRow, ParamEstimate


def _row(name: str, dbic: float, reported: bool = True) -> EffectRow:
    nan = float("nan")
    return EffectRow(
        name=name,
        family="contact",
        reported=reported,
        verdict="add" if reported else "likely",
        delta_bic=dbic,
        heldout_rms_before=nan,
        heldout_rms_after=nan,
        heldout_gain=nan,
        heldout_dchi2=nan,
        effect_size=nan,
        effect_size_total=nan,
        explained=nan,
        rms_after=nan,
        params=[ParamEstimate(name=f"{name}_p", value=-dbic, low=nan, high=nan, unit="")],
        heldout_gain_sigma2=-dbic,
        null_threshold_sigma2=20.0,
    )


def _fake(monkeypatch, passes: dict[str, bool]) -> list[tuple[str, list[dict]]]:
    """Stand-in conditional diagnosis: ``passes[name]`` says whether it passes given the rest."""
    calls: list[tuple[str, list[dict]]] = []

    def diagnose(rec, *, effects, engine, partial, holdout):
        (name,) = effects
        calls.append((name, rec.physics.get("effects", [])))
        r = _row(name, -30.0, passes[name])
        return SimpleNamespace(rows=[r])

    monkeypatch.setattr(dg, "diagnose_recording", diagnose)
    monkeypatch.setattr(dg, "Engine", lambda rec, dt, backend: None)
    return calls


def _eng():
    return SimpleNamespace(prep=SimpleNamespace(scene=SimpleNamespace(dt=1e-3)), backend="planar")


@pytest.mark.parametrize("second_passes", [False, True])
def test_second_report_is_judged_given_the_first(monkeypatch, second_passes):
    rows = [
        _row("stribeck", -900.0),
        _row("table_tilt", -3000.0),
        _row("viscous_damping", -5.0, False),
    ]
    calls = _fake(monkeypatch, {"stribeck": second_passes})
    rec = SimpleNamespace(physics={"objects": {}})
    dg._conditional(rows, rec, _eng(), partial=True, holdout=None)
    by = {r.name: r for r in rows}
    assert by["table_tilt"].reported and by["table_tilt"].conditional == {}  # never touched
    assert not by["viscous_damping"].reported and by["viscous_damping"].conditional == {}
    # one extra diagnosis, of Stribeck alone, on a base holding the tilt at its fitted value
    assert [c[0] for c in calls] == ["stribeck"]
    assert calls[0][1] == [{"name": "table_tilt", "params": {"table_tilt_p": 3000.0}}]
    assert rec.physics == {"objects": {}}  # the caller's document is not changed
    s = by["stribeck"]
    assert s.reported is second_passes
    assert s.conditional["given"] == ["table_tilt"] and s.conditional["reported"] is second_passes
    assert s.verdict == ("add" if second_passes else "conditional")


def test_a_third_report_is_judged_given_every_stronger_one_that_stayed(monkeypatch):
    rows = [_row("a", -3000.0), _row("b", -900.0), _row("c", -500.0)]
    calls = _fake(monkeypatch, {"b": False, "c": True})
    dg._conditional(rows, SimpleNamespace(physics={}), _eng(), partial=True, holdout=None)
    assert [r.reported for r in rows] == [True, False, True]
    assert [[e["name"] for e in c[1]] for c in calls] == [["a"], ["a"]]  # b withdrawn, not given


def test_an_unresolved_pair_is_not_split_by_delta_bic(monkeypatch):
    """_rivals' "unresolved" (each one's evidence is what the other gives it) is kept: the rule
    records the conditional numbers but does not withdraw the weaker member by its Delta BIC."""
    rows = [_row("quadratic_drag", -50.6), _row("viscous_damping", -48.9), _row("c", -40.0)]
    for a, b in ((rows[0], rows[1]), (rows[1], rows[0])):
        a.verdict, a.rivals = "unresolved", [b.name]
    rows[2].verdict, rows[2].rivals = "unresolved", ["x"]  # unresolved with another: judged
    _fake(monkeypatch, {"viscous_damping": False, "c": False})
    dg._conditional(rows, SimpleNamespace(physics={}), _eng(), partial=True, holdout=None)
    v = rows[1]
    assert v.reported and v.verdict == "unresolved" and v.conditional["reported"] is False
    assert "unresolved pair" in v.note
    assert not rows[2].reported and rows[2].verdict == "conditional"


@pytest.mark.slow
def test_design_a_tilt_does_not_also_report_stribeck_under_the_parametric_null(monkeypatch):
    """Design A, seed 3 (h83: Stribeck reported beside the tilt at 53x its threshold)."""
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios import make_scenario

    monkeypatch.setenv("ROBOGS_GATE_METHOD", "parametric")
    rec = make_scenario("table_tilt", seed=3, noise="nominal")
    res = dg.diagnose_recording(rec, engine=Engine(rec, backend="planar"))
    rows = {r.name: r for r in res.rows}
    assert res.reported[0].name == "table_tilt"
    assert not rows["stribeck"].reported
    assert rows["stribeck"].heldout_gain_sigma2 > rows["stribeck"].null_threshold_sigma2


@pytest.mark.slow
def test_design_a_real_second_effect_keeps_its_report_under_the_parametric_null(monkeypatch):
    """Design A hiding a centre-of-mass offset and Stribeck friction together, seed 1. h101
    (planar, 5873a46): offset Delta BIC -1510, Stribeck -1455; Stribeck's held-out fall given
    the offset 5788 sigma^2 against its threshold 15.6 (marginal 5185 / 20.6). Which one is
    second may change with the code; the test does not assume it. Two candidates only (the
    hidden ones): the rule's power is tested, not the marginal screen's."""
    from robogs.physics.engine import Engine
    from robogs.synth.scenarios import make_scenario

    monkeypatch.setenv("ROBOGS_GATE_METHOD", "parametric")
    rec = make_scenario("com_offset+stribeck", seed=1, noise="nominal")
    res = dg.diagnose_recording(
        rec, effects=["com_offset", "stribeck"], engine=Engine(rec, backend="planar")
    )
    first, second = sorted(res.rows, key=lambda r: r.delta_bic)
    assert first.reported and first.conditional == {}
    c = second.conditional
    assert c["given"] == [first.name]  # it was judged given the stronger one
    assert c["reported"] and c["heldout_gain_sigma2"] > c["null_threshold_sigma2"]
    assert second.reported and second.verdict != "conditional"
