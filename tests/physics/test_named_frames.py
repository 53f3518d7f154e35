"""Named frames (spec 1.1.0 ``robot.frames``), ``<capsule>`` URDF geometry, and wrench frames.

Oracles: hand-composed transforms, a mutated (non-rigid, cyclic, malformed) entry that must be
refused with its place, and the schema accepting old manifests unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from robogs.format.errors import FormatError
from robogs.format.named_frames import (
    NamedFrame,
    add_named_frames,
    frame_in_link,
    read_named_frames,
)
from robogs.format.schemas import schema_problems


def _T(xyz, yaw=0.0) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = xyz
    return T


def _manifest(tmp_path: Path, frames: dict | None) -> dict:
    """The manifest of a minimal dataset with a robot, written by the dataset writer."""
    from robogs.format.dataset import Dataset

    w = Dataset.create(tmp_path / "ds")
    with w:
        w.write_bytes("robot/robot.urdf", _CAP.format(r=0.01, l=0.04).encode())
        w.set_robot("robot/robot.urdf", base_link="base")
        ds = w.commit()
    man = json.loads(ds.manifest_path.read_text())
    if frames is not None:
        man["robot"] = {**man["robot"], "frames": frames}
    return man


def test_frames_compose_to_the_link():
    frames = {
        "flange": NamedFrame("flange", "tool0", _T([0, 0, 0.05], 0.3)),
        "tip": NamedFrame("tip", "flange", _T([0.01, 0, -0.1], -0.2)),
    }
    link, T = frame_in_link(frames, "tip", {"tool0", "base"})
    assert link == "tool0"
    np.testing.assert_allclose(T, _T([0, 0, 0.05], 0.3) @ _T([0.01, 0, -0.1], -0.2), atol=1e-15)
    assert frame_in_link(frames, "tool0", {"tool0"}) == ("tool0", pytest.approx(np.eye(4)))
    with pytest.raises(FormatError, match="not a robot link"):
        frame_in_link({"a": NamedFrame("a", "nowhere", np.eye(4))}, "a", {"tool0"})
    cyc = {"a": NamedFrame("a", "b", np.eye(4)), "b": NamedFrame("b", "a", np.eye(4))}
    with pytest.raises(FormatError, match="cycle"):
        frame_in_link(cyc, "a", {"tool0"})


def test_manifest_round_trip_and_schema(tmp_path: Path):
    man = _manifest(tmp_path, None)
    assert "frames" not in man["robot"] and not schema_problems("manifest", man)  # 1.0 datasets
    assert read_named_frames(man) == {}
    from robogs.format.dataset import Dataset

    assert Dataset.open(tmp_path / "ds").named_frames == {}
    add_named_frames(man, {"tip": NamedFrame("tip", "tool0", _T([0, 0, -0.1]), "/tf_static")})
    assert not schema_problems("manifest", man)
    (tip,) = read_named_frames(man).values()
    assert tip.parent == "tool0" and tip.source == "/tf_static"
    np.testing.assert_array_equal(tip.T_parent_frame, _T([0, 0, -0.1]))


@pytest.mark.parametrize(
    "entry,match",
    [
        ({"parent": "tool0", "T_parent_frame": (2 * np.eye(4)).tolist()}, "not a rigid"),
        ({"parent": "tool0", "T_parent_frame": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}, "4x4"),
        ({"T_parent_frame": np.eye(4).tolist()}, "parent"),
        ({"parent": "tip", "T_parent_frame": np.eye(4).tolist()}, "own parent"),
    ],
)
def test_bad_frames_are_refused_with_their_place(entry, match):
    with pytest.raises(FormatError, match=match) as exc:
        read_named_frames({"robot": {"urdf": "r.urdf", "frames": {"tip": entry}}})
    assert "robot/frames/tip" in str(exc.value)


def test_schema_refuses_a_malformed_frame(tmp_path: Path):
    man = _manifest(tmp_path, None)
    bad = {**man, "robot": {**man["robot"], "frames": {"tip": {"parent": "tool0",
           "T_parent_frame": [[1, 0, 0, 0]] * 3}}}}  # fmt: skip
    assert schema_problems("manifest", bad)
    tip = {"parent": "tool0", "T_parent_frame": np.eye(4).tolist(), "x": 1}
    extra = {**man, "robot": {**man["robot"], "frames": {"tip": tip}}}
    assert schema_problems("manifest", extra)


def test_converter_keeps_static_frames_that_hang_from_links():
    from robogs.convert.ingest.provenance import Provenance
    from robogs.convert.ingest.tf_ingest import TfIngest

    def ts(parent, child, xyz, q=(1.0, 0.0, 0.0, 0.0)):
        v = SimpleNamespace(x=xyz[0], y=xyz[1], z=xyz[2])
        r = SimpleNamespace(w=q[0], x=q[1], y=q[2], z=q[3])
        return SimpleNamespace(
            header=SimpleNamespace(frame_id=parent),
            child_frame_id=child,
            transform=SimpleNamespace(translation=v, rotation=r),
        )

    s = np.sqrt(0.5)
    msg = SimpleNamespace(
        transforms=[
            ts("tool0", "ft_sensor", (0, 0, 0.02), (s, 0, 0, s)),  # 90 deg about z
            ts("ft_sensor", "pusher_tip", (0, 0, 0.1)),
            ts("world", "camera_mount", (1, 0, 1)),  # not on the robot: not kept
            ts("base_link", "shoulder", (0, 0, 0.1)),  # a link: not a named frame
        ]
    )
    tf = TfIngest(Provenance("mcap", "x.mcap"), lambda t: True)
    tf.add_static("/tf_static", msg)
    tf.finalize()
    man: dict = {}
    kept = tf.keep_static_frames(man, {"base_link", "shoulder", "tool0"})
    tf.close()
    assert kept == ["ft_sensor", "pusher_tip"]
    frames = read_named_frames({"robot": {"urdf": "r.urdf", **man["robot"]}})
    link, T = frame_in_link(frames, "pusher_tip", {"base_link", "shoulder", "tool0"})
    assert link == "tool0"
    np.testing.assert_allclose(T, _T([0, 0, 0.02], np.pi / 2) @ _T([0, 0, 0.1]), atol=1e-12)


def test_wrench_frames_rotate_into_the_world():
    from robogs.physics.recording import _frame_rotation

    frames = {"ft": {"parent": "tool0", "T_parent_frame": _T([0, 0, 0.02], 0.5).tolist()}}
    ds = SimpleNamespace(manifest={"robot": {"base_link": "base", "frames": frames}})
    kind, R = _frame_rotation(ds, "ft", "tool0")
    assert kind == "ee"
    np.testing.assert_allclose(R, _T([0, 0, 0], 0.5)[:3, :3])
    assert _frame_rotation(ds, "tool0", "tool0")[0] == "ee"
    assert _frame_rotation(ds, "base", "tool0")[0] == "world"
    assert _frame_rotation(ds, "elsewhere", "tool0") is None


_CAP = (
    '<robot name="r"><link name="base"/><link name="tool0"><collision>'
    '<origin xyz="0 0 -0.1" rpy="1.5707963267948966 0 0"/>'
    '<geometry><capsule radius="{r}" length="{l}"/></geometry></collision></link>'
    '<joint name="j" type="revolute"><parent link="base"/><child link="tool0"/>'
    '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
)


def test_urdf_capsule_is_read_and_checked(tmp_path: Path):
    from robogs.format.urdf import capsules, load_urdf

    path = tmp_path / "r.urdf"
    path.write_text(_CAP.format(r=0.012, l=0.05))
    urdf = load_urdf(path, load_meshes=False)
    (cap,) = capsules(urdf)
    assert (cap.link, cap.kind, cap.radius, cap.length) == ("tool0", "collision", 0.012, 0.05)
    np.testing.assert_allclose(cap.origin[:3, 2], [0, -1, 0], atol=1e-12)  # axis z -> -y
    np.testing.assert_allclose(cap.origin[:3, 3], [0, 0, -0.1])
    assert capsules(urdf, "visual") == []
    for r, length in (("-0.01", "0.05"), ("0.01", "nan"), ("x", "0.05")):
        path.write_text(_CAP.format(r=r, l=length))
        with pytest.raises(FormatError, match="capsule needs radius") as exc:
            load_urdf(path, load_meshes=False)
        assert "tool0" in str(exc.value)
