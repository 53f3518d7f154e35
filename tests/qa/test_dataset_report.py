"""The HTML report carries the findings and the plots of a dataset."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from robogs.format import Dataset
from robogs.format.qa.dataset_report import write_dataset_report


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    from robogs.synth.scene import synthesize

    out = tmp_path_factory.mktemp("qa") / "scene"
    synthesize(out, seed=1, size="small", progress=False)
    return Dataset.open(out)


def test_report_has_findings_table_and_four_plots(scene: Dataset, tmp_path: Path) -> None:
    finding = {
        "code": "T003",
        "severity": "error",
        "location": {"stream": "joint_states", "t_ns": 5},
        "value": 12.5,
        "budget": 5.0,
        "unit": "ms",
        "message": "gap <b>",
        "hint": "re-record",
    }
    path = write_dataset_report(scene, [finding], tmp_path / "r.html")
    html = path.read_text()
    assert "1 errors, 0 warnings" in html
    assert "12.5 ms" in html and "5 ms" in html and "gap &lt;b&gt;" in html  # escaped, with units
    assert len(re.findall(r'src="data:image/png;base64,', html)) == 4
    for stream in ("joint_states", "object_poses", "camera/cam0"):
        assert f"<td>{stream}</td>" in html


def test_clean_report_says_so(scene: Dataset, tmp_path: Path) -> None:
    html = write_dataset_report(scene, [], tmp_path / "r.html").read_text()
    assert 'class="ok">0 errors, 0 warnings, 0 notes' in html
