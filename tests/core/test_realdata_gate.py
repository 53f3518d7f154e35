"""The real-data gate of tests/conftest.py, run on a tiny test file in a pytest subprocess.

Missing folder: marked tests skip with one reason naming the path; with
``ROBOGS_REQUIRE_REALDATA=1`` they fail. A test requesting ``real_data`` without the marker
fails. And no test file outside tests/conftest.py spells the folder's path itself.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]

_TINY = """
import pytest


@pytest.fixture(scope="session")
def robot(real_data):
    return real_data / "robot.urdf"


@pytest.mark.realdata
def test_reads_the_folder(real_data):
    assert (real_data / "robot.urdf").read_text() == "<robot/>"


@pytest.mark.realdata
def test_marked_without_the_fixture():
    pass


def test_plain():
    pass


def test_unmarked_reader(real_data):
    pass


def test_unmarked_reader_through_a_fixture(robot):
    pass
"""

_INI = """[pytest]
markers =
    realdata: needs the real-data folder
"""


def _run(tmp_path: Path, real: Path, require: str | None) -> dict[str, tuple[str, str]]:
    """Run the tiny file; {test name: (outcome, message)} from its JUnit XML."""
    box = tmp_path / "box"
    if not box.exists():
        box.mkdir()
        shutil.copy(TESTS / "conftest.py", box / "conftest.py")
        (box / "test_tiny.py").write_text(_TINY)
        (box / "pytest.ini").write_text(_INI)
    env = {k: v for k, v in os.environ.items() if not k.startswith("ROBOGS_")}
    env["ROBOGS_REALDATA_DIR"] = str(real)
    if require is not None:
        env["ROBOGS_REQUIRE_REALDATA"] = require
    xml = tmp_path / f"junit-{require}-{real.name}.xml"
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
         f"--junitxml={xml}", "test_tiny.py"],
        cwd=box, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    out: dict[str, tuple[str, str]] = {}
    for case in ET.parse(xml).getroot().iter("testcase"):
        name = case.get("name", "")
        verdict = ("passed", "")
        for tag in ("skipped", "error", "failure"):
            el = case.find(tag)
            if el is not None:
                verdict = (tag, el.get("message", ""))
        out[name] = verdict
    out["<exit>"] = (str(res.returncode), res.stdout[-2000:])
    return out


def test_missing_folder_skips_with_one_reason_and_fails_when_required(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere" / "real"
    got = _run(tmp_path, missing, None)
    reason = (
        f"../shared/fixtures/real not found at {missing}; "
        "set ROBOGS_REQUIRE_REALDATA=1 to make this a failure"
    )
    for name in ("test_reads_the_folder", "test_marked_without_the_fixture"):
        assert got[name][0] == "skipped" and reason in got[name][1], got
    assert got["test_plain"] == ("passed", "")
    for name in ("test_unmarked_reader", "test_unmarked_reader_through_a_fixture"):
        assert got[name][0] == "error" and "is not marked @pytest.mark.realdata" in got[name][1]
    assert got["<exit>"][0] == "1"  # the two unmarked readers
    for flag in ("1", "0"):
        got = _run(tmp_path, missing, flag)
        for name in ("test_reads_the_folder", "test_marked_without_the_fixture"):
            outcome = got[name][0]
            assert outcome == ("error" if flag == "1" else "skipped"), (flag, got)
            assert str(missing) in got[name][1]
        assert got["test_plain"] == ("passed", "")


def test_present_folder_runs_the_marked_tests(tmp_path: Path) -> None:
    real = tmp_path / "real"
    real.mkdir()
    (real / "robot.urdf").write_text("<robot/>")
    for flag in (None, "1"):
        got = _run(tmp_path, real, flag)
        for name in ("test_reads_the_folder", "test_marked_without_the_fixture", "test_plain"):
            assert got[name] == ("passed", ""), got
        for name in ("test_unmarked_reader", "test_unmarked_reader_through_a_fixture"):
            assert got[name][0] == "error", got


def _spells_the_real_folder(text: str) -> bool:
    return text == "shared" or "shared/fixtures" in text or "fixtures/real" in text


def test_no_test_file_builds_the_real_folder_path_itself() -> None:
    """Every reader goes through ``real_data``; docstrings may mention the folder."""
    offenders = []
    for path in sorted(TESTS.rglob("*.py")):
        if path == TESTS / "conftest.py" or path == Path(__file__).resolve():
            continue
        tree = ast.parse(path.read_text(), str(path))
        docs = {
            id(node.body[0].value)
            for node in ast.walk(tree)
            if isinstance(node, ast.Module | ast.FunctionDef | ast.ClassDef | ast.AsyncFunctionDef)
            and node.body
            and isinstance(node.body[0], ast.Expr)
            and isinstance(node.body[0].value, ast.Constant)
        }
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and id(node) not in docs
                and _spells_the_real_folder(node.value)
            ):
                offenders.append(f"{path.relative_to(TESTS)}:{node.lineno}")
    assert offenders == [], offenders


def test_ci_runs_the_readme_test_command_and_requires_the_real_data() -> None:
    readme = (TESTS.parent / "README.md").read_text()
    blocks = readme.split("```bash\n")[1:]
    cmds = [b.split("\n```", 1)[0].strip() for b in blocks]
    test_cmd = next(c for c in cmds if "pytest" in c and "pip install" in c)
    ci = [ln.strip() for ln in (TESTS.parent / ".ci" / "run").read_text().splitlines()]
    assert test_cmd in ci
    assert "export ROBOGS_REQUIRE_REALDATA=1" in ci[: ci.index(test_cmd)]
    assert "source .venv/bin/activate" in cmds
