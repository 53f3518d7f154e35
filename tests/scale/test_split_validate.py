"""Split validation (``robogs.format.distributed``) against the one-process run, finding for finding.

The oracle is :func:`robogs.format.validate.validate` on the same dataset: the split run must
give the same findings (every field, same order), the same dropped counts per code, the same
check statuses and the same notes. Run in this process (LocalExecutor); the Ray path is in
``test_ray_validate.py``.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from robogs.format.checks.context import InputReported
from robogs.format.checks.registry import check, unregister_check
from robogs.format.distributed import EPISODE_SCOPED, Stats, plan_units, validate_distributed
from robogs.format.errors import FormatError
from robogs.format.validate import validate

from ._data import EXPECTED_CODES, mutated_bulk


def _facts(report) -> tuple:
    return (
        [f.to_dict() for f in report.findings],
        dict(report.dropped),
        [(r.code, r.status, r.findings) for r in report.runs],
        list(report.notes),
        report.counts(),
    )


@pytest.fixture(scope="module")
def mutated(tmp_path_factory) -> Path:
    return mutated_bulk(tmp_path_factory.mktemp("split") / "ds", 36)


@pytest.fixture(scope="module")
def mutated_sharded(tmp_path_factory) -> Path:
    """The same defects in chunks of 12 episodes (tasks read their chunk index)."""
    return mutated_bulk(tmp_path_factory.mktemp("split-sharded") / "ds", 36, chunk_size=12)


@pytest.fixture(params=["flat", "sharded"])
def either(request, mutated, mutated_sharded) -> Path:
    return mutated if request.param == "flat" else mutated_sharded


def check_scope(code: str) -> str | None:
    """The test checks below split by episode (the hook the distributed runner reads)."""
    return "episode" if code.startswith("Z99") else None


@pytest.fixture
def odd_checks():
    """Z990 crashes at ep020, Z991 raises a FormatError at ep021, Z992 stops (InputReported)
    at ep005; each yields an info finding per episode before that."""

    def per_episode(stop: str, exc):
        def fn(chk, ctx):
            for ep in ctx.episodes:
                if ep.id == stop:
                    raise exc(ep)
                yield chk.finding(f"seen {ep.id}", severity="info", episode=ep.id)

        return fn

    def fmt(ep):
        return FormatError("broken on purpose", path=Path("/nowhere") / ep.id, where="row 3")

    specs = {
        "Z990": ("ep020", lambda ep: ValueError(f"boom in {ep.id}")),
        "Z991": ("ep021", fmt),
        "Z992": ("ep005", lambda ep: InputReported(ep.id)),
    }
    for code, (stop, exc) in specs.items():
        fn = per_episode(stop, exc)
        fn.__module__ = __name__
        check(code, group="physics", severity="info", title=f"test {code}")(fn)
    yield
    for code in specs:
        unregister_check(code)


def test_split_equals_single_on_mutated_episodes(mutated):
    single = validate(mutated)
    assert EXPECTED_CODES <= single.codes(), single.codes()
    stats = Stats()
    split = validate_distributed(mutated, episodes_per_task=5, files_per_task=7, stats=stats)
    assert stats.reason is None and stats.units == 8 + 11  # 36/5 episode units, 73/7 file units
    assert _facts(split) == _facts(single)


@pytest.mark.parametrize(
    "kw",
    [
        {"max_per_code": 1},
        {"quick": True},
        {"select": ["T", "I00"], "ignore": ["I004"]},
    ],
)
def test_split_equals_single_with_caps_quick_and_selection(either, kw):
    single = validate(either, **kw)
    stats = Stats()
    split = validate_distributed(either, episodes_per_task=4, files_per_task=9, stats=stats, **kw)
    assert _facts(split) == _facts(single)
    assert (stats.chunk_units > 0) == ("shards" in (either / "manifest.json").read_text())
    if "max_per_code" in kw:
        assert single.dropped, "the cap must drop something for this case to test it"


def test_crash_error_and_reported_stop_where_the_single_run_stops(either, odd_checks):
    single = validate(either, max_per_code=30)
    stats = Stats()
    split = validate_distributed(either, episodes_per_task=3, max_per_code=30, stats=stats)
    assert _facts(split) == _facts(single)
    assert (stats.chunk_units > 0) == ("shards" in (either / "manifest.json").read_text())
    runs = {r.code: r for r in split.runs}
    assert runs["Z990"].status == "crashed" and runs["Z992"].status == "ran"
    z990 = [f for f in split.findings if f.code == "Z990"]
    assert len(z990) == 20  # ep000..ep019, then the crash
    x = {f.code: f.message for f in split.findings if f.code in ("X001", "X002")}
    assert "Z990" in x["X001"] and "boom in ep020" in x["X001"]
    assert "Z991" in x["X002"] and "broken on purpose" in x["X002"]
    assert split.dropped == single.dropped and split.dropped.get("Z991", 0) == 0


def test_tables_shared_by_episodes_run_in_one_process(mutated, tmp_path):
    import json
    import shutil

    ds = tmp_path / "one_table_two_episodes"
    shutil.copytree(mutated, ds)
    m = json.loads((ds / "manifest.json").read_text())
    m["episodes"][1]["streams"]["ee_poses"]["path"] = m["episodes"][0]["streams"]["ee_poses"][
        "path"
    ]
    (ds / "manifest.json").write_text(json.dumps(m))
    stats = Stats()
    split = validate_distributed(ds, episodes_per_task=5, stats=stats)
    assert stats.units == 0 and "named by two episodes" in stats.reason
    assert _facts(split) == _facts(validate(ds))


def test_plan_scopes(mutated):
    from robogs.format.checks.context import CheckContext
    from robogs.format.checks.registry import available_checks

    plan = plan_units(CheckContext(mutated), list(available_checks().values()))
    assert {c for c, s in plan.scopes.items() if s == "episode"} == EPISODE_SCOPED
    assert plan.scopes["I002"] == plan.scopes["S001"] == plan.scopes["B004"] == "dataset"
