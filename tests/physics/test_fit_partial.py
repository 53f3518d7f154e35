"""``fit --add`` and ``report`` on a partly identified effect, as diagnose judges it (issue 17).

Oracles: the construction of ``test_partial_ident.py``'s toy, as a rigid-model effect. A hidden
table tilt along ``u`` (the scenario generator's own renderer) is fitted by a toy effect whose
acceleration is ``(SCALE (p + q) + EPS (p - q)) u``: the data determine only the sum (the
difference moves the predictions EPS / SCALE as much), so diagnose reports it "add (partly
identified)" and ``fit --add`` must write it, at the joint fit diagnose scored (held-out chi^2
equal to diagnose's row within 1e-6 relative), with ``p`` and ``q`` flagged undetermined; the
written sum must be the true tilt ``|g|`` within its determined interval. The mutated toy
(SCALE 1e-3: the tilt would need p + q far beyond the bounds, nothing determined) must not be
written: exit 2, one line, the revision unchanged. ``report`` of the written revision prints
the same before and after as diagnose to the printed digit.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
import torch
from physics_scenarios import scenario

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.physics import api, baseline
from robogs.physics.diagnose import PARTLY, auto_loop
from robogs.physics.effects import Effect, Param, register_effect, unregister_effect
from robogs.physics.model import FreeState
from robogs.synth.scenarios import TRUE_PARAMS, write_scenario

G = np.array([TRUE_PARAMS["table_tilt"]["g_x"], TRUE_PARAMS["table_tilt"]["g_y"]])
U = G / np.linalg.norm(G)
EPS = 2e-3
SEP = "a design where the speed varies apart from the tilt"


@dataclass(frozen=True)
class SplitTilt(Effect):
    """A tilt along ``U`` of magnitude ``SCALE (p + q) + EPS (p - q)`` [m/s^2]."""

    name: str = "split_tilt"
    params: tuple[Param, ...] = (
        Param("p", "m/s^2", -1.0, 1.0, 0.0, 0.2),
        Param("q", "m/s^2", -1.0, 1.0, 0.0, 0.2),
    )
    needs: tuple[str, ...] = ("object_poses", "sliding")
    separate_by: str = SEP
    scale: float = 1.0

    def accel(self, th, state: FreeState):
        s = self.scale * (th["p"] + th["q"]) + EPS * (th["p"] - th["q"])
        z = torch.zeros_like(state.w)
        a = torch.stack([(s * U[0]).expand_as(z), (s * U[1]).expand_as(z), z], dim=-1)
        return a, None


@pytest.fixture
def toy(request, tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """The toy registered with ``scale`` (the test's param), a tilt dataset, own caches."""
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    baseline._CACHE.clear()
    register_effect(SplitTilt(scale=request.param), replace=True)
    ds = tmp_path / "ds"
    write_scenario(scenario("table_tilt", seed=0), ds)
    yield ds
    unregister_effect("split_tilt")
    baseline._CACHE.clear()


def _cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main(list(argv))
    out = capsys.readouterr()
    return rc, out.out, out.err


@pytest.mark.parametrize("toy", [1.0], indirect=True)
def test_fit_add_writes_a_partly_identified_effect_as_diagnose_scored_it(toy, capsys):
    ds = str(toy)
    diag = api.diagnose(ds, effects=["split_tilt"], mask_frames=0)
    (row,) = diag.rows
    assert (row.verdict, row.reported, row.undetermined) == (PARTLY, True, ["p", "q"])

    rc, text, _ = _cli(capsys, "fit", ds, "--add", "split_tilt", "--mask-frames", "0")
    assert rc == 0
    flag = f"not determined by this data (interval unbounded); to determine it: {SEP}"
    assert f"split_tilt.p, split_tilt.q {flag}" in text
    doc = Dataset.open(ds).physics()
    assert doc["revision"] == 2 and f"split_tilt.p, split_tilt.q {flag}" in doc["note"]
    (eff,) = [e for e in doc["effects"] if e["name"] == "split_tilt"]
    # the held-out error printed is diagnose's, to the digit
    m = re.search(r"held-out position RMS: (\d+\.\d+) → (\d+\.\d+) mm", text)
    assert m and m.groups() == (f"{row.heldout_rms_before:.3f}", f"{row.heldout_rms_after:.3f}")

    # the written parameters are the joint fit whose held-out chi^2 is diagnose's row: the
    # same fit of revision 1 (now in the history), in memory
    rev1 = json.loads(Path(ds, "physics/history/rev-0001.json").read_text())
    res = api.fit(replace(api._open(ds)[0], physics=rev1), add=["split_tilt"], write=False)
    assert res.undetermined == {"split_tilt": ["p", "q"]}
    assert res.physics["effects"][-1]["params"] == eff["params"]
    assert res.physics["objects"]["box"] == doc["objects"]["box"]
    dchi2 = res.heldout_chi2_before - res.heldout_chi2_after
    assert dchi2 == pytest.approx(row.heldout_dchi2, rel=1e-6)
    assert res.heldout_rms_after == pytest.approx(row.heldout_rms_after, rel=1e-6)
    assert res.heldout_rms_before == pytest.approx(row.heldout_rms_before, rel=1e-6)
    # the undetermined intervals are unbounded, the determined sum is the hidden tilt:
    # s = p + q + (EPS)(p - q) along u equals |g| within 3 % (the fit's own interval is ~20 %)
    prm = {p.name: p for p in res.params}
    assert np.isinf(prm["split_tilt.p"].low) and np.isinf(prm["split_tilt.q"].high)
    p, q = eff["params"]["p"], eff["params"]["q"]
    assert p + q + EPS * (p - q) == pytest.approx(np.linalg.norm(G), rel=0.05)

    # report of the written revision: the same before and after as diagnose, to the digit
    html = Path(ds).with_name("r.html")
    rc, text, _ = _cli(capsys, "report", ds, "--out", str(html), "--json")
    rep = json.loads(text)
    assert f"{rep['rms_before_mm']:.2f}" == f"{diag.rms_base:.2f}"
    assert f"{rep['rms_after_mm']:.2f}" == f"{row.rms_after:.2f}"
    assert f"{rep['heldout_rms_before_mm']:.2f}" == f"{row.heldout_rms_before:.2f}"
    assert f"{rep['heldout_rms_after_mm']:.2f}" == f"{row.heldout_rms_after:.2f}"
    assert flag in rep["notes"]["split_tilt"]
    page = html.read_text()
    assert "Not fully determined by this data" in page and "unbounded" in page
    assert f"{row.rms_after:.2f} mm</p>" in page or f"&rarr; {row.rms_after:.2f} mm" in page


@pytest.mark.parametrize("toy", [1.0], indirect=True)
def test_auto_loop_accepts_it_with_diagnose_numbers(toy):
    """The loop's step is diagnose's row, and matches what ``fit --add`` prints."""
    rec = api._open(str(toy))[0]
    path = auto_loop(rec, effects=["split_tilt"], max_steps=2)
    step = path.steps[0]
    assert path.accepted == ["split_tilt"]
    assert step.verdict.startswith("added (partly identified: p, q not determined)")
    res = api.fit(rec, add=["split_tilt"], write=False)
    assert res.heldout_rms_after == pytest.approx(step.heldout_rms_after, rel=1e-6)
    assert res.heldout_rms_before == pytest.approx(step.heldout_rms_before, rel=1e-6)
    assert path.steps[-1].verdict.startswith("stop")


@pytest.mark.parametrize("toy", [1e-3], indirect=True)
def test_fully_unidentifiable_effect_is_not_written(toy, capsys):
    ds = str(toy)
    (row,) = api.diagnose(ds, effects=["split_tilt"], mask_frames=0).rows
    assert row.verdict == "unidentifiable" and not row.reported
    for extra in ((), ("--dry-run",)):
        rc, out, err = _cli(capsys, "fit", ds, "--add", "split_tilt", "--mask-frames", "0", *extra)
        assert rc == 2 and out == ""
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "split_tilt is not written: unidentifiable" in lines[0]
        assert "Traceback" not in err and f"to identify it: {SEP}" in lines[0]
    doc = Dataset.open(ds).physics()
    assert doc["revision"] == 1 and all(e["name"] != "split_tilt" for e in doc["effects"])
    # in memory: the effect is left out with the reason
    res = api.fit(api._open(ds)[0], add=["split_tilt"], write=False)
    assert "split_tilt" in res.not_written and res.physics["effects"] == []
