"""The binding moves Gaussians exactly as closed-form poses say."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import torch
from scipy.spatial.transform import Rotation

from robogs.format import Dataset
from robogs.format.binding import Binding, rotate_sh
from robogs.format.render.sh import eval_sh
from robogs.format.splats import SplatSet

URDF = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <link name="upper"/>
  <link name="slider"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="upper"/>
    <origin xyz="0.1 0 0.2" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="upper"/><child link="slider"/>
    <origin xyz="0.3 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="10" velocity="1"/>
  </joint>
</robot>
"""


def _splats(means: np.ndarray, bind_id: np.ndarray, k: int = 1) -> SplatSet:
    n = len(means)
    rng = np.random.default_rng(1)
    q = rng.normal(size=(n, 4)).astype("f4")
    return SplatSet(
        means.astype("f4"),
        q / np.linalg.norm(q, axis=1, keepdims=True),
        np.full((n, 3), -5, "f4"),
        np.full(n, 3, "f4"),
        rng.normal(size=(n, k, 3)).astype("f4"),
        bind_id.astype("i4"),
        np.full(n, -1, "i4"),
        np.zeros((n, 2), "f4"),
        np.zeros(n, "f4"),
    )


@pytest.fixture()
def scene(tmp_path: Path) -> Dataset:
    t = np.arange(0, 1_000_000_001, 10_000_000, dtype=np.int64)  # 100 Hz for 1 s
    th = 0.8 * t * 1e-9  # rad, linear in time
    s = 0.2 * t * 1e-9  # m
    rng = np.random.default_rng(0)
    link_means = rng.normal(size=(40, 3)) * 0.1
    obj_means = rng.normal(size=(10, 3)) * 0.05 + [0.5, 0.0, 0.05]
    with Dataset.create(tmp_path / "ds") as w:
        w.write_text("robot/robot.urdf", URDF)
        w.set_robot("robot/robot.urdf", base_link="base")
        w.write_table(
            "ep/js.parquet",
            pa.table({"t_ns": t, "position.j1": th, "position.j2": s}),
            kind="joint_states",
        )
        yaw = 0.5 * t * 1e-9
        w.write_table(
            "ep/obj.parquet",
            pa.table(
                {
                    "t_ns": t,
                    "object": ["box"] * len(t),
                    "x": 0.5 + 0.1 * t * 1e-9,
                    "y": np.zeros(len(t)),
                    "z": np.full(len(t), 0.05),
                    "qw": np.cos(yaw / 2),
                    "qx": np.zeros(len(t)),
                    "qy": np.zeros(len(t)),
                    "qz": np.sin(yaw / 2),
                }
            ),
            kind="object_poses",
        )
        w.write_splats("robot/splats.ply", _splats(link_means, np.repeat([0, 1], 20), k=4))
        w.write_splats("assets/box/splats.ply", _splats(obj_means, np.zeros(10)))
        w.manifest["robot"]["splats"] = {
            "path": "robot/splats.ply",
            "kind": "3dgs",
            "sh_degree": 1,
            "targets": ["upper", "slider"],
            "rest": {"t_ns": 0, "joint_positions": {"j1": 0.0, "j2": 0.0}},
        }
        w.set_asset(
            "box",
            kind="object",
            splats={
                "path": "assets/box/splats.ply",
                "kind": "3dgs",
                "targets": ["box"],
                "rest": {"object_poses": {"box": [0.5, 0, 0.05, 1, 0, 0, 0]}},
            },
        )
        streams = {
            n: {"kind": k, "path": p, "stamp_source": "synthetic", "offset_ns": 0}
            for n, k, p in [
                ("joint_states", "joint_states", "ep/js.parquet"),
                ("object_poses", "object_poses", "ep/obj.parquet"),
            ]
        }
        w.add_episode("ep0", start_ns=0, end_ns=int(t[-1]), streams=streams)
        ds = w.commit()
    ds._truth = (link_means, obj_means)  # type: ignore[attr-defined]
    return ds


def _rz(a: float) -> np.ndarray:
    return Rotation.from_euler("z", a).as_matrix()


