"""Mutation tests: the clean fixture passes; each corruption trips exactly its check's code."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robogs.synth import mutations as mut

from .scope import validate


def _errors(report) -> set[str]:
    return report.codes(min_severity="error")


def test_clean_fixture_has_no_errors(clean_root: Path) -> None:
    report = validate(clean_root)
    assert _errors(report) == set(), [f.to_dict() for f in report.findings]
    assert all(r.status == "ran" for r in report.runs), report.runs


# (mutation, kwargs, expected code, budget overrides isolating the code)
CASES: list[tuple[str, dict, str, dict]] = [
    ("manifest_wrong_type", {}, "S001", {}),
    ("camera_negative_focal", {}, "S002", {}),
    ("table_wrong_dtype", {}, "S003", {}),
    ("set_spec_version", {"version": "2.0.0"}, "S005", {}),
    ("unknown_budget", {}, "S006", {}),
    ("rename_object", {}, "S007", {}),
    ("delete_file", {}, "I001", {}),
    ("add_extra_file", {}, "I002", {}),
    ("append_to_file", {}, "I003", {}),
    ("edit_file", {}, "I004", {}),
    ("row_count_mismatch", {}, "I005", {}),
    ("truncate_parquet", {}, "I006", {}),
    ("escape_path", {}, "I007", {}),
    ("dangling_reference", {}, "I008", {}),
    ("reverse_stamps", {}, "T001", {}),
    ("wrong_nominal_rate", {}, "T002", {}),
    ("gap_in_stream", {}, "T003", {}),
    ("jitter_camera_stamps", {}, "T005", {}),
    ("early_frame", {}, "T006", {"time.jitter_p99_ms": 1000.0}),
    ("late_start", {}, "T007", {}),
    ("shrink_episode", {}, "T008", {}),
    ("drop_video_frame", {}, "T009", {}),
    ("label_unknown_frame", {}, "T010", {}),
    ("box2d_stamp_offset", {}, "T011", {}),
    ("corrupt_urdf", {}, "G001", {}),
    ("zero_moving_link_mass", {}, "G002", {}),
    ("negative_inertia", {}, "G003", {}),
    ("com_outside_link", {}, "G004", {}),
    ("scale_link_mesh_to_mm", {}, "G005", {}),
    ("scale_asset_mesh_to_mm", {}, "G006", {}),
    ("joint_beyond_limit", {}, "G007", {}),
    ("offset_ee_pose", {"mm": 5.0}, "G008", {}),
    ("offset_box2d", {"px": 5.0}, "G009", {}),
    ("shrink_box3d", {}, "G010", {}),
    ("sink_object", {}, "G011", {}),
    ("physics_bad_inertia", {}, "P001", {}),
    ("friction_inverted", {}, "P002", {}),
    ("com_outside_object", {}, "P004", {}),
]


@pytest.mark.parametrize(("name", "kwargs", "code", "budgets"), CASES, ids=[c[0] for c in CASES])
def test_mutation_trips_exactly_its_code(
    clean_copy: Path, name: str, kwargs: dict, code: str, budgets: dict
) -> None:
    mut.MUTATIONS[name](clean_copy, **kwargs)
    report = validate(clean_copy, budgets=budgets)
    assert _errors(report) == {code}, [f.to_dict() for f in report.findings]


def test_dropped_frame_is_a_dropped_sample_warning(clean_copy: Path) -> None:
    mut.drop_frame(clean_copy)
    report = validate(clean_copy)
    assert _errors(report) == set(), [f.to_dict() for f in report.findings]
    t004 = [f for f in report.findings if f.code == "T004"]
    assert len(t004) == 1 and t004[0].value == 1 and t004[0].location.stream.startswith("camera")


def test_newer_minor_version_is_a_warning(clean_copy: Path) -> None:
    mut.set_spec_version(clean_copy, "1.9.0")
    report = validate(clean_copy)
    assert _errors(report) == set()
    assert "S004" in report.codes(min_severity="warning")


def test_newer_minor_version_fields_are_warnings_and_checks_still_run(clean_copy: Path) -> None:
    mut.set_spec_version(clean_copy, "1.9.0")
    m = json.loads((clean_copy / "manifest.json").read_text())
    m["calibration_report"] = {"added_in": "1.9"}
    (clean_copy / "manifest.json").write_text(json.dumps(m))
    mut.gap_in_stream(clean_copy)
    report = validate(clean_copy)
    assert _errors(report) == {"T003"}
    assert {"S001", "S004"} <= report.codes(min_severity="warning")


def test_rigid_object_without_inertia_is_a_warning(clean_copy: Path) -> None:
    mut.drop_object_inertia(clean_copy)
    report = validate(clean_copy)
    assert _errors(report) == set()
    assert "P003" in report.codes(min_severity="warning")


def test_camera_shift_is_detected_from_robot_motion(clean_copy: Path) -> None:
    """20 ms late camera stamps: T012 fits the lag of the robot-link label boxes behind the joints."""
    mut.shift_camera_stamps(clean_copy, ms=20.0)
    report = validate(clean_copy)
    assert _errors(report) == {"T012"}, [f.to_dict() for f in report.findings]
    (f,) = [f for f in report.findings if f.code == "T012"]
    assert f.value == pytest.approx(20.0, abs=5.0)


def test_camera_shift_beyond_episode_end_is_detected_from_stamps(tiny_copy: Path) -> None:
    """Without robot labels only the stamps can tell: the last frame now lies after the episode end."""
    mut.shift_camera_stamps(tiny_copy, ms=20.0)
    report = validate(tiny_copy)
    assert _errors(report) == {"T008"}, [f.to_dict() for f in report.findings]
    found = {f.location.stream: f.value for f in report.findings if f.code == "T008"}
    assert found == {
        "camera/cam0": pytest.approx(20.0, abs=0.01),
        "boxes2d": pytest.approx(20.0, abs=0.01),
    }


def test_tiny_scene_is_clean(tiny_root: Path) -> None:
    report = validate(tiny_root)
    assert report.findings == [], [f.to_dict() for f in report.findings]


def test_mutation_without_target_fails_loudly(tmp_path: Path, clean_root: Path) -> None:
    import shutil

    ds = tmp_path / "ds"
    shutil.copytree(clean_root, ds)
    mut.add_extra_file(ds)
    with pytest.raises(mut.NothingToCorrupt):
        mut.add_extra_file(ds)
    with pytest.raises(mut.NothingToCorrupt):
        mut.reverse_stamps(ds, kind="wrenches")
