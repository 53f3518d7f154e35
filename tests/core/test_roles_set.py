"""``robogs roles`` and ``robogs roles set``: re-role a decoded generic stream.

The fixture is the synthetic scene (``robogs.synth.scene``) with its object poses moved, by
hand here, into a generic table shaped like a decoded ``geometry_msgs/PoseStamped`` topic
(``pose.position.x`` ... ``header.frame_id``): ``set`` must rebuild the object stream, value for
value, and the result must validate as the original does.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from robogs.cli.main import main
from robogs.format.validate import validate

TOPIC = "/mocap/box/pose"
GENERIC = "streams/mocap_box_pose"


def _digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def _rehash(root: Path, m: dict, *rels: str) -> None:
    for rel in rels:
        p = root / rel
        m["files"][rel] = {
            "sha256": hashlib.sha256(p.read_bytes()).hexdigest(),
            "size": p.stat().st_size,
            "rows": pq.ParquetFile(p).metadata.num_rows,
        }


def _add_generic(ds: Path, name: str, table: pa.Table, topic: str) -> None:
    """Declare ``table`` as the 500 Hz generic stream ``streams/<name>`` decoded from ``topic``."""
    m = json.loads((ds / "manifest.json").read_text())
    rel = f"episodes/ep000/streams/{name}.parquet"
    pq.write_table(table, ds / rel)
    m["episodes"][0]["streams"][f"streams/{name}"] = {
        "kind": "generic",
        "path": rel,
        "stamp_source": "log_time",
        "offset_ns": 0,
        "nominal_rate_hz": 500.0,
        "source": topic,
    }
    _rehash(ds, m, rel)
    (ds / "manifest.json").write_text(json.dumps(m, indent=2))


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(clean synthetic scene, the same with its object poses as a generic PoseStamped table)."""
    from robogs.synth.scene import synthesize

    base = tmp_path_factory.mktemp("roles")
    clean = synthesize(base / "clean", seed=0, size="small") and base / "clean"
    gen = base / "generic"
    shutil.copytree(clean, gen)
    m = json.loads((gen / "manifest.json").read_text())
    ep = m["episodes"][0]
    st = ep["streams"].pop("object_poses")
    tab = pq.read_table(gen / st["path"])
    rel = "episodes/ep000/streams/mocap_box_pose.parquet"
    (gen / rel).parent.mkdir(parents=True)
    n = tab.num_rows
    pq.write_table(
        pa.table(
            {
                "t_ns": tab.column("t_ns"),
                "header.seq": pa.array(np.arange(n), pa.int64()),
                "header.frame_id": pa.array(["world"] * n),
                **{f"pose.position.{a}": tab.column(a) for a in "xyz"},
                **{f"pose.orientation.{a}": tab.column(f"q{a}") for a in "xyzw"},
            }
        ),
        gen / rel,
    )
    (gen / st["path"]).unlink()
    del m["files"][st["path"]]
    ep["streams"][GENERIC] = {
        "kind": "generic",
        "path": rel,
        "stamp_source": st["stamp_source"],
        "offset_ns": 0,
        "nominal_rate_hz": st["nominal_rate_hz"],
        "source": TOPIC,
    }
    m.setdefault("provenance", {})["topics"] = {
        TOPIC: {"type": "my_msgs/msg/Tracked", "role": "generic", "reason": "custom type"}
    }
    _rehash(gen, m, rel)
    (gen / "manifest.json").write_text(json.dumps(m, indent=2))
    return clean, gen


def _errors(root: Path) -> set[str]:
    return validate(root, ignore=["binding"]).codes(min_severity="error")


