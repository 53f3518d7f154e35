"""``session_once.once_per_session``: one run per session, whichever worker asks first."""

from __future__ import annotations

import json
from pathlib import Path

from session_once import once_per_session


def _counting(calls: list[Path]):
    def run(folder: Path) -> dict:
        calls.append(folder)
        (folder / "made.txt").write_text("x")
        return {"n": len(calls), "folder": folder.name}

    return run


def _dump(r: dict) -> bytes:
    return json.dumps(r).encode()


def test_workers_share_one_run_and_read_the_same_result(tmp_path: Path):
    calls: list[Path] = []
    run = _counting(calls)
    base = {w: tmp_path / w for w in ("gw0", "gw1")}  # each worker's basetemp, one parent
    for b in base.values():
        b.mkdir()
    got = [once_per_session("thing", base[w], w, run, _dump, json.loads) for w in ("gw0", "gw1")]
    assert len(calls) == 1 and calls[0] == tmp_path / "thing"
    assert got[0] == got[1] == (tmp_path / "thing", {"n": 1, "folder": "thing"})
    assert (tmp_path / "thing" / "made.txt").is_file()
    assert not list(tmp_path.glob("*.tmp"))  # the result was renamed into place


def test_without_xdist_it_runs_in_the_session_folder(tmp_path: Path):
    calls: list[Path] = []
    folder, res = once_per_session("thing", tmp_path, "master", _counting(calls), _dump, json.loads)
    assert folder == tmp_path / "thing" and res["n"] == 1 and calls == [folder]
    assert not (tmp_path / "thing.result").exists()  # nothing stored: no other worker reads it
