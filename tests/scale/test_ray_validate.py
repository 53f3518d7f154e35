"""``robogs validate --ray`` on a local 2-CPU Ray cluster: the findings of the one-process run,
code for code and value for value, on ~100 episodes with defects in known episodes; a task whose
worker dies is retried and the findings do not change."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from robogs.format.distributed import RayExecutor, Stats, ray_unit, validate_distributed
from robogs.format.validate import validate

from ._data import EXPECTED_CODES, mutated_bulk

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return mutated_bulk(tmp_path_factory.mktemp("ray") / "ds", 100, duration_s=0.3)


@pytest.fixture(scope="module")
def single(dataset):
    report = validate(dataset)
    assert EXPECTED_CODES <= report.codes()
    return report


def _facts(report) -> tuple:
    return (
        [f.to_dict() for f in report.findings],
        dict(report.dropped),
        [(r.code, r.status, r.findings) for r in report.runs],
        report.notes,
    )


def test_ray_two_workers_equal_single_process(ray_cluster, dataset, single):
    stats = Stats()
    split = validate_distributed(
        dataset, executor=RayExecutor(), episodes_per_task=10, files_per_task=40, stats=stats
    )
    assert stats.reason is None and stats.units == 10 + 6
    assert len(stats.peak_rss) == 2, "both workers must have taken tasks"
    assert _facts(split) == _facts(single)
    assert max(stats.peak_rss.values()) < 1024**3  # the per-worker bound


def test_killed_worker_is_retried(ray_cluster, dataset, single, tmp_path):
    marker = str(tmp_path / "killed-once")

    def dies_once(root, base, unit, settings):
        if unit.index == 3 and not os.path.exists(marker):
            open(marker, "w").close()
            os._exit(1)  # the worker process dies mid-task
        return ray_unit(root, base, unit, settings)

    split = validate_distributed(
        dataset,
        executor=RayExecutor(body=dies_once, max_retries=2),
        episodes_per_task=10,
        files_per_task=40,
    )
    assert os.path.exists(marker)
    assert _facts(split) == _facts(single)


def test_cli_ray_json_equals_cli_single(ray_cluster, dataset, capsys):
    from robogs.cli.main import main

    def run(*extra):
        code = main(["validate", str(dataset), "--json", "--threads", "1", *extra])
        out = capsys.readouterr()
        return code, json.loads(out.out), out.err

    code1, one, _ = run()
    code2, split, err = run("--ray", "--episodes-per-task", "7")
    assert code1 == code2 == 1
    assert split["findings"] == one["findings"]
    assert split["summary"]["counts"] == one["summary"]["counts"]
    # 100 episodes in tasks of 7, 206 files in tasks of 200; both workers named
    assert "ray: 17 tasks on 2 worker processes" in err


@pytest.fixture(scope="module")
def sharded(tmp_path_factory) -> Path:
    """The same defects in the sharded layout (chunks of 40 episodes: 3 chunk indexes)."""
    return mutated_bulk(
        tmp_path_factory.mktemp("ray-sharded") / "ds", 100, duration_s=0.3, chunk_size=40
    )


def test_ray_two_workers_on_sharded_layout_equal_single_process(ray_cluster, sharded):
    single = validate(sharded)
    assert EXPECTED_CODES <= single.codes() and "I011" not in single.codes()
    stats = Stats()
    split = validate_distributed(
        sharded, executor=RayExecutor(), episodes_per_task=20, files_per_task=70, stats=stats
    )
    # chunks of 40, 40, 20 episodes in tasks of 20 (5 units, each reading its chunk's index);
    # each chunk's 80, 80, 40 files in tasks of 70 (2 + 2 + 1), and the rows between them:
    # index 0, index 1, index 2 + the URDF (3 units)
    assert stats.reason is None and stats.units == 5 + 8 and stats.chunk_units == 10
    assert len(stats.peak_rss) == 2, "both workers must have taken tasks"
    assert _facts(split) == _facts(single)
