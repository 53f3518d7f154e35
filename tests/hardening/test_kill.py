"""kill -9 during convert, reconstruct and fit: the previous dataset survives, the next run works.

Each command runs in a fresh interpreter and is killed with SIGKILL at three seeded points: a
random time after start, a random moment after the writer's temp folder appears (the write
phase), and a random moment after the manifest lands in the temp folder (commit and swap).
After every kill the dataset path must hold either the previous version byte for byte (every
file hashed, manifest included) or a complete new version; afterwards one uninterrupted run
must succeed and clean up what the killed runs left. The verdict uses hashlib and json only
(``robogs.synth.killrun``). The longer campaign is ``bench/kill_campaign.py``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from robogs.cli.main import main
from robogs.synth.armlogs import ArmLogSpec, generate_armlog, ur5_urdf
from robogs.synth.killrun import (
    after_start,
    is_complete_version,
    leftovers,
    manifest_in_tmp,
    run_and_kill,
    run_to_end,
    tmp_appeared,
    tree_digest,
    when_exists,
)
from robogs.synth.multiview import synthesize_multiview

SEED = 7


@pytest.fixture(scope="module")
def inputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("kill")
    urdf = root / "ur5.urdf"
    urdf.write_text(ur5_urdf())
    for name, seed in (("logA", 1), ("logB", 2)):
        generate_armlog(root / name, urdf, ArmLogSpec(segments=2, duration_s=2.0, seed=seed))
    assert main(["convert", str(root / "logA"), str(root / "arm"), "--urdf", str(urdf)]) == 0
    synthesize_multiview(root / "mv", n_views=8, width=40, height=30, supersample=1)
    return {
        "root": root,
        "urdf": urdf,
        "logB": root / "logB",
        "arm": root / "arm",
        "mv": root / "mv",
    }


def _triggers(target: Path, rng: np.random.Generator, first=None):
    return [
        first or after_start(float(rng.uniform(0.2, 1.5))),
        tmp_appeared(target, float(rng.uniform(0.0, 0.05))),
        manifest_in_tmp(target, float(rng.uniform(0.0, 0.003))),
    ]


def _campaign(argv: list[str], target: Path, rng: np.random.Generator, log: Path, first=None):
    """Three killed runs, each checked; returns the states seen."""
    states = []
    for trig in _triggers(target, rng, first):
        before = tree_digest(target)
        res = run_and_kill(argv, target, trig, before=before, log=log)
        assert res.state in ("previous", "new"), (res, log.read_text()[-2000:])
        if res.state == "previous":
            assert tree_digest(target) == before
        states.append(res.state)
    return states


def _final_run(argv: list[str], target: Path, log: Path) -> None:
    rc, _ = run_to_end(argv, log=log)
    assert rc == 0, log.read_text()[-3000:]
    assert is_complete_version(target)
    assert leftovers(target) == []


def test_kill_during_convert_force(inputs: dict[str, Path], tmp_path: Path) -> None:
    target = tmp_path / "out"
    shutil.copytree(inputs["arm"], target)
    first = tree_digest(target)
    argv = ["convert", str(inputs["logB"]), str(target), "--urdf", str(inputs["urdf"]), "--force"]
    log = tmp_path / "log.txt"
    _campaign(argv, target, np.random.default_rng(SEED), log)
    _final_run(argv, target, log)
    assert tree_digest(target) != first  # logB replaced logA
    ref = tmp_path / "ref"  # the same conversion, never interrupted
    assert main(["convert", str(inputs["logB"]), str(ref), "--urdf", str(inputs["urdf"])]) == 0
    files = json.loads((target / "manifest.json").read_text())["files"]
    assert files == json.loads((ref / "manifest.json").read_text())["files"]


def test_kill_during_fit_add(inputs: dict[str, Path], tmp_path: Path) -> None:
    target = tmp_path / "arm"
    shutil.copytree(inputs["arm"], target)
    argv = ["fit", str(target), "--add", "joint_friction"]
    log = tmp_path / "log.txt"
    states = _campaign(argv, target, np.random.default_rng(SEED + 1), log)
    rev = json.loads((target / "physics.json").read_text())["revision"]
    assert rev == 1 + states.count("new")  # each committed run adds exactly one revision
    _final_run(argv, target, log)
    assert json.loads((target / "physics.json").read_text())["revision"] == rev + 1


def test_kill_during_reconstruct(inputs: dict[str, Path], tmp_path: Path) -> None:
    target, work = tmp_path / "mv", tmp_path / "work"
    shutil.copytree(inputs["mv"], target)
    argv = [
        "reconstruct", str(target), "--iterations", "6", "--checkpoint-every", "2",
        "--max-views", "4", "--tsdf-resolution", "24", "--heldout-every", "4", "--threads", "1",
        "--no-progress", "--work-dir", str(work), "--force",
    ]  # fmt: skip
    log = tmp_path / "log.txt"
    rng = np.random.default_rng(SEED + 2)  # first kill: mid-training, after a checkpoint
    ckpt = when_exists("checkpoint", (work / "checkpoint.pt").exists, float(rng.uniform(0, 0.2)))
    _campaign(argv, target, rng, log, first=ckpt)
    _final_run(argv, target, log)
    man = json.loads((target / "manifest.json").read_text())
    assert "splats" in man["robot"] and (target / "reconstruction" / "mesh.ply").is_file()
