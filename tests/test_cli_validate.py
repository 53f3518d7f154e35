"""``robogs validate`` / ``robogs-validate``: output formats and exit codes."""

from __future__ import annotations

import importlib.util
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from robogs.cli.main import main, validate_main
from robogs.format.checks import available_checks
from robogs.synth import mutations as mut

_spec = importlib.util.spec_from_file_location(
    "robogs_tests_tiny_scene", Path(__file__).resolve().parent / "checks" / "tiny_scene.py"
)
_tiny = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_tiny)
build_tiny_scene = _tiny.build_tiny_scene


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_tiny_scene(tmp_path_factory.mktemp("cli") / "ds")


@pytest.fixture
def broken(tiny: Path, tmp_path: Path) -> Path:
    ds = tmp_path / "ds"
    shutil.copytree(tiny, ds)
    mut.gap_in_stream(ds)
    mut.jitter_camera_stamps(ds, ms=1.0)  # no finding (below every budget)
    mut.drop_object_inertia(ds)  # warning P003
    return ds


def test_clean_dataset_exits_0_with_a_summary(
    tiny: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert validate_main([str(tiny), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "0 errors, 0 warnings" in out and "integrity" in out


def test_findings_exit_1_and_fail_on_policy(
    broken: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["validate", str(broken), "--no-progress"]) == 1
    out = capsys.readouterr().out
    assert "T003" in out and "hint:" in out and "budget" in out
    assert main(["validate", str(broken), "--ignore", "T003"]) == 0
    assert main(["validate", str(broken), "--ignore", "T003", "--fail-on", "warning"]) == 1
    assert main(["validate", str(broken), "--fail-on", "never"]) == 0


def test_json_output_is_one_object_with_findings_and_summary(
    broken: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["validate", str(broken), "--json"]) == 1
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"findings", "summary"}
    keys = {"code", "severity", "location", "value", "budget", "unit", "message", "hint"}
    assert all(set(f) == keys for f in data["findings"])
    (gap,) = [f for f in data["findings"] if f["code"] == "T003"]
    assert gap["unit"] == "ms" and gap["value"] > gap["budget"] > 0
    assert gap["location"]["stream"] == "joint_states" and isinstance(gap["location"]["t_ns"], int)
    assert data["summary"]["counts"] == {"error": 1, "warning": 1, "info": 0}
    assert data["summary"]["groups"]["time"]["error"] == 1


def test_select_ignore_and_quick(broken: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(broken), "--json", "--select", "T003,P"]) == 1
    codes = {f["code"] for f in json.loads(capsys.readouterr().out)["findings"]}
    assert codes == {"T003", "P003"}
    assert main(["validate", str(broken), "--json", "--quick"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["summary"]["quick"] is True
    assert data["summary"]["checks_run"] == sum(
        not c.needs_full for c in available_checks().values()
    )


def test_junit_and_markdown_files(broken: Path, tmp_path: Path) -> None:
    junit, md = tmp_path / "r.xml", tmp_path / "r.md"
    assert (
        main(
            ["validate", str(broken), "--junit", str(junit), "--markdown", str(md), "--no-progress"]
        )
        == 1
    )
    root = ET.parse(junit).getroot()
    assert root.tag == "testsuites"
    failures = [c for c in root.iter("testcase") if c.find("failure") is not None]
    assert [c.get("name").split()[0] for c in failures] == ["T003"]
    time_suite = next(s for s in root.iter("testsuite") if s.get("name") == "robogs.time")
    assert time_suite.get("failures") == "1"
    text = md.read_text()
    assert "| T003 | error |" in text and "FAIL" in text


def test_budget_option(tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ds = tmp_path / "ds"
    shutil.copytree(tiny, ds)
    mut.offset_ee_pose(ds, mm=5.0)
    assert main(["validate", str(ds), "--no-progress"]) == 1
    assert main(["validate", str(ds), "--budget", "geometry.fk_ee_mm=6", "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["validate", str(ds), "--budget", "geometry.fk_ee_cm=6"]) == 2
    assert "unknown budget" in capsys.readouterr().err
    assert main(["validate", str(ds), "--budget", "nonsense"]) == 2


@pytest.mark.parametrize("content", ["{oops", None])
def test_unreadable_input_exits_2_with_one_line(
    tmp_path: Path, content: str | None, capsys: pytest.CaptureFixture[str]
) -> None:
    if content is not None:
        (tmp_path / "manifest.json").write_text(content)
    assert main(["validate", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "manifest" in err


def test_usage_errors_exit_2(tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(tiny), "--fail-on", "sometimes"]) == 2
    assert main(["validate", str(tiny), "--select", "Q123"]) == 2
    assert "no check matches" in capsys.readouterr().err
    assert main(["validate"]) == 2


def test_list_checks(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["validate", "--list-checks", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert [c["code"] for c in listed] == list(available_checks())
    md = tmp_path / "cat.md"
    assert main(["validate", "--list-checks", "--markdown", str(md)]) == 0
    catalogue = (Path(__file__).resolve().parents[1] / "spec" / "CHECKS.md").read_text()
    assert md.read_text() in catalogue


def test_json_out_equals_json_stdout_in_the_same_run(
    broken: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "out").mkdir()
    out = tmp_path / "out" / "report.json"
    assert main(["validate", str(broken), "--json", "--json-out", str(out)]) == 1
    assert out.read_text(encoding="utf-8") == capsys.readouterr().out
    assert [p.name for p in out.parent.iterdir()] == ["report.json"]  # no temporary file left


def test_json_out_beside_the_text_output(
    broken: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One run gives the text report on stdout and the JSON report in the file; the file holds
    what ``--json`` prints (compared without the run's own wall time)."""
    out = tmp_path / "report.json"
    out.write_text("old")
    assert main(["validate", str(broken), "--json-out", str(out), "--no-progress"]) == 1
    text = capsys.readouterr().out
    assert "T003" in text and "errors" in text and not text.lstrip().startswith("{")
    written = json.loads(out.read_text(encoding="utf-8"))
    assert main(["validate", str(broken), "--json"]) == 1
    printed = json.loads(capsys.readouterr().out)
    for doc in (written, printed):
        assert doc["summary"].pop("seconds") >= 0.0
    assert written == printed
    assert [f["code"] for f in written["findings"]] == ["T003", "P003"]


def test_json_out_is_atomic(
    broken: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A failing write leaves the old file whole and no temporary file; a missing folder is a
    usage error before anything runs."""
    import os

    (tmp_path / "out").mkdir()
    out = tmp_path / "out" / "report.json"
    out.write_text("old")

    def refuse(src: str, dst: str) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", refuse)
    assert main(["validate", str(broken), "--json-out", str(out), "--no-progress"]) == 2
    assert "cannot write report" in capsys.readouterr().err
    assert out.read_text() == "old" and [p.name for p in out.parent.iterdir()] == ["report.json"]
    monkeypatch.undo()
    missing = tmp_path / "nowhere" / "r.json"
    assert main(["validate", str(broken), "--json-out", str(missing), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "does not exist" in err and err.count("\n") == 1 and not missing.parent.exists()