@pytest.mark.parametrize("t_ns", [0, 250_000_000, 555_000_000, 1_000_000_000])
def test_links_and_objects_follow_closed_form(scene: Dataset, t_ns: int) -> None:
    b = Binding(scene, dtype=torch.float64)
    g = b.pose(t_ns)
    link_means, obj_means = scene._truth  # type: ignore[attr-defined]
    link_means = link_means.astype("f4").astype(np.float64)
    obj_means = obj_means.astype("f4").astype(np.float64)
    th, s = 0.8 * t_ns * 1e-9, 0.2 * t_ns * 1e-9
    pivot = np.array([0.1, 0, 0.2])
    R = _rz(th)
    upper = (
        link_means[:20] - pivot
    ) @ R.T + pivot  # rotation about the joint axis through the pivot
    # slider: rotate with upper, then translate by s along upper's x axis
    slider = (link_means[20:] - pivot) @ R.T + pivot + s * R[:, 0]
    yaw = 0.5 * t_ns * 1e-9
    c0 = np.array([0.5, 0, 0.05])
    box = (obj_means - c0) @ _rz(yaw).T + c0 + [0.1 * t_ns * 1e-9, 0, 0]
    expect = np.concatenate([upper, slider, box])
    assert np.abs(g.means.numpy() - expect).max() < 1e-9
    # rotations compose: R_world(t) = R_motion · R_rest
    Rg = Rotation.from_quat(g.quats.numpy()[:, [1, 2, 3, 0]]).as_matrix()
    R0 = Rotation.from_quat(b.rest.quats.numpy()[:, [1, 2, 3, 0]]).as_matrix()
    assert np.abs(Rg[:40] - R @ R0[:40]).max() < 1e-9
    assert np.abs(Rg[40:] - _rz(yaw) @ R0[40:]).max() < 1e-9


def test_time_interpolation_between_samples(scene: Dataset) -> None:
    b = Binding(scene, dtype=torch.float64)
    g1 = b.pose(
        5_000_000
    )  # between the 0 and 10 ms samples: linear joint motion is reproduced exactly
    th = 0.8 * 5e-3
    link = scene._truth[0].astype("f4").astype(np.float64)[:20]  # type: ignore[attr-defined]
    pivot = np.array([0.1, 0, 0.2])
    assert np.abs(g1.means.numpy()[:20] - ((link - pivot) @ _rz(th).T + pivot)).max() < 1e-9


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_rotate_sh_matches_rotated_view(degree: int) -> None:
    torch.manual_seed(0)
    n = 7
    k = (degree + 1) ** 2
    sh = torch.randn(n, k, 3, dtype=torch.float64)
    R = torch.as_tensor(Rotation.random(n, random_state=3).as_matrix())
    d = torch.nn.functional.normalize(torch.randn(n, 3, dtype=torch.float64), dim=-1)
    rotated = rotate_sh(sh, R)
    lhs = eval_sh(rotated, d)
    rhs = eval_sh(sh, torch.einsum("nji,nj->ni", R, d))  # rest colour seen from Rᵀd
    assert (lhs - rhs).abs().max() < 1e-10


def test_rotate_sh_about_z_by_2pi_is_identity() -> None:
    sh = torch.randn(3, 16, 3, dtype=torch.float64)
    R = torch.as_tensor(_rz(2 * math.pi)).expand(3, 3, 3)
    assert (rotate_sh(sh, R) - sh).abs().max() < 1e-10


def test_fitted_joint_offsets_move_the_bound_gaussians(scene: Dataset) -> None:
    """physics.json joint offsets (robogs fit --add kinematic_offsets) reach the binding.

    Closed form: a zero offset dtheta on j1 cancels in the motion of ``upper`` (T(t) T(0)^-1),
    but the slider then translates along the x axis of Rz(th + dtheta), not of Rz(th).
    """
    d = 0.1
    with scene.edit() as w:
        w.set_physics(
            {
                "revision": 1,
                "objects": {},
                "joints": {"j1": {"offsets": {"dtheta_rad": d, "dd_m": 0.0, "da_m": 0.0}}},
            },
            note="fitted offsets",
        )
        ds = w.commit()
    t_ns = 750_000_000
    b = Binding(ds, dtype=torch.float64, owners=["robot"])
    g = b.pose(t_ns).means.numpy()
    assert "joint offsets of physics revision" in b.chain_note
    link_means = scene._truth[0].astype("f4").astype(np.float64)  # type: ignore[attr-defined]
    th, s = 0.8 * t_ns * 1e-9, 0.2 * t_ns * 1e-9
    pivot = np.array([0.1, 0, 0.2])
    upper = (link_means[:20] - pivot) @ _rz(th).T + pivot
    slider = (link_means[20:] - pivot) @ _rz(th).T + pivot + s * _rz(th + d)[:, 0]
    np.testing.assert_allclose(g[:20], upper, atol=1e-9)
    np.testing.assert_allclose(g[20:], slider, atol=1e-9)
    nominal = (link_means[20:] - pivot) @ _rz(th).T + pivot + s * _rz(th)[:, 0]
    assert np.min(np.linalg.norm(g[20:] - nominal, axis=1)) > 0.01  # 15 cm * 0.1 rad
