"""Validation in bounded memory: streaming statistics, long episodes and many episodes.

Oracles: numpy over the whole array (order statistics), interpolation over the whole table
(``SampleWindow``), defects planted at known rows of a long episode written by
``robogs.synth.bulk`` (independent of the writer), and a peak RSS measured by ``os.wait4`` for a
100-episode validation in its own interpreter. The full-size figures (1,000 episodes, a
30-minute episode) are ``bench/load.py``, and so is the figure under CPU load: two ``robogs
diagnose`` at once on two cores against their solo time (``bench/load.py --diagnose``; a timing
target lives in ``bench/``, not in the suite). The thread settings that keep that figure near 2x
are tested without timing in ``tests/qa/test_threads.py``.
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.format.checks.context import CheckContext
from robogs.format.checks.streaming import (
    MedianSketch,
    SampleWindow,
    kth_smallest,
    median,
    percentile,
)
from robogs.format.interp import interp_linear
from robogs.format.validate import validate
from robogs.synth.bulk import JOINTS, LINKS_M, write_bulk_dataset


def _chunked(x: np.ndarray, size: int = 4096):
    return lambda: (x[i : i + size] for i in range(0, x.size, size))


@pytest.mark.parametrize("n", [1, 2, 7, 1000, 70_001])
@pytest.mark.parametrize("kind", ["jitter", "ties", "heavy"])
def test_streamed_order_statistics_equal_numpy(n: int, kind: str) -> None:
    rng = np.random.default_rng(n)
    if kind == "jitter":  # periods of a 500 Hz clock, in ns
        x = (2_000_000 + rng.integers(-5000, 5000, n)).astype(np.float64)
    elif kind == "ties":
        x = np.where(rng.random(n) < 0.9, 2e6, 4e6)
    else:
        x = np.abs(rng.standard_cauchy(n)) * 1e3
    values = _chunked(x)
    assert median(values, n) == np.median(x)
    for q in (0, 50, 99, 100):
        assert percentile(values, n, q) == np.percentile(x, q)
    for k in {0, n // 2, n - 1}:
        assert kth_smallest(values, k) == np.partition(x, k)[k]


def test_median_sketch_is_exact_then_within_its_resolution(monkeypatch) -> None:
    rng = np.random.default_rng(1)
    x = np.abs(rng.normal(3.0, 1.0, 5000))
    exact = MedianSketch()
    for c in np.array_split(x, 7):
        exact.add(c)
    assert exact.exact and exact.median() == np.median(x)
    monkeypatch.setattr(MedianSketch, "_CAP", 1000)
    sketch = MedianSketch()
    for c in np.array_split(x, 7):
        sketch.add(c)
    assert not sketch.exact
    assert sketch.median() == pytest.approx(np.median(x), rel=2 ** (1 / 256) - 1)
    zeros = MedianSketch()
    zeros.add(np.r_[np.zeros(1500), np.full(1400, 1e-15)])
    assert zeros.median() == 0.0


def test_sample_window_interpolates_like_the_whole_table(tmp_path: Path) -> None:
    root = tmp_path / "ds"
    write_bulk_dataset(root, n_episodes=1, duration_s=300.0)  # 150k rows, 3 row groups
    rel = "episodes/ep000/joint_states.parquet"
    tab = pq.read_table(root / rel)
    cols = tuple(f"position.{j}" for j in JOINTS)
    t = tab.column("t_ns").to_numpy()
    q = np.stack([tab.column(c).to_numpy() for c in cols], axis=1)
    window = SampleWindow(CheckContext(root), rel, cols)
    rng = np.random.default_rng(2)
    # forward-moving query ranges, some on exact sample stamps and on the last one
    starts = np.sort(rng.integers(t[0], t[-1], 40))
    for lo in [*starts, int(t[-3])]:
        hi = min(int(lo) + 300_000_000, int(t[-1]))
        exact = t[(t >= lo) & (t <= hi)][::50]
        tq = np.sort(np.concatenate([rng.integers(lo, hi + 1, 500), exact, [lo, hi]]))
        tw, qw = window.around(int(tq[0]), int(tq[-1]))
        assert tw.size < 3 * (1 << 16)  # bounded, whatever the length
        assert np.array_equal(interp_linear(tq, tw, qw), interp_linear(tq, t, q))
    tw, qw = window.around(int(t[5]), int(t[9]))  # backwards: restarts the read
    assert np.array_equal(interp_linear(t[5:10], tw, qw), q[5:10])


def _rehash(root: Path, rel: str) -> None:
    man = json.loads((root / "manifest.json").read_text())
    p = root / rel
    man["files"][rel] = {
        "sha256": hashlib.sha256(p.read_bytes()).hexdigest(),
        "size": p.stat().st_size,
        "rows": pq.ParquetFile(p).metadata.num_rows,
    }
    (root / "manifest.json").write_text(json.dumps(man))


def test_defects_at_the_end_of_a_long_episode_are_found_at_their_rows(tmp_path: Path) -> None:
    root = tmp_path / "long"
    write_bulk_dataset(root, n_episodes=1, duration_s=280.0, seed=3)  # 140k rows per table
    assert validate(root).counts()["error"] == 0
    rel_js, rel_ee = "episodes/ep000/joint_states.parquet", "episodes/ep000/ee_poses.parquet"
    js, ee = pq.read_table(root / rel_js), pq.read_table(root / rel_ee)
    n = js.num_rows
    gap, late, limit, off = n - 900, n - 2000, n - 3000, n - 4000
    t = js.column("t_ns").to_numpy().copy()
    t[gap + 1 :] += 7 * 2_000_000  # 8 periods: a gap
    t[late] += 300_000  # 0.3 ms late: jitter
    q2 = js.column("position.joint2").to_numpy().copy()
    q2[limit] = 3.25  # limit 3.1
    x = ee.column("x").to_numpy().copy()
    x[off] += 0.004  # 4 mm
    qrow = np.array([js.column(f"position.{j}")[limit].as_py() for j in JOINTS])
    qrow[1] = 3.25
    cum = np.cumsum(qrow)  # keep the recorded pose consistent with the joint past its limit
    y, qw, qz = (ee.column(c).to_numpy().copy() for c in ("y", "qw", "qz"))
    x[limit] = sum(L * np.cos(cum[i]) for i, L in enumerate(LINKS_M))
    y[limit] = sum(L * np.sin(cum[i]) for i, L in enumerate(LINKS_M))
    qw[limit], qz[limit] = np.cos(cum[2] / 2), np.sin(cum[2] / 2)
    js = js.set_column(0, "t_ns", pa.array(t))
    js = js.set_column(
        js.schema.get_field_index("position.joint2"), "position.joint2", pa.array(q2)
    )
    ee = ee.set_column(0, "t_ns", pa.array(t))
    for c, v in (("x", x), ("y", y), ("qw", qw), ("qz", qz)):
        ee = ee.set_column(ee.schema.get_field_index(c), c, pa.array(v))
    for rel, tab in ((rel_js, js), (rel_ee, ee)):
        pq.write_table(tab, root / rel, row_group_size=1 << 16)
        _rehash(root, rel)
    man = json.loads((root / "manifest.json").read_text())
    man["episodes"][0]["end_ns"] = int(t[-1])  # the gap moved the end
    (root / "manifest.json").write_text(json.dumps(man))

    budgets = {"time.jitter_max_ms": 0.2}
    found = {(f.code, f.location.file): f for f in validate(root, budgets=budgets).findings}
    assert {c for c, _ in found} == {"T003", "T006", "G007", "G008"}
    dt = np.diff(t).astype(np.float64)  # brute-force oracles over the whole arrays
    p = np.median(dt)
    f = found[("T003", rel_js)]
    assert f.location.where == f"row {gap}" and f.value == pytest.approx(dt[gap] * 1e-6)
    f = found[("T006", rel_js)]
    jit = np.abs(dt[dt <= 1.5 * p] - p) * 1e-6
    assert f.value == jit.max() and f.location.t_ns == t[late]
    assert f"p99 {np.percentile(jit, 99):.3g} ms" in f.message
    f = found[("G007", rel_js)]
    assert f.location.where == f"row {limit}" and f.value == pytest.approx(0.15)
    f = found[("G008", rel_ee)]
    assert f.location.where == f"row {off}" and f.value == pytest.approx(4.0, abs=1e-6)
    assert f"1 of {n} samples" in f.message


_CHILD = """
import json, sys, torch
torch.set_num_threads(1)
from robogs.format.validate import validate
r = validate(sys.argv[1])
hwm = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM:")]
print(json.dumps(r.counts()))
print(int(hwm[0].split()[1]) if hwm else -1)
"""


def test_one_hundred_episodes_validate_in_bounded_memory(tmp_path: Path) -> None:
    root = tmp_path / "many"
    write_bulk_dataset(root, n_episodes=100, duration_s=2.0)
    proc = subprocess.Popen(
        [sys.executable, "-W", "ignore", "-c", _CHILD, str(root)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    out, err = proc.stdout.read(), proc.stderr.read()  # type: ignore[union-attr]
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    assert proc.returncode == 0, err.decode()[-2000:]
    counts, hwm_kb = out.decode().strip().splitlines()
    assert json.loads(counts) == {"error": 0, "warning": 0, "info": 0}
    # the child's own peak (VmHWM, kB): wait4's ru_maxrss also counts the parent's pages
    # at fork time, which a busy pytest worker inflates
    peak_kb = int(hwm_kb) if int(hwm_kb) > 0 else usage.ru_maxrss
    assert peak_kb / 1024 < 1024  # MB; about 450 measured, mostly the torch import
