"""``robogs diagnose --gate-null``: the object model's gate null chosen on the command line.

Oracle: what :func:`robogs.physics.diagnose.gate_method` returns while the diagnosis runs
(the stubbed diagnosis reads it the way the calibration does); the default is the parametric
null, the flag overrides an environment that says otherwise, and a bad choice is refused by
the parser before any work."""

from __future__ import annotations

import pytest

from robogs.cli.main import main
from robogs.physics import api
from robogs.physics.diagnose import GATE_METHOD_ENV, gate_method
from robogs.synth.scenarios import make_scenario, write_scenario


@pytest.fixture()
def dataset(tmp_path, monkeypatch):
    monkeypatch.setenv("ROBOGS_CACHE_DIR", str(tmp_path / "cache"))
    rec = make_scenario("none", seed=0, kinds=("push",), n_speeds=1, n_dirs=2, check=False)
    ds = tmp_path / "ds"
    write_scenario(rec, str(ds))
    return ds


def _seen(monkeypatch, args) -> list[str]:
    seen: list[str] = []
    doc = {"effects": [], "skipped": [], "rms_base_mm": 1.0, "noise_floor_mm": 1.0, "gate": {}}

    class Stub:
        def to_dict(self):
            return doc

    def fake(*a, **k):
        seen.append(gate_method())
        return Stub()

    monkeypatch.setattr(api, "diagnose", fake)
    main(args)
    return seen


def test_default_is_parametric_and_the_flag_overrides_the_environment(dataset, monkeypatch):
    base = ["diagnose", str(dataset), "--no-progress", "--model", "object"]
    monkeypatch.delenv(GATE_METHOD_ENV, raising=False)
    assert _seen(monkeypatch, base) == ["parametric"]
    monkeypatch.setenv(GATE_METHOD_ENV, "parametric")
    assert _seen(monkeypatch, base + ["--gate-null", "both"]) == ["both"]
    monkeypatch.setenv(GATE_METHOD_ENV, "both")
    assert _seen(monkeypatch, base + ["--gate-null", "parametric"]) == ["parametric"]
    assert _seen(monkeypatch, base) == ["both"]  # no flag: the environment stands


def test_unknown_null_is_refused_by_the_parser(dataset, monkeypatch, capsys):
    monkeypatch.setattr(api, "diagnose", lambda *a, **k: pytest.fail("must not run"))
    assert main(["diagnose", str(dataset), "--model", "object", "--gate-null", "bootstrap"]) == 2
    err = capsys.readouterr().err
    assert "--gate-null" in err and "parametric" in err


def test_the_arm_model_refuses_the_flag_instead_of_ignoring_it(dataset, monkeypatch, capsys):
    """The arm model's gate does not read the object null: the flag is an error there, named."""
    monkeypatch.setattr(api, "diagnose", lambda *a, **k: pytest.fail("must not run"))
    rc = main(["diagnose", str(dataset), "--model", "arm", "--gate-null", "both"])
    assert rc != 0
    assert "--gate-null" in capsys.readouterr().err
