"""``robogs render --simulate`` and ``--format lerobot``.

Oracles: the physics loop's own ``compare`` residual (the simulated box follows the recorded one
as closely as the fitted model does), a pusher lifted clear of the box (the box must not move),
the LeRobot layout read back with pyarrow and ``robogs convert`` (rendered episodes marked).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from robogs.cli.main import main
from robogs.cli.render_cmd import simulate_objects
from robogs.format import Dataset
from robogs.format.kinematics import Chain
from robogs.format.render_trajectory import episode_trajectory
from robogs.synth.scene import synthesize

START_NS, SPAN_NS = 2_000_000_000, 200_000_000


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("render_sim") / "s"
    synthesize(out, seed=1, size="small", progress=False)
    return out


def _box(ep) -> tuple[np.ndarray, np.ndarray]:
    tab = ep.table("object_poses")
    m = np.asarray(tab.column("object").to_pylist()) == "box"
    return tab.column("t_ns").to_numpy()[m], np.stack(
        [tab.column(c).to_numpy()[m] for c in ("x", "y", "z")], -1
    )


def _short_traj(scene: Path, path: Path) -> None:
    js = Dataset.open(scene).episode().table("joint_states")
    t = js.column("t_ns").to_numpy()
    rows = np.flatnonzero((t >= START_NS) & (t <= START_NS + SPAN_NS))[::4]
    names = [c for c in js.column_names if c.startswith("position.")]
    body = [[int(t[r]), *(float(js.column(c).to_numpy()[r]) for c in names)] for r in rows]
    path.write_text("\n".join(",".join(map(str, r)) for r in [["t_ns", *names], *body]) + "\n")


def test_simulated_box_matches_the_recorded_within_a_few_noise_floors(scene: Path) -> None:
    from robogs.physics.api import compare

    ds = Dataset.open(scene)
    ep = ds.episode()
    chain = Chain.from_urdf(ds.urdf(load_meshes=False))
    traj = episode_trajectory(ep, chain, {})  # the recorded joint trajectory, unedited
    poses, desc, _ = simulate_objects(ds, ep, traj)
    t_sim, p_sim, q_sim = poses["box"]
    assert np.array_equal(t_sim, traj.t_ns) and "simulated by the planar engine" in desc
    assert np.allclose(np.linalg.norm(q_sim, axis=-1), 1.0)
    t_rec, p_rec = _box(ep)
    inside = (t_rec >= t_sim[0]) & (t_rec <= t_sim[-1])
    at = np.stack([np.interp(t_rec[inside], t_sim, p_sim[:, k]) for k in range(3)], -1)
    rms_mm = float(np.sqrt(np.mean(np.sum((at - p_rec[inside]) ** 2, -1)))) * 1e3
    moved_mm = float(np.linalg.norm(p_rec[inside][-1] - p_rec[inside][0])) * 1e3
    res = compare(ds, mask_frames=0)  # the refitted model's residual and the data's noise floor
    ref, floor = res.rms_mm, res.noise_floor_mm
    print(f"simulated vs recorded {rms_mm:.2f} mm, compare {ref:.2f} mm, floor {floor:.2f} mm")
    assert moved_mm > 20 * rms_mm  # the box is pushed: staying put would not pass
    # the rollout uses physics.json as stored (no refit of friction or initial pose), so it
    # may leave more than compare's refitted residual, but only a few noise floors more
    assert rms_mm <= ref + 3.0 * floor


def test_pusher_lifted_clear_leaves_the_box_at_rest(scene: Path) -> None:
    ds = Dataset.open(scene)
    ep = ds.episode()
    chain = Chain.from_urdf(ds.urdf(load_meshes=False))
    lifted = episode_trajectory(ep, chain, {"shoulder_lift_joint": 0.3})  # tip z >= 0.16 m
    poses, _, _ = simulate_objects(ds, ep, lifted)
    _, p, _ = poses["box"]
    assert np.abs(p - p[0]).max() < 1e-6  # m; the replay would move it by centimetres
    t_rec, p_rec = _box(ep)
    assert np.linalg.norm(p_rec[-1] - p_rec[0]) > 0.02


def test_cli_simulate_writes_the_simulated_poses(scene: Path) -> None:
    traj = scene.parent / "short.csv"
    _short_traj(scene, traj)
    out = scene.parent / "sim"
    assert (
        main(["render", str(scene), str(out), "--joints", str(traj), "--simulate", "--quiet"]) == 0
    )
    ds = Dataset.open(out)
    ep = ds.episode()
    assert "simulated by the planar engine" in ep.streams["object_poses"]["source"]
    src = Dataset.open(scene)
    chain = Chain.from_urdf(src.urdf(load_meshes=False))
    from robogs.format.render_trajectory import read_joint_trajectory

    want, _, _ = simulate_objects(src, src.episode(), read_joint_trajectory(traj, chain))
    t, p = _box(ep)
    assert np.array_equal(t, want["box"][0]) and np.abs(p - want["box"][1]).max() < 1e-12
    prov = ds.manifest["provenance"]["rendered"]["episodes"][ep.id]
    assert prov["objects"].startswith("simulated by the planar engine")


def test_render_straight_to_lerobot_mixed_with_recorded(scene: Path, tmp_path: Path) -> None:
    from robogs.convert.ingest.convert import convert_path

    traj = tmp_path / "short.csv"
    _short_traj(scene, traj)
    lr = tmp_path / "lr"
    args = ["render", str(scene), str(lr), "--joints", str(traj), "--format", "lerobot"]
    assert main([*args, "--with-recorded", "--quiet"]) == 0
    info = json.loads((lr / "meta" / "info.json").read_text())
    eps = pq.read_table(lr / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    assert info["codebase_version"] == "v3.0" and info["total_episodes"] == 2
    src = {e["robogs/episode_id"]: e["robogs/source"] for e in eps}
    assert src == {"ep000": "recorded", "render000": "rendered"}
    assert info["robogs"]["episodes"]["render000"]["source"] == "rendered"
    assert "observation.images.cam0.panoptic" in info["features"]
    # the rendered episode's frames: 30 fps over the 0.2 s trajectory
    rendered = next(e for e in eps if e["robogs/episode_id"] == "render000")
    t = np.loadtxt(traj, delimiter=",", skiprows=1, usecols=0, dtype=np.int64)
    assert rendered["length"] == (t[-1] - t[0]) * 30 // 1_000_000_000 + 1
    assert not list(tmp_path.glob(".lr.render-*"))  # the temporary dataset is gone
    back = convert_path(lr, tmp_path / "back")
    assert set(back.manifest["provenance"]["rendered"]["episodes"]) == {"render000"}
    assert sorted(e.id for e in back.episodes) == ["ep000", "render000"]
    # without --with-recorded: only the rendered episode; an existing OUT needs --force
    assert main([*args, "--quiet"]) == 2
    assert main([*args, "--quiet", "--force"]) == 0
    info = json.loads((lr / "meta" / "info.json").read_text())
    assert info["total_episodes"] == 1 and list(info["robogs"]["episodes"]) == ["render000"]


def test_simulate_without_a_rigid_object_is_one_clear_error(
    scene: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    bad = tmp_path / "static"
    shutil.copytree(scene, bad)
    ds = Dataset.open(bad)
    doc = ds.physics()
    doc["objects"]["box"]["equation"] = "static"
    with ds.edit() as w:
        w.set_physics(doc)
        w.commit()
    traj = tmp_path / "short.csv"
    _short_traj(scene, traj)
    capsys.readouterr()
    args = ["render", str(bad), str(tmp_path / "o"), "--joints", str(traj), "--simulate"]
    assert main([*args, "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exactly one rigid object" in err[0]
    assert not (tmp_path / "o").exists()
