"""Splat PLY export: the plain 3DGS layout, values at rest and posed by an independent FK."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import plyfile
import pytest

from robogs.cli.main import main
from robogs.convert.export import export
from robogs.format import Dataset, InputError

try:
    from .test_export_data import build_tiny_dataset
except ImportError:
    from test_export_data import build_tiny_dataset

# graphdeco-inria/gaussian-splatting GaussianModel.construct_list_of_attributes() for SH degree 1
REFERENCE_3DGS_DEG1 = (
    ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    + [f"f_rest_{i}" for i in range(9)]
    + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Dataset:
    return build_tiny_dataset(tmp_path_factory.mktemp("ply") / "tiny")


def _vertex(path: Path) -> tuple[plyfile.PlyData, np.ndarray]:
    ply = plyfile.PlyData.read(str(path))
    return ply, ply["vertex"].data


def test_layout_is_the_reference_3dgs_layout(tiny: Dataset, tmp_path: Path) -> None:
    export("ply", tiny, tmp_path / "s.ply")
    ply, v = _vertex(tmp_path / "s.ply")
    assert [e.name for e in ply.elements] == ["vertex"]
    assert ply.byte_order == "<" and not ply.text
    props = ply["vertex"].properties
    assert [p.name for p in props] == REFERENCE_3DGS_DEG1
    assert {p.val_dtype for p in props} == {"f4"}
    assert len(v) == 300 + 80


def test_rest_values_equal_the_stored_splats(tiny: Dataset, tmp_path: Path) -> None:
    export("ply", tiny, tmp_path / "s.ply")
    _, v = _vertex(tmp_path / "s.ply")
    robot, box = tiny.splats("robot"), tiny.splats("box")
    r, b = v[:300], v[300:]
    np.testing.assert_array_equal(np.stack([r["x"], r["y"], r["z"]], -1), robot.means)
    np.testing.assert_array_equal(np.stack([r[f"rot_{i}"] for i in range(4)], -1), robot.quats)
    np.testing.assert_array_equal(r["opacity"], robot.opacity_logits)
    # f_rest is channel-major: index c * (K - 1) + j holds coefficient j + 1 of channel c
    for c in range(3):
        for j in range(3):
            np.testing.assert_array_equal(r[f"f_rest_{c * 3 + j}"], robot.sh[:, 1 + j, c])
        np.testing.assert_array_equal(r[f"f_dc_{c}"], robot.sh[:, 0, c])
    # the 2DGS box keeps its two scales, gets a flat third one, and zero-padded SH
    np.testing.assert_array_equal(np.stack([b["scale_0"], b["scale_1"]], -1), box.log_scales)
    np.testing.assert_allclose(b["scale_2"], math.log(1e-7), rtol=1e-6)
    assert all(np.all(b[f"f_rest_{i}"] == 0) for i in range(9))
    for nm in ("nx", "ny", "nz"):
        assert np.all(v[nm] == 0)


def _fk_yourdfpy(ds: Dataset, q: dict[str, float], link: str) -> np.ndarray:
    urdf = ds.urdf(load_meshes=False)
    urdf.update_cfg(q)
    return np.asarray(urdf.get_transform(link, urdf.base_link))


def test_posed_export_matches_an_independent_pose(tiny: Dataset, tmp_path: Path) -> None:
    ep = tiny.episode()
    poses = ep.table("object_poses")
    t = int(poses.column("t_ns")[5].as_py())  # a pose sample: no slerp needed for the box
    export("ply", tiny, tmp_path / "p.ply", t_ns=t)
    _, v = _vertex(tmp_path / "p.ply")
    js = ep.table("joint_states")
    tj = js.column("t_ns").to_numpy()
    q_t = {
        j: float(np.interp(t - tj[0], tj - tj[0], js.column(f"position.{j}").to_numpy()))
        for j in ("j1", "j2")
    }
    q_0 = {"j1": 0.0, "j2": 0.0}
    robot = tiny.splats("robot")
    targets = tiny.splat_entry("robot")["targets"]
    got = np.stack([v["x"], v["y"], v["z"]], -1).astype(np.float64)
    for b, link in enumerate(targets):
        sel = np.flatnonzero(robot.bind_id == b)
        M = _fk_yourdfpy(tiny, q_t, link) @ np.linalg.inv(_fk_yourdfpy(tiny, q_0, link))
        want = robot.means[sel].astype(np.float64) @ M[:3, :3].T + M[:3, 3]
        np.testing.assert_allclose(got[sel], want, atol=2e-6, err_msg=link)
    row = {c: poses.column(c)[5].as_py() for c in ("x", "y", "z", "qw", "qx", "qy", "qz")}
    w, x, y, z = row["qw"], row["qx"], row["qy"], row["qz"]
    R = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    ) / (w * w + x * x + y * y + z * z)
    box = tiny.splats("box")
    rest = np.array([0.3, 0.0, 0.05])  # rest pose of the box: identity rotation
    want = (box.means.astype(np.float64) - rest) @ R.T + np.array([row["x"], row["y"], row["z"]])
    np.testing.assert_allclose(got[300:], want, atol=2e-6)


def test_with_binding_appends_columns_and_targets(tiny: Dataset, tmp_path: Path) -> None:
    export("ply", tiny, tmp_path / "b.ply", with_binding=True)
    ply, v = _vertex(tmp_path / "b.ply")
    names = [p.name for p in ply["vertex"].properties]
    assert names == REFERENCE_3DGS_DEG1 + [
        "bind_id",
        "bind_face",
        "bind_u",
        "bind_v",
        "bind_offset",
    ]
    targets = json.loads(
        next(c for c in ply.comments if c.startswith("robogs_targets "))[len("robogs_targets ") :]
    )
    assert targets == ["base_link", "link1", "link2", "tool", "box"]
    np.testing.assert_array_equal(v["bind_id"][:300], tiny.splats("robot").bind_id)
    assert np.all(v["bind_id"][300:] == 4)
    assert not any(n.startswith(("scale_", "rot")) for n in names[len(REFERENCE_3DGS_DEG1) :])


def test_no_splats_is_a_clear_error(tiny: Dataset, tmp_path: Path) -> None:
    shutil.copytree(tiny.root, tmp_path / "copy")
    with Dataset.open(tmp_path / "copy").edit() as w:
        w.manifest["robot"].pop("splats")
        w.manifest["assets"]["box"].pop("splats")
        w.remove("robot/splats.ply")
        w.remove("assets/box/splats.ply")
        bare = w.commit()
    out = tmp_path / "o"
    out.mkdir()
    with pytest.raises(InputError, match="no splats"):
        export("ply", bare, out / "n.ply")
    assert list(out.iterdir()) == []  # neither the output nor a temporary file is left


def _reference_3dgs_load_ply(path: Path, max_sh_degree: int) -> dict[str, np.ndarray]:
    """An oracle written after graphdeco-inria/gaussian-splatting ``GaussianModel.load_ply``:
    it sorts the ``f_rest_*`` properties by index, asserts their count is
    ``3 (max_sh_degree + 1)^2 - 3`` and reshapes them channel-major to [N, 3, K - 1]."""
    el = plyfile.PlyData.read(str(path)).elements[0]
    names = sorted(
        (p.name for p in el.properties if p.name.startswith("f_rest_")),
        key=lambda n: int(n.split("_")[-1]),
    )
    assert len(names) == 3 * (max_sh_degree + 1) ** 2 - 3
    n = len(el.data)
    rest = np.stack([np.asarray(el[nm]) for nm in names], 1).reshape(n, 3, -1)
    dc = np.stack([np.asarray(el[f"f_dc_{i}"]) for i in range(3)], 1)
    return {"dc": dc, "rest": rest}


def test_sh_degree_3_pads_f_rest_for_the_reference_loader(tiny: Dataset, tmp_path: Path) -> None:
    export("ply", tiny, tmp_path / "d1.ply")
    with pytest.raises(AssertionError):  # degree 1 data, the loader's default degree is 3
        _reference_3dgs_load_ply(tmp_path / "d1.ply", 3)
    assert (
        main(["export", "ply", str(tiny.root), str(tmp_path / "d3.ply"), "--sh-degree", "3"]) == 0
    )
    got = _reference_3dgs_load_ply(tmp_path / "d3.ply", 3)
    assert got["rest"].shape == (380, 3, 15)
    robot = tiny.splats("robot")
    np.testing.assert_array_equal(got["dc"][:300], robot.sh[:, 0, :])
    # bands 1 are the data (channel-major), bands 2 and 3 are zero; the 2DGS box is all zero
    np.testing.assert_array_equal(got["rest"][:300, :, :3], robot.sh[:, 1:4, :].transpose(0, 2, 1))
    assert not got["rest"][:300, :, 3:].any() and not got["rest"][300:].any()
    with pytest.raises(InputError, match="below the splats' SH degree 1"):
        export("ply", tiny, tmp_path / "d0.ply", sh_degree=0)
