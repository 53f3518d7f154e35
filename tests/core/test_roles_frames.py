"""``robogs roles set`` moves poses into the world through static frames.

The fixture is the synthetic scene (``robogs.synth.scene``) with two named frames added to
``robot.frames``: ``mocap`` (a tracking system's world, fixed to ``base_link``) and ``marker``
(a tracked marker fixed to ``pusher_tip``). Its ``ee_poses`` are replaced by a generic
PoseStamped-like table of ``marker`` in ``mocap``, computed here with ``scipy.spatial.transform``
(``T_mocap_marker = T_world_mocap^-1 · T_world_tip · T_tip_marker``). ``set`` must give back the
original ``pusher_tip`` rows, and G008 must catch either offset when it is not applied.
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
from scipy.spatial.transform import Rotation

from robogs.cli.main import main
from robogs.format.validate import validate

TOPIC = "/mocap/marker/pose"


def _T(rotvec: list[float], xyz: list[float]) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = xyz
    return T


T_BASE_MOCAP = _T([0.0, 0.0, np.radians(30.0)], [0.2, -0.1, 0.05])
T_TIP_MARKER = _T([np.radians(90.0), 0.0, 0.0], [0.01, 0.02, 0.03])


def _poses(tab: pa.Table) -> np.ndarray:
    """[N, 4, 4] of an ``x y z qw qx qy qz`` table."""
    T = np.tile(np.eye(4), (tab.num_rows, 1, 1))
    q = np.stack([tab.column(c).to_numpy() for c in ("qx", "qy", "qz", "qw")], 1)
    T[:, :3, :3] = Rotation.from_quat(q).as_matrix()
    T[:, :3, 3] = np.stack([tab.column(c).to_numpy() for c in "xyz"], 1)
    return T


def _rehash(root: Path, m: dict, rel: str) -> None:
    p = root / rel
    m["files"][rel] = {
        "sha256": hashlib.sha256(p.read_bytes()).hexdigest(),
        "size": p.stat().st_size,
        "rows": pq.ParquetFile(p).metadata.num_rows,
    }


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(clean synthetic scene, the same with its ee_poses as ``marker`` in ``mocap``)."""
    from robogs.synth.scene import synthesize

    base = tmp_path_factory.mktemp("roles_frames")
    clean = base / "clean"
    synthesize(clean, seed=0, size="small")
    gen = base / "generic"
    shutil.copytree(clean, gen)
    m = json.loads((gen / "manifest.json").read_text())
    m["robot"]["frames"] = {
        "mocap": {"parent": "base_link", "T_parent_frame": T_BASE_MOCAP.tolist(), "source": "t"},
        "marker": {"parent": "pusher_tip", "T_parent_frame": T_TIP_MARKER.tolist()},
        "wrist_cam": {"parent": "wrist_3_link", "T_parent_frame": np.eye(4).tolist()},
    }
    ep = m["episodes"][0]
    st = ep["streams"].pop("ee_poses")
    tab = pq.read_table(gen / st["path"])
    T = np.linalg.inv(T_BASE_MOCAP)[None] @ _poses(tab) @ T_TIP_MARKER[None]
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()  # x, y, z, w
    rel = "episodes/ep000/streams/mocap_marker_pose.parquet"
    (gen / rel).parent.mkdir(parents=True)
    n = tab.num_rows
    pq.write_table(
        pa.table(
            {
                "t_ns": tab.column("t_ns"),
                "header.frame_id": pa.array(["mocap"] * n),
                **{f"pose.position.{a}": T[:, i, 3] for i, a in enumerate("xyz")},
                **{f"pose.orientation.{a}": q[:, i] for i, a in enumerate("xyzw")},
            }
        ),
        gen / rel,
    )
    (gen / st["path"]).unlink()
    del m["files"][st["path"]]
    ep["streams"]["streams/mocap_marker_pose"] = {
        "kind": "generic",
        "path": rel,
        "stamp_source": st["stamp_source"],
        "offset_ns": 0,
        "nominal_rate_hz": st["nominal_rate_hz"],
        "source": TOPIC,
    }
    _rehash(gen, m, rel)
    (gen / "manifest.json").write_text(json.dumps(m, indent=2))
    return clean, gen


