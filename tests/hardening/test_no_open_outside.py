"""No file outside the dataset root is opened (issue 19): strace follows ``robogs-validate`` on
a dataset whose manifest, sidecars and tables point out of the root (symlinks and paths), and
no file descriptor ever names a victim file (``strace -y`` prints the file an fd really refers
to, so an open through an in-root symlink shows the target)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

STRACE = shutil.which("strace")


@pytest.mark.skipif(STRACE is None, reason="strace is not installed (apt-get install strace)")
def test_validate_never_opens_a_file_outside_the_root(seeds, tmp_path: Path) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    victims = {
        name: outside / name for name in ("secret.json", "secret.parquet", "secret.urdf", "m.json")
    }
    for p in victims.values():
        p.write_text("{}")
    ds = tmp_path / "ds"
    shutil.copytree(seeds.dataset, ds)
    m = json.loads((ds / "manifest.json").read_text())
    # a stream table that is a symlink out of the root, and a path that climbs out
    ep = m["episodes"][0]
    name, st = next((n, s) for n, s in ep["streams"].items() if isinstance(s.get("path"), str))
    (ds / st["path"]).unlink()
    (ds / st["path"]).symlink_to(victims["secret.parquet"])
    m.setdefault("cameras", {})["evil"] = "../outside/secret.json"
    if isinstance(m.get("robot"), dict):
        (ds / m["robot"]["urdf"]).unlink()
        (ds / m["robot"]["urdf"]).symlink_to(victims["secret.urdf"])
    (ds / "manifest.json").write_text(json.dumps(m))
    exe = Path(sys.executable).with_name("robogs-validate")
    log = tmp_path / "strace.log"
    run = subprocess.run(
        [STRACE, "-f", "-qq", "-y", "-e", "trace=open,openat,openat2,creat", "-o", str(log),
         str(exe), str(ds), "--json"],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert run.returncode in (1, 2), run.stderr[-2000:]
    assert "Traceback" not in run.stderr
    trace = log.read_text(errors="replace")
    assert "openat(" in trace or "open(" in trace  # strace did record the run
    opened = [ln for ln in trace.splitlines() if str(outside) in ln]
    assert opened == [], opened[:5]
    # and the findings name the unsafe paths instead
    report = json.loads(run.stdout)
    assert "I007" in {f["code"] for f in report["findings"]}

    # control: with -y strace prints the file an fd really names, so opening the victim
    # through the in-root symlink does show the outside path
    probe = subprocess.run(
        [STRACE, "-f", "-qq", "-y", "-e", "trace=open,openat", "-o", str(log), "cat",
         str(ds / st["path"])],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert probe.returncode == 0
    assert str(victims["secret.parquet"]) in log.read_text(errors="replace")
