"""``robogs fit`` on two objects prints and returns every object's position RMS (issue 16).

The two-box generator (:mod:`robogs.synth.scenarios.two_objects`: box A pushed into box B,
pose noise 0.5 mm) written as a dataset; ``robogs fit --engine auto`` refits both table
frictions and must report, per object by its dataset name, the position RMS before -> after
and the held-out RMS. Oracle: ``robogs compare --json`` of the written revision (the same fitted
model): box A's overall RMS, and box B's ``object_poses/box_b`` rows pooled over the pushes by
their sample counts (counted from the dataset, not from the fit).
"""

from __future__ import annotations

import json
import re
import sys

import numpy as np
import pytest

from robogs.cli.main import main
from robogs.physics.recording import load_recording
from robogs.synth.scenarios.two_objects import make_two_objects, write_two_objects

_NUM = r"([\d.]+)"


def _pooled(streams: list[dict], name: str, counts: dict[str, int]) -> float:
    """RMS [mm] of an object's per-push rows of ``compare --json``, pooled by sample count."""
    rows = [(s["rms_mm"], counts[s["trajectory"]]) for s in streams if s["stream"] == name]
    assert len(rows) == len(counts)
    return float(np.sqrt(sum(n * r * r for r, n in rows) / sum(n for _, n in rows)))


@pytest.mark.slow
def test_fit_reports_each_object_as_compare_does(tmp_path, capsys):
    ds = tmp_path / "two_boxes"
    write_two_objects(make_two_objects(seed=0, noise=True), ds)
    rec = load_recording(ds)
    counts = {
        "box_a": {t.name: len(t.t_ns) for t in rec.trajectories},
        "box_b": {t.name: len(t.others["box_b"].t_ns) for t in rec.trajectories},
    }
    rc = main(["--threads", "1", "fit", str(ds), "--engine", "auto", "--mask-frames", "0"])
    out = capsys.readouterr().out
    assert rc == 0, out
    printed = {
        m.group(1): tuple(float(m.group(k)) for k in (2, 3, 5, 6))
        for m in re.finditer(
            rf"^  (box_[ab]): position RMS {_NUM} → {_NUM} mm \(noise floor {_NUM} mm; "
            rf"held-out {_NUM} → {_NUM} mm\)$",
            out,
            re.M,
        )
    }
    assert sorted(printed) == ["box_a", "box_b"], out
    rc = main(["--threads", "1", "compare", str(ds), "--engine", "mujoco", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    cmp = json.loads(cap.out)
    oracle = {
        "box_a": cmp["rms_mm"],
        "box_b": _pooled(cmp["streams"], "object_poses/box_b", counts["box_b"]),
    }
    # box A pooled from its own rows is compare's overall figure (the pooling is right)
    assert _pooled(cmp["streams"], "object_poses/box_a", counts["box_a"]) == pytest.approx(
        oracle["box_a"], rel=1e-9
    )
    print(f"fit printed {printed}; compare {oracle}", file=sys.stderr)
    for name, (before, after, h_before, h_after) in printed.items():
        assert after == pytest.approx(oracle[name], abs=6e-4)  # printed to 3 decimals
        assert before == pytest.approx(after, abs=0.1)  # both refitted (baseline), no effect added
        assert np.isfinite(h_before) and np.isfinite(h_after) and h_after > 0.0
    # JSON: a fit from the written revision has as its "before" that revision refitted, as
    # compare refits it: the same per-object numbers, unrounded
    rc = main(["--threads", "1", "fit", str(ds), "--engine", "mujoco", "--dry-run", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    objs = json.loads(cap.out)["objects"]
    assert list(objs) == ["box_a", "box_b"]
    for name in objs:
        assert objs[name]["rms_before_mm"] == pytest.approx(oracle[name], rel=1e-9)
        assert objs[name]["rms_after_mm"] == pytest.approx(oracle[name], abs=0.05)
        assert objs[name]["heldout_rms_before_mm"] > 0.0
    assert objs["box_b"]["noise_floor_mm"] == pytest.approx(np.sqrt(3) * 0.5, rel=0.15)
