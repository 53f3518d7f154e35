"""``robogs export mjcf``: the scene loads in MuJoCo from the written file, carries the
dataset's masses and friction, and replays a recorded pusher path within the noise.

The replay here uses MuJoCo directly (no robogs physics code): the initial box pose is the
median of each episode's first 5 pose samples, the pusher servos follow the recorded
``ee_poses`` smoothed (Savitzky-Golay, 41 samples = 80 ms at 500 Hz, cubic) and interpolated
onto the 1 ms grid, as ``docs/exports.md`` tells a user. Measured on these 9 pushes (seed 1,
nominal noise, 1 mm per axis): 1.93 mm RMS over all samples (2.87 mm without smoothing the
encoder noise; the mujoco engine through ``robogs.physics.prepare``: 2.03 mm), against
1.73 mm for the pose noise alone.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.signal import savgol_filter

from robogs.convert.export import export, get_exporter
from robogs.format.errors import DatasetExistsError, InputError


@pytest.fixture(scope="module")
def pushes(tmp_path_factory) -> tuple[Path, object]:
    """9 noisy pushes (nominal noise) written as a dataset whose physics.json holds the
    generator's friction (as a fit would write it)."""
    from robogs.synth.scenarios import make_scenario, write_scenario

    rec = make_scenario("none", seed=1, kinds=("push",), noise="nominal")
    rec.physics["objects"]["box"]["friction_dynamic"] = rec.meta["true_friction_dynamic"]
    path = tmp_path_factory.mktemp("mjcf") / "pushes"
    write_scenario(rec, path)
    return path, rec


def _yaw(q: np.ndarray) -> np.ndarray:
    return np.arctan2(
        2 * (q[..., 0] * q[..., 3] + q[..., 1] * q[..., 2]),
        1 - 2 * (q[..., 2] ** 2 + q[..., 3] ** 2),
    )


def _replay(model: mujoco.MjModel, tr, hz: float) -> np.ndarray:
    """Simulated box positions [N, 3] at the recorded object-pose stamps of one episode."""
    dt = model.opt.timestep
    t0 = min(int(tr.t_ns[0]), int(tr.ee_t_ns[0]))
    te = (tr.ee_t_ns - t0) * 1e-9
    ee = savgol_filter(tr.ee_pos, 41, 3, axis=0)
    grid = np.arange(0.0, (max(int(tr.t_ns[-1]), int(tr.ee_t_ns[-1])) - t0) * 1e-9 + dt, dt)
    p = np.stack([np.interp(grid, te, ee[:, a]) for a in range(3)], -1)
    yaw = np.interp(grid, te, np.unwrap(_yaw(tr.ee_quat)))
    data = mujoco.MjData(model)
    box, pusher = model.joint("box"), model.joint("pusher_x")
    qb, qp = box.qposadr[0], pusher.qposadr[0]
    pos0 = np.median(tr.object_pos[:5], axis=0)
    yaw0 = float(np.median(_yaw(tr.object_quat[:5])))
    data.qpos[qb : qb + 3] = (pos0[0], pos0[1], hz)
    data.qpos[qb + 3 : qb + 7] = (np.cos(yaw0 / 2), 0, 0, np.sin(yaw0 / 2))
    data.qpos[qp : qp + 3], data.qpos[qp + 3] = p[0], yaw[0]
    pos = np.empty((len(grid), 3))
    pos[0] = data.qpos[qb : qb + 3]
    for k in range(len(grid) - 1):
        data.ctrl[:4] = (*p[k], yaw[k])
        data.ctrl[4:7] = (p[k + 1] - p[k]) / dt
        data.ctrl[7] = (yaw[k + 1] - yaw[k]) / dt
        mujoco.mj_step(model, data)
        pos[k + 1] = data.qpos[qb : qb + 3]
    ts = (tr.t_ns - t0) * 1e-9
    return np.stack([np.interp(ts, grid, pos[:, a]) for a in range(3)], -1)


def test_mjcf_export_loads_carries_the_physics_and_replays_within_the_noise(
    pushes, tmp_path
) -> None:
    path, rec = pushes
    out = tmp_path / "scene_mjcf"
    report = export("mjcf", path, out)
    assert report.files == ["scene.xml"] and report.facts["objects"] == ["box"]
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    box = rec.physics["objects"]["box"]
    assert model.body("box").mass[0] == pytest.approx(box["mass_kg"], rel=1e-12)
    assert np.allclose(
        np.sort(model.body("box").inertia), np.sort(np.diag(box["inertia_kgm2"])), rtol=1e-9
    )
    k = next(
        i
        for i in range(model.npair)
        if {model.geom(model.pair_geom1[i]).name, model.geom(model.pair_geom2[i]).name}
        == {"box", "table"}
    )
    assert model.pair_friction[k, 0] == pytest.approx(box["friction_dynamic"])
    assert np.allclose(model.opt.gravity, rec.physics["gravity_mps2"])

    hz = 0.5 * box["size_m"][2]
    sq, n = 0.0, 0
    worst = 0.0
    for tr in rec.trajectories:
        err = _replay(model, tr, hz) - tr.object_pos
        e2 = np.sum(err**2, axis=-1)
        worst = max(worst, float(np.sqrt(e2.mean())))
        sq, n = sq + e2.sum(), n + len(e2)
    rms = np.sqrt(sq / n)
    noise_only = np.sqrt(3) * rec.meta["noise_levels"]["pos"]  # 3-D RMS of the pose noise alone
    assert rms < 1.25 * noise_only, (rms, noise_only)
    assert worst < 2.0 * noise_only, worst


def test_a_mesh_object_is_hulled_and_written_beside_the_scene(tmp_path) -> None:
    """A non-convex mesh asset becomes its convex hull under OUT/meshes, reported in the notes
    and the document; the exported scene loads and the object has the physics.json mass."""
    import trimesh

    from robogs.format.dataset import Dataset

    w = Dataset.create(tmp_path / "ds", name="meshy")
    ring = trimesh.creation.annulus(r_min=0.02, r_max=0.03, height=0.02, sections=64)
    w.write_bytes("assets/ring.stl", ring.export(file_type="stl"))
    w.set_asset("ring", kind="object", mesh="assets/ring.stl")
    inertia = (np.eye(3) * 5e-5).tolist()
    w.set_physics(
        {
            "objects": {
                "ring": {"equation": "rigid", "mass_kg": 0.15, "inertia_kgm2": inertia},
                "table": {"equation": "static", "plane_z_m": 0.0},
            }
        }
    )
    ds = w.commit()
    out = tmp_path / "ring_mjcf"
    report = export("mjcf", ds.root, out)
    assert report.files == ["scene.xml", "meshes/ring_hull.stl"]
    assert any("non-convex" in n for n in report.notes)
    assert "non-convex" in (out / "scene.xml").read_text()
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    assert model.body("ring").mass[0] == pytest.approx(0.15)
    hull = trimesh.load(out / "meshes" / "ring_hull.stl")
    assert hull.is_convex and hull.volume == pytest.approx(ring.convex_hull.volume, rel=1e-6)


def test_refusals(pushes, tmp_path) -> None:
    path, _ = pushes
    out = tmp_path / "o"
    out.mkdir()
    with pytest.raises(DatasetExistsError):
        export("mjcf", path, out)
    assert get_exporter("mjcf").output == "folder"
    from robogs.format.dataset import Dataset

    bare = Dataset.create(tmp_path / "bare", name="bare").commit()
    with pytest.raises(InputError, match="physics.json"):
        export("mjcf", bare.root, tmp_path / "x")
