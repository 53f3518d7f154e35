"""URDF findings graded by consequence (G002-G004): massless frame links and CoMs left at the
link origin are notes; what breaks simulation or FK stays an error."""

from __future__ import annotations

from pathlib import Path

import pytest

from robogs.synth import mutations as mut

from .scope import validate


def _by_code(report, code: str) -> dict[str, str]:
    return {f.location.link: f.severity for f in report.findings if f.code == code}


def test_massless_fixed_base_is_a_note(clean_copy: Path) -> None:
    """The first <mass> of the synthetic UR5 is the base, bolted to the world."""
    mut.zero_link_mass(clean_copy)
    report = validate(clean_copy)
    assert report.codes(min_severity="error") == set(), [f.to_dict() for f in report.findings]
    assert _by_code(report, "G002") == {"base_link": "info"}


def test_massless_moving_body_is_an_error(clean_copy: Path) -> None:
    mut.zero_moving_link_mass(clean_copy)
    report = validate(clean_copy)
    assert _by_code(report, "G002") == {"shoulder_link": "error"}


@pytest.mark.realdata
def test_stock_ur5_urdf_has_notes_but_no_errors(tmp_path: Path, real_data: Path) -> None:
    """ros-industrial UR5: massless frames base, tool0, ee_link and wrist CoMs at the origin."""
    from robogs.synth.scene import synthesize

    urdf = real_data / "ur5" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf"
    ds = synthesize(tmp_path / "ur5", seed=3, size="small", urdf=urdf, progress=False)
    report = validate(ds)
    assert report.codes(min_severity="error") == set(), [f.to_dict() for f in report.findings]
    assert _by_code(report, "G002") == {"base": "info", "tool0": "info", "ee_link": "info"}
    assert _by_code(report, "G004") == {f"wrist_{i}_link": "info" for i in (1, 2, 3)}
    assert "G003" not in report.codes()