def _copy(scene: tuple[Path, Path], tmp_path: Path) -> Path:
    ds = tmp_path / "ds"
    shutil.copytree(scene[1], ds)
    return ds


def _ee(root: Path) -> pa.Table:
    m = json.loads((root / "manifest.json").read_text())
    return pq.read_table(root / m["episodes"][0]["streams"]["ee_poses"]["path"])


def _g008(root: Path) -> list:
    return [f for f in validate(root, select=["G008"]).findings if f.code == "G008"]


def test_marker_in_mocap_becomes_the_links_pose(
    scene: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ds = _copy(scene, tmp_path)
    assert main(["roles", "set", str(ds), TOPIC, "ee_pose:marker"]) == 0
    out = capsys.readouterr().out
    assert "named frame 'mocap' on link 'base_link'" in out and "T_world_mocap applied" in out
    assert "'marker' is a named frame on link 'pusher_tip'" in out
    got, want = _ee(ds), _ee(scene[0])
    assert set(got.column("link").to_pylist()) == {"pusher_tip"}
    np.testing.assert_array_equal(got.column("t_ns").to_numpy(), want.column("t_ns").to_numpy())
    Tg, Tw = _poses(got), _poses(want)
    assert np.abs(Tg[:, :3, 3] - Tw[:, :3, 3]).max() < 1e-9
    assert np.abs(Tg[:, :3, :3] - Tw[:, :3, :3]).max() < 1e-9
    assert _g008(ds) == []
    rec = json.loads((ds / "manifest.json").read_text())["provenance"]["topics"][TOPIC]
    assert "named frame 'mocap'" in rec["frames"] and rec["role"] == "ee_pose:marker"


def _offset_mm(scene: tuple[Path, Path], T_left: np.ndarray, T_right: np.ndarray) -> float:
    """Largest distance (mm) of the tip from its pose read as ``T_left · T_tip · T_right``."""
    T = _poses(_ee(scene[0]))
    wrong = T_left[None] @ T @ T_right[None]
    return float(np.linalg.norm(wrong[:, :3, 3] - T[:, :3, 3], axis=1).max() * 1e3)


@pytest.mark.parametrize(
    ("role", "frame", "left", "right"),
    [
        # nothing applied: the marker in mocap read as the tip in the world
        ("ee_pose:pusher_tip", "world", np.linalg.inv(T_BASE_MOCAP), T_TIP_MARKER),
        # the mocap frame applied, the marker's offset on the tip not
        ("ee_pose:pusher_tip", None, np.eye(4), T_TIP_MARKER),
        # the marker's offset removed, the mocap frame not
        ("ee_pose:marker", "world", np.linalg.inv(T_BASE_MOCAP), np.eye(4)),
    ],
)
def test_a_frame_offset_not_applied_is_caught_by_g008(
    scene: tuple[Path, Path],
    tmp_path: Path,
    role: str,
    frame: str | None,
    left: np.ndarray,
    right: np.ndarray,
) -> None:
    ds = _copy(scene, tmp_path)
    assert main(["roles", "set", str(ds), TOPIC, role, *(["--frame", frame] if frame else [])]) == 0
    want = _offset_mm(scene, left, right)
    (f,) = _g008(ds)
    assert f.severity == "error" and want > 20.0
    assert f.value == pytest.approx(want, abs=0.5)  # FK of the clean scene is within 0.26 mm


@pytest.mark.parametrize(
    ("frame", "needle"),
    [
        ("viconworld", "unknown frame 'viconworld'"),
        ("wrist_cam", "frame 'wrist_cam' is not fixed in the world"),
    ],
)
def test_frames_that_cannot_be_applied_are_one_line_errors(
    scene: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    frame: str,
    needle: str,
) -> None:
    ds = _copy(scene, tmp_path)
    before = (ds / "manifest.json").read_text()
    assert main(["roles", "set", str(ds), TOPIC, "ee_pose:marker", "--frame", frame]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and "--frame" in err and "\n" not in err and "Traceback" not in err
    assert (ds / "manifest.json").read_text() == before


def test_frame_is_refused_for_a_wrench_role(
    scene: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ds = _copy(scene, tmp_path)
    assert main(["roles", "set", str(ds), TOPIC, "wrench:ft", "--frame", "mocap"]) == 2
    assert "--frame applies to pose roles" in capsys.readouterr().err
