"""``robogs-validate`` options: ``--quick`` never loads torch; ``--stride``/``--scale``/``--full``/
``--rerender-budget`` reach the binding re-render."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import torch

from robogs.cli.main import validate_main
from robogs.format import rerender

REPO = Path(__file__).resolve().parents[2]


def test_quick_validation_does_not_import_torch(clean_root: Path) -> None:
    """A fresh interpreter: quick validation (all checks registered) leaves torch unimported;
    a binding check run afterwards does import it (the probe can see it)."""
    code = textwrap.dedent(
        f"""
        import contextlib, io, json, sys
        from robogs.format.checks import available_checks
        from robogs.cli.main import validate_main
        root = {str(clean_root)!r}
        with contextlib.redirect_stdout(io.StringIO()) as report:
            rc = validate_main([root, "--quick", "--no-progress", "--json"])
        probe = {{"rc": rc, "report": json.loads(report.getvalue()),
                  "torch": "torch" in sys.modules, "codes": list(available_checks())}}
        with contextlib.redirect_stdout(io.StringIO()):
            validate_main([root, "--select", "B009", "--no-progress", "--json"])
        probe["torch_after_b009"] = "torch" in sys.modules
        print(json.dumps(probe))
        """
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    probe = json.loads(out.stdout)
    assert probe["rc"] == 0
    summary = probe["report"]["summary"]
    assert summary["quick"] is True and summary["checks_run"] > 5
    assert "B005" in probe["codes"]  # the binding checks were imported and registered
    assert probe["torch"] is False
    assert probe["torch_after_b009"] is True


def _camera_frames(root: Path) -> int:
    m = json.loads((root / "manifest.json").read_text(encoding="utf-8"))
    rels = [
        st["frames"]
        for ep in m["episodes"]
        for st in ep["streams"].values()
        if st.get("kind") == "camera" and st.get("video")
    ]
    assert len(rels) == 1
    return pq.read_metadata(root / rels[0]).num_rows


@pytest.fixture
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_stride_and_scale_reach_the_binding_checks(
    clean_root: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    one_thread: None,
) -> None:
    """With ``--full``, B004 reports how many frames it compared: ceil(frames / stride); the
    re-render grid is the camera's resolution times ``--scale``. An unreachable PSNR floor makes
    B004 report the clean scene (which otherwise clears it)."""
    built: list[rerender.SceneRerenderer] = []

    class Recording(rerender.SceneRerenderer):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            built.append(self)

    monkeypatch.setattr(rerender, "SceneRerenderer", Recording)
    n = _camera_frames(clean_root)
    compared = {}
    for stride in (20, 45):
        argv = [str(clean_root), "--select", "B004", "--stride", str(stride), "--scale", "0.25"]
        argv += ["--full"]
        argv += ["--budget", "binding.psnr_min_db=100"]
        assert validate_main([*argv, "--json", "--no-progress"]) == 0  # a warning, not an error
        doc = json.loads(capsys.readouterr().out)
        assert doc["summary"]["notes"] == []  # --full leaves nothing out
        (finding,) = [f for f in doc["findings"] if f["code"] == "B004"]
        compared[stride] = int(re.search(r"over (\d+) frames", finding["message"]).group(1))
    assert compared == {20: len(range(0, n, 20)), 45: len(range(0, n, 45))}
    assert compared[20] > compared[45]
    assert len(built) == 2
    for rr in built:
        assert rr.scale == 0.25
        assert (rr.width, rr.height) == (round(rr.model.width / 4), round(rr.model.height / 4))


def test_rerender_budget_reaches_the_binding_checks(
    clean_root: Path, capsys: pytest.CaptureFixture[str], one_thread: None
) -> None:
    """A budget no frame fits in: the pass compares its minimum (6 frames), and the note in
    the text output and the JSON summary says so, with the budget and ``--full``."""
    n = _camera_frames(clean_root)
    argv = [str(clean_root), "--select", "B002", "--rerender-budget", "0.001", "--no-progress"]
    assert validate_main([*argv, "--json"]) == 0
    (note,) = json.loads(capsys.readouterr().out)["summary"]["notes"]
    assert f"labels compared on {rerender.MIN_PASS_FRAMES} of {n} frames" in note
    assert "the minimum counts, over the 0.001 s re-render budget" in note
    assert "--full for all" in note
    assert validate_main(argv) == 0
    text = " ".join(capsys.readouterr().out.split())  # rich wraps long lines
    assert "note: binding re-render" in text and f"{rerender.MIN_PASS_FRAMES} of {n} frames" in text


@pytest.mark.parametrize(
    "argv",
    [
        ["--rerender-budget", "0"],
        ["--rerender-budget", "inf"],
        ["--full", "--rerender-budget", "9"],
    ],
)
def test_bad_budget_options_are_usage_errors(
    tiny_root: Path, capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    assert validate_main([str(tiny_root), *argv, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "rerender-budget" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("flag", "value"), [("--stride", "0"), ("--scale", "5"), ("--stride", "x")]
)
def test_bad_speed_options_are_usage_errors(
    tiny_root: Path, capsys: pytest.CaptureFixture[str], flag: str, value: str
) -> None:
    assert validate_main([str(tiny_root), flag, value, "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"argument {flag}" in err and "Traceback" not in err


def test_threads_reach_torch_and_the_label_decoder(
    tiny_root: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``--threads N`` sizes torch's pool during the run and the label decoder; afterwards the
    process is as it was."""
    import robogs.format.validate as validate_module

    seen: dict[str, int] = {}
    real = validate_module.validate

    def spy(*args, **kwargs):
        seen["label_threads"] = kwargs["label_threads"]
        seen["torch"] = torch.get_num_threads()
        return real(*args, **kwargs)

    monkeypatch.setattr(validate_module, "validate", spy)
    before = torch.get_num_threads()
    for n in (1, 3):
        assert validate_main([str(tiny_root), "--threads", str(n), "--no-progress"]) == 0
        assert seen == {"label_threads": n, "torch": n}
        assert torch.get_num_threads() == before
