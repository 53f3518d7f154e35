"""``robogs render``: a new joint trajectory through the binding into a dataset that validates.

Oracles: ``robogs-validate`` (binding group included) on the output, and the same validator
failing once the written joints no longer match the rendered pixels (mutation); boxes by brute
force over the label images; depth against the camera-frame distance of the replayed box;
orbit poses in closed form; bad trajectories by the row they name.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from robogs.cli.main import main
from robogs.format import Dataset
from robogs.format.errors import InputError
from robogs.format.images import decode_label_png
from robogs.format.kinematics import Chain
from robogs.format.render_trajectory import (
    episode_trajectory,
    orbit_poses,
    parse_edits,
    read_joint_trajectory,
)
from robogs.synth.scene import synthesize

START_NS, SPAN_NS = 2_000_000_000, 200_000_000


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("render") / "s"
    synthesize(out, seed=1, size="small", progress=False)
    return out


def _write_traj(scene: Path, path: Path, *, mutate=None) -> list[str]:
    """0.2 s of the recorded joints with a pan sweep and an elbow ramp never recorded."""
    js = Dataset.open(scene).episode().table("joint_states")
    t = js.column("t_ns").to_numpy()
    rows = np.flatnonzero((t >= START_NS) & (t <= START_NS + SPAN_NS))[::4]
    names = [c for c in js.column_names if c.startswith("position.")]
    q = np.stack([js.column(c).to_numpy()[rows] for c in names], -1)
    s = (t[rows] - START_NS) / SPAN_NS
    q[:, 0] += 0.3 * np.sin(np.pi * s)
    q[:, 2] += 0.15 * s
    header, body = (
        ["t_ns", *names],
        [[int(a), *map(float, b)] for a, b in zip(t[rows], q, strict=True)],
    )
    if mutate is not None:
        header, body = mutate(header, body)
    path.write_text("\n".join(",".join(map(str, r)) for r in [header, *body]) + "\n")
    return names


def _validate(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, dict]:
    capsys.readouterr()
    rc = main(["validate", str(path), "--json", "--no-progress"])
    return rc, json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def rendered(scene: Path) -> Path:
    traj = scene.parent / "traj.csv"
    _write_traj(scene, traj)
    out = scene.parent / "r"
    assert main(["render", str(scene), str(out), "--joints", str(traj), "--quiet"]) == 0
    return out


def test_rendered_episode_validates(rendered: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rc, rep = _validate(rendered, capsys)
    groups = rep["summary"]["groups"]
    assert rc == 0 and rep["summary"]["counts"]["error"] == 0, rep["findings"][:3]
    assert groups["binding"]["checks"] > 0 and groups["binding"]["skipped"] == 0
    ds = Dataset.open(rendered)
    ep = ds.episode()
    assert ds.manifest["provenance"]["rendered"]["episodes"][ep.id]["joints"] == "file traj.csv"
    frames = ep.frames("cam0").column("t_ns").to_numpy()
    assert np.all(np.diff(frames) == pytest.approx(1e9 / 30, abs=1))  # --fps 30 grid
    # scene assets are shared with the source, not rewritten
    src = Dataset.open(rendered.parent / "s")
    assert (
        ds.resolve("robot/splats.ply").stat().st_ino
        == src.resolve("robot/splats.ply").stat().st_ino
    ) or (ds.files["robot/splats.ply"]["sha256"] == src.files["robot/splats.ply"]["sha256"])


def test_validator_catches_joints_that_do_not_match_the_pixels(
    rendered: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    bad = tmp_path / "bad"
    shutil.copytree(rendered, bad)
    ds = Dataset.open(bad)
    js = ds.episode().table("joint_states")
    col = "position.shoulder_pan_joint"
    i = js.column_names.index(col)
    with ds.edit() as w:
        w.write_table(
            ds.episode().stream("joint_states")["path"],
            js.set_column(i, col, pa.array(js.column(col).to_numpy() + 0.25)),
            kind="joint_states",
        )
        w.commit()
    rc, rep = _validate(bad, capsys)
    codes = {f["code"] for f in rep["findings"] if f["severity"] == "error"}
    assert rc == 1 and any(c.startswith("B") for c in codes), codes


def test_boxes_and_depth(rendered: Path) -> None:
    ds = Dataset.open(rendered)
    ep = ds.episode()
    b2d = ep.table("boxes2d").to_pylist()
    labels = dict(ep.iter_labels("cam0"))
    assert len(labels) == len(ep.frames("cam0"))
    for k, lab in labels.items():
        want = set()
        for v in np.unique(lab[lab > 0]):
            rows, cols = np.nonzero(lab == v)
            want.add((int(v), cols.min(), rows.min(), cols.max() + 1, rows.max() + 1))
        got = {
            (r["label_id"], r["x_min"], r["y_min"], r["x_max"], r["y_max"])
            for r in b2d
            if r["frame_index"] == k
        }
        assert got == want
    # depth of the box label against the camera-frame z of the replayed box centre
    cam = ds.camera("cam0")
    T = np.linalg.inv(np.asarray(cam.T_world_cam))
    obj = ep.table("object_poses")
    dep = ep.table("depth/cam0")
    t0 = int(dep.column("t_ns")[0].as_py())
    d0 = decode_label_png(dep.column("png")[0].as_py()).astype(float) / 1000.0
    i = int(np.argmin(np.abs(obj.column("t_ns").to_numpy() - t0)))
    centre = np.array([obj.column(c)[i].as_py() for c in "xyz"])
    z = (T[:3, :3] @ centre + T[:3, 3])[2]
    box = labels[0] == 100
    assert box.sum() > 10
    assert abs(np.median(d0[box]) - z) < 0.06  # the visible faces lie within the box
    assert np.all(d0[labels[0] == 0] == 0)


def test_camera_behind_everything_warns(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cam = json.loads((scene / "cameras" / "cam0.json").read_text())
    T = np.asarray(cam["T_world_cam"])
    T[:3, 0] *= -1  # turn around: z and x flipped keeps a right-handed frame
    T[:3, 2] *= -1
    cam["T_world_cam"], cam["name"] = T.tolist(), "away"
    f = tmp_path / "away.json"
    f.write_text(json.dumps(cam))
    traj = tmp_path / "t.csv"
    _write_traj(scene, traj)
    capsys.readouterr()
    rc = main(
        [
            "render",
            str(scene),
            str(tmp_path / "o"),
            "--joints",
            str(traj),
            "--camera",
            str(f),
            "--fps",
            "15",
            "--quiet",
        ]
    )
    err = capsys.readouterr().err
    assert rc == 0
    import re

    m = re.search(r"warning: camera 'away' sees nothing in (\d+) of (\d+) frames", err)
    assert m is not None and m.group(1) == m.group(2) and int(m.group(1)) >= 3, err


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda h, b: ([*h[:-1], "position.gripper"], b), "unknown joint(s) gripper"),
        (lambda h, b: (h[:-1], [r[:-1] for r in b]), "missing joint(s) wrist_3_joint"),
        (lambda h, b: (h, [*b[:3], [b[1][0], *b[3][1:]], *b[4:]]), "not increasing at row 4"),
        (
            lambda h, b: (h, [*b[:2], [b[2][0], 9.0, *b[2][2:]], *b[3:]]),
            "row 3: shoulder_pan_joint = 9 is outside its limits",
        ),
    ],
)
def test_bad_trajectories_name_the_row(scene: Path, tmp_path: Path, mutate, message: str) -> None:
    path = tmp_path / "bad.csv"
    _write_traj(scene, path, mutate=mutate)
    chain = Chain.from_urdf(Dataset.open(scene).urdf(load_meshes=False))
    with pytest.raises(InputError) as exc:
        read_joint_trajectory(path, chain)
    assert message in str(exc.value)


def test_bad_trajectory_is_one_line_on_the_cli(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.csv"
    _write_traj(scene, path, mutate=lambda h, b: (h, [*b[:3], [b[1][0], *b[3][1:]], *b[4:]]))
    capsys.readouterr()
    assert main(["render", str(scene), str(tmp_path / "o"), "--joints", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "row 4" in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "o").exists()


def test_edits_and_parquet_input(scene: Path, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    ds = Dataset.open(scene)
    chain = Chain.from_urdf(ds.urdf(load_meshes=False))
    edits = parse_edits(["elbow_joint=+0.1", "elbow_joint=-0.02"], chain.joint_names)
    assert edits == {"elbow_joint": pytest.approx(0.08)}
    traj = episode_trajectory(ds.episode(), chain, edits)
    js = ds.episode().table("joint_states")
    j = chain.joint_names.index("elbow_joint")
    assert np.allclose(traj.q[:, j], js.column("position.elbow_joint").to_numpy() + 0.08)
    with pytest.raises(InputError, match="unknown joint 'knee'"):
        parse_edits(["knee=0.1"], chain.joint_names)
    with pytest.raises(InputError, match="outside its limits"):
        episode_trajectory(ds.episode(), chain, {"elbow_joint": 7.0})
    cols = {"t_ns": traj.t_ns[:5]} | {
        f"position.{n}": traj.q[:5, i] for i, n in enumerate(chain.joint_names)
    }
    pq.write_table(pa.table(cols), tmp_path / "t.parquet")
    back = read_joint_trajectory(tmp_path / "t.parquet", chain)
    assert np.array_equal(back.t_ns, traj.t_ns[:5]) and np.array_equal(back.q, traj.q[:5])


def test_orbit_poses_closed_form() -> None:
    eye, target = np.array([1.0, -0.5, 0.7]), np.array([0.3, 0.1, 0.2])
    t = np.linspace(0, 1e9, 9).astype(np.int64)
    pos, quat = orbit_poses(eye, target, 0.5, t)
    assert np.allclose(pos[0], eye)
    r = np.hypot(*(eye - target)[:2])
    assert np.allclose(np.hypot(*(pos - target)[:, :2].T), r) and np.allclose(pos[:, 2], eye[2])
    assert np.allclose(pos[-1][:2] - target[:2], -(eye - target)[:2])  # half a turn
    from robogs.format.frames import quat_to_matrix

    R = quat_to_matrix(quat)
    look = (target - pos) / np.linalg.norm(target - pos, axis=1, keepdims=True)
    assert np.allclose(R[:, :, 2], look, atol=1e-9)  # optical axis at the target
    assert np.all(R[:, 2, 1] < 0)  # image y points down in the world
