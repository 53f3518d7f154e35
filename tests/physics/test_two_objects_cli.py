"""Two objects through the user path (issue 16): the two-box generator
(:mod:`robogs.synth.scenarios.two_objects`: box A pushed into box B; mu_a 0.45, mu_b 0.25,
physics.json nominal 0.35 / 0.35, pose noise 0.5 mm per axis) written as a dataset
(:func:`~robogs.synth.scenarios.two_objects.write_two_objects`: both boxes in
``object_poses``, no wrench), then ``robogs fit`` / ``compare`` / ``diagnose`` on it.

``load_recording`` takes box A (the one the pusher comes closest to) as the free object and
tracks box B; ``--engine auto`` picks MuJoCo (the planar model has one box), the default planar
engine stops with the fix; the fit refits both table frictions from both boxes' poses.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robogs.cli.main import main
from robogs.format.dataset import Dataset
from robogs.physics.recording import load_recording
from robogs.synth.scenarios.two_objects import TwoBoxTruth, make_two_objects, write_two_objects

TRUTH = TwoBoxTruth()


@pytest.fixture(scope="module")
def two_box_dataset(tmp_path_factory):
    rec = make_two_objects(seed=0, noise=True)
    out = tmp_path_factory.mktemp("two") / "two_boxes"
    write_two_objects(rec, out)
    return out, rec


def test_dataset_holds_both_boxes(two_box_dataset):
    """The dataset round-trips both boxes' poses exactly; box A is the free object."""
    ds, gen = two_box_dataset
    rec = load_recording(ds)
    assert rec.object_name == "box_a" and rec.tracked == ["box_b"]
    assert [t.name for t in rec.trajectories] == [t.name for t in gen.trajectories]
    for tr, g in zip(rec.trajectories, gen.trajectories, strict=True):
        np.testing.assert_array_equal(tr.object_pos, g.object_pos)
        b = tr.others["box_b"]
        np.testing.assert_array_equal(b.t_ns, g.t_ns)
        np.testing.assert_array_equal(b.pos, g.other_pos)
    assert main(["validate", str(ds), "--fail-on", "warning"]) == 0


def test_planar_engine_names_the_fix(two_box_dataset, capsys):
    """Default engine (planar): one line, exit 2, naming --engine mujoco."""
    ds, _ = two_box_dataset
    assert main(["fit", str(ds), "--dry-run", "--mask-frames", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--engine mujoco" in err[0] and "2 rigid objects" in err[0]


def test_fit_two_boxes(two_box_dataset, capsys):
    """``robogs fit --engine auto`` writes both table frictions within 10 % of the generator
    (measured mu_a 0.428, -4.8 %; mu_b 0.244, -2.2 %; before the z-ballast contact settings
    0.471 and 0.255) and ``compare`` then leaves each box within 1.2 mm RMS in every push
    (measured 0.83-0.98 mm; the generator's noise alone gives
    sqrt(3) x 0.5 = 0.87 mm, so the model is within about 0.7 mm RMS of the generator; at the
    nominal frictions box B is 6 mm off, ``test_two_objects.py``)."""
    ds, _ = two_box_dataset
    rc = main(["--threads", "1", "fit", str(ds), "--engine", "auto", "--mask-frames", "0"])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "engine: mujoco (auto: planar cannot represent it: 2 rigid objects" in out
    objects = Dataset.open(ds).physics()["objects"]
    mu_a, mu_b = objects["box_a"]["friction_dynamic"], objects["box_b"]["friction_dynamic"]
    assert mu_a == pytest.approx(TRUTH.mu_a, rel=0.10)
    assert mu_b == pytest.approx(TRUTH.mu_b, rel=0.10)
    assert objects["box_a"]["friction_static"] >= mu_a  # still valid Coulomb friction (P002)
    assert main(["validate", str(ds), "--fail-on", "warning"]) == 0
    capsys.readouterr()
    rc = main(["--threads", "1", "compare", str(ds), "--engine", "mujoco", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    d = json.loads(cap.out)
    rows = {(s["stream"], s["trajectory"]): s["rms_mm"] for s in d["streams"]}
    print(f"fitted mu_a {mu_a:.4f}, mu_b {mu_b:.4f}; rms per push [mm]: {rows}")
    for obj in ("box_a", "box_b"):
        per = [v for (s, _), v in rows.items() if s == f"object_poses/{obj}"]
        assert len(per) == 3 and max(per) < 1.2


DOCS = Path(__file__).resolve().parents[2] / "docs" / "physics.md"
SECTION = "### Two objects in one scene"


def _doc_lines() -> list[str]:
    """The command lines of docs/physics.md's two-object section (its first bash block)."""
    text = DOCS.read_text(encoding="utf-8")
    block = re.search(r"```bash\n(.*?)```", text[text.index(SECTION) :], re.S).group(1)
    return [ln.strip() for ln in block.splitlines() if ln.strip()]


@pytest.mark.slow
def test_docs_two_object_commands(tmp_path):
    """The docs' two-object lines run as written (venv first on the PATH): the fit picks MuJoCo
    and fits both frictions, compare lists box B per push, and ``robogs diagnose --engine
    mujoco`` on the null scenario runs the catalogue to the end and reports no effect (the
    dynamic effects are skipped as unobservable: box A stops within 3 samples of losing
    contact; the directional ones need 3 push directions)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"
    lines = _doc_lines()
    assert [ln.split()[:2] for ln in lines[1:]] == [
        ["robogs", "fit"],
        ["robogs", "compare"],
        ["robogs", "diagnose"],
    ]
    out = {}
    for line in lines:
        args = shlex.split(line)
        if args[0] == "python":
            args[0] = sys.executable
        else:
            args[1:1] = ["--threads", "1"]
        p = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
        assert p.returncode == 0 and "Traceback" not in p.stderr, f"{line}\n{p.stderr[-3000:]}"
        out[args[3] if args[0] != sys.executable else "write"] = p.stdout
    assert "engine: mujoco (auto: planar cannot represent it" in out["fit"]
    assert "base.objects.box_b.friction_dynamic" in out["fit"]
    assert len(re.findall(r"object_poses/box_b: rms", out["compare"])) == 3
    assert "missing effect(s): none above the noise" in out["diagnose"], out["diagnose"]
    objects = json.loads((tmp_path / "two_boxes" / "physics.json").read_text())["objects"]
    assert objects["box_b"]["friction_dynamic"] == pytest.approx(TRUTH.mu_b, rel=0.10)