def test_generic_pose_becomes_an_object_stream_that_validates(
    scene: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    clean, gen = scene
    ds = tmp_path / "ds"
    shutil.copytree(gen, ds)
    assert main(["roles", "set", str(ds), TOPIC, "object_pose:box"]) == 0
    out = capsys.readouterr().out
    assert "'object_poses'" in out and "frame world" in out
    m = json.loads((ds / "manifest.json").read_text())
    streams = m["episodes"][0]["streams"]
    assert GENERIC not in streams and streams["object_poses"]["kind"] == "object_poses"
    assert not (ds / "episodes/ep000/streams/mocap_box_pose.parquet").exists()
    want = pq.read_table(clean / "episodes/ep000/object_poses.parquet")
    got = pq.read_table(ds / streams["object_poses"]["path"])
    assert got.column("object").to_pylist() == want.column("object").to_pylist()
    for c in ("t_ns", "x", "y", "z", "qw", "qx", "qy", "qz"):
        np.testing.assert_allclose(got.column(c).to_numpy(), want.column(c).to_numpy(), atol=1e-12)
    assert m["provenance"]["topics"][TOPIC]["role"] == "object_pose:box"
    assert "was: custom type" in m["provenance"]["topics"][TOPIC]["reason"]
    assert _errors(ds) == _errors(clean) == set()


def test_roles_lists_streams_with_reasons(
    scene: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    _clean, gen = scene
    assert main(["roles", str(gen), "--json"]) == 0
    rows = {r["stream"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows[GENERIC]["kind"] == "generic" and rows[GENERIC]["reason"] == "custom type"
    assert rows["joint_states"]["role"] == "joint_states"


@pytest.mark.parametrize(
    ("target", "role", "needle"),
    [
        ("/no/such/topic", "object_pose:box", "no stream or topic '/no/such/topic'"),
        (TOPIC, "wrench:ft_sensor", "has no columns for role 'wrench:ft_sensor'"),
        ("joint_states", "ignore", "not a decoded generic table"),
        (TOPIC, "ee_pose:no_such_link", "link 'no_such_link' is not in the robot URDF"),
        (TOPIC, "teleport:box", "unknown role 'teleport:box'"),
    ],
)
def test_bad_requests_are_one_line_and_change_nothing(
    scene: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    target: str,
    role: str,
    needle: str,
) -> None:
    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    before = _digest(ds)
    assert main(["roles", "set", str(ds), target, role]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "\n" not in err and "Traceback" not in err
    assert _digest(ds) == before
    assert not list(tmp_path.glob(".ds*"))  # no temp folder or lock left behind


def test_ignore_removes_the_stream(scene: tuple[Path, Path], tmp_path: Path) -> None:
    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    assert main(["roles", "set", str(ds), GENERIC, "ignore"]) == 0
    m = json.loads((ds / "manifest.json").read_text())
    assert GENERIC not in m["episodes"][0]["streams"]
    assert "episodes/ep000/streams/mocap_box_pose.parquet" not in m["files"]
    assert m["provenance"]["topics"][TOPIC]["role"] == "ignore"


def test_generic_wrench_becomes_a_wrench_stream(scene: tuple[Path, Path], tmp_path: Path) -> None:
    """A decoded WrenchStamped-like table (``wrench.force.x`` ...) becomes ``wrenches``."""
    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    t = np.arange(1_000_000_000, 2_000_000_000, 2_000_000, dtype=np.int64)
    vals = {
        f"wrench.{g}.{a}": np.sin(t * 1e-9 + i)
        for i, (g, a) in enumerate((g, a) for g in ("force", "torque") for a in "xyz")
    }
    tab = pa.table({"t_ns": t, "header.frame_id": ["ft"] * t.size, **vals})
    _add_generic(ds, "netft_data", tab, "/netft_data")
    assert main(["roles", "set", str(ds), "/netft_data", "wrench:ft_sensor"]) == 0
    m = json.loads((ds / "manifest.json").read_text())
    st = m["episodes"][0]["streams"]["wrenches"]
    assert st["kind"] == "wrenches" and st["nominal_rate_hz"] == pytest.approx(500.0)
    got = pq.read_table(ds / st["path"])
    assert set(got.column("frame").to_pylist()) == {"ft_sensor"}
    for i, c in enumerate(("fx", "fy", "fz", "tx", "ty", "tz")):
        np.testing.assert_array_equal(got.column(c).to_numpy(), np.sin(t * 1e-9 + i))


def test_ee_pose_at_another_rate_gets_its_own_stream(
    scene: tuple[Path, Path], tmp_path: Path
) -> None:
    """120 Hz poses given to a link beside the 500 Hz ``ee_poses``: a stream of their own (one
    nominal rate per stream), the existing table untouched; the same link again is refused."""
    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    before_ee = (ds / "episodes/ep000/ee_poses.parquet").read_bytes()
    gen = pq.read_table(ds / "episodes/ep000/streams/mocap_box_pose.parquet")
    assert main(["roles", "set", str(ds), GENERIC, "ee_pose:wrist_3_link"]) == 0
    m = json.loads((ds / "manifest.json").read_text())
    st = m["episodes"][0]["streams"]["ee_poses/mocap_box_pose"]
    assert st["nominal_rate_hz"] == pytest.approx(120.0, rel=0.01) and st["source"] == TOPIC
    got = pq.read_table(ds / st["path"])
    assert set(got.column("link").to_pylist()) == {"wrist_3_link"}
    np.testing.assert_array_equal(
        got.column("x").to_numpy(), gen.column("pose.position.x").to_numpy()
    )
    assert (ds / "episodes/ep000/ee_poses.parquet").read_bytes() == before_ee


def test_ee_pose_at_the_same_rate_joins_the_ee_poses_table(
    scene: tuple[Path, Path], tmp_path: Path
) -> None:
    """500 Hz poses given to another link are merged into ``ee_poses``, rows in stamp order."""
    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    old = pq.read_table(ds / "episodes/ep000/ee_poses.parquet")
    cols = {f"pose.position.{a}": old.column(a) for a in "xyz"}
    cols.update({f"pose.orientation.{a}": old.column(f"q{a}") for a in "xyzw"})
    _add_generic(ds, "tcp", pa.table({"t_ns": old.column("t_ns"), **cols}), "/tcp")
    assert main(["roles", "set", str(ds), "/tcp", "ee_pose:wrist_3_link"]) == 0
    m = json.loads((ds / "manifest.json").read_text())
    st = m["episodes"][0]["streams"]["ee_poses"]
    got = pq.read_table(ds / st["path"])
    assert got.num_rows == 2 * old.num_rows
    assert set(got.column("link").to_pylist()) == {*old.column("link").to_pylist(), "wrist_3_link"}
    assert np.all(np.diff(got.column("t_ns").to_numpy()) >= 0)
    assert "/tcp" in st["source"] and "streams/tcp" not in m["episodes"][0]["streams"]
    before = _digest(ds)
    assert main(["roles", "set", str(ds), GENERIC, "ee_pose:wrist_3_link"]) == 2  # taken
    assert _digest(ds) == before


def test_a_concurrent_edit_is_refused_and_nothing_is_lost(
    scene: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    """Another command commits between our read and our edit: ours is refused (exit 2), theirs
    stays (optimistic concurrency of the writer)."""
    from robogs.format.dataset import Dataset as _Dataset

    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    edit = _Dataset.edit

    def edit_after_another(self):
        with edit(_Dataset.open(self.root)) as w:  # the other command
            w.manifest["name"] = "theirs"
            w.commit()
        return edit(self)

    monkeypatch.setattr(_Dataset, "edit", edit_after_another)
    assert main(["roles", "set", str(ds), TOPIC, "object_pose:box"]) == 2
    assert "changed on disk" in capsys.readouterr().err
    m = json.loads((ds / "manifest.json").read_text())
    assert m["name"] == "theirs" and GENERIC in m["episodes"][0]["streams"]


def test_roles_on_a_converted_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """End to end on the converter's own output: a ROS 1 bag with custom message types (written
    with rosbags in ``tests/converters/test_ingest_meaning.py``) converts to generic streams
    with reasons; a position-only custom pose cannot be an ee pose (one line, nothing changed);
    the custom marker topic can be ignored."""
    import importlib.util

    from robogs.convert.ingest.context import ConvertOptions
    from robogs.convert.ingest.convert import convert_path

    src = Path(__file__).resolve().parents[1] / "converters" / "test_ingest_meaning.py"
    spec = importlib.util.spec_from_file_location("_ingest_meaning", src)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    urdf = tmp_path / "planar.urdf"
    urdf.write_text(mod.URDF)
    mod._write_bag(tmp_path / "push.bag")
    out = tmp_path / "out"
    convert_path(tmp_path / "push.bag", out, options=ConvertOptions(urdf=urdf))
    capsys.readouterr()
    assert main(["roles", str(out), "--json"]) == 0
    rows = {r["stream"]: r for r in json.loads(capsys.readouterr().out)}
    for name in ("streams/robot_cartesian", "streams/vicon_markers"):
        assert rows[name]["kind"] == "generic" and rows[name]["reason"], rows[name]
    before = _digest(out)
    assert main(["roles", "set", str(out), "/robot/cartesian", "ee_pose:tool"]) == 2
    err = capsys.readouterr().err.strip()
    assert "has no columns for role 'ee_pose:tool'" in err and "\n" not in err
    assert _digest(out) == before
    assert main(["roles", "set", str(out), "/vicon/markers", "ignore"]) == 0
    m = json.loads((out / "manifest.json").read_text())
    assert "streams/vicon_markers" not in m["episodes"][0]["streams"]
    assert m["provenance"]["topics"]["/vicon/markers"]["role"] == "ignore"
