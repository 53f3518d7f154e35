"""The structure-from-motion recipe of docs/reconstruct.md, run as written at a small size.

The shell block after the ``recipe`` marker runs line by line in an empty folder; only the
training size changes (see the doc). The oracles are the sample's ground truth and a recorded
episode: after the recipe the stored camera centres are within 1 % of the scene size of the
true ones and the rotations within 1 degree, in the robot's world (no fit to the truth); the
dataset validates without errors; and the reconstruction re-rendered along the joints of a
recorded episode of the same robot (``robogs synth --size small``) covers the robot's pixels of
that recording (IoU of the robot masks at matched stamps). The reconstructed table is written as
its support plane: it must lie within ``TABLE_TOP_MM`` of the true top (a ray cast down onto
the true scene mesh), and neither validation may report an error (G011 included).
"""

from __future__ import annotations

import json
import os
import re
import resource
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "reconstruct.md"
FULL = "--iterations 3000 --threads 2"
SMALL = "--iterations 150 --lr-scale 3 --scale 0.5 --force --threads 2 --no-progress"
#: robot-mask IoU of the re-rendered episode against the recording (measured: see the test)
IOU_MIN = 0.8
#: reconstructed table plane vs the true top, mm (measured 7.2 at the test's size; see the doc)
TABLE_TOP_MM = 12.0
#: SfM pre-alignment residual, mm RMS: two voxels of the labelled hull it fits. The hull (160
#: voxels along the workspace) is 8.4-11.2 mm a voxel in the robot's world, and the fit reads
#: about one voxel: 7.16-7.65 mm over 10 SfM runs of the sample before they repeated (h74: 7 with
#: 2 threads, 3 of them beside a busy process, and 3 with 1), 7.42 mm since with any thread
#: count, 6.8-8.0 mm with the SfM frame turned by 5 random rotations (the grid is axis-aligned in
#: that frame). Beyond two voxels the hull is not what was fitted: the depth-reversed SfM basin
#: reads 284 mm. CI read 32.1 mm once before h74 (not reproduced here).
PREALIGN_RMS_MM = 20.0


def recipe_lines() -> list[str]:
    text = DOC.read_text(encoding="utf-8")
    m = re.search(r"<!-- recipe:[^\n]*-->\s*```sh\n(.*?)```", text, re.S)
    assert m, "docs/reconstruct.md lost its recipe block"
    return [ln for ln in m.group(1).splitlines() if ln.strip()]


def test_the_recipe_block_is_what_the_test_expects():
    lines = recipe_lines()
    assert [ln.split()[:2] for ln in lines] == [
        ["robogs", "synth"],
        ["robogs", "convert"],
        ["robogs", "reconstruct"],
        ["robogs-validate", "scan-posed"],
        ["robogs", "synth"],
        ["robogs", "render"],
        ["robogs-validate", "replay"],
    ]
    assert "--sfm" in lines[1] and FULL in lines[2] and "--align apply" in lines[2]
    assert "--joints episode/" in lines[5] and "--camera episode/" in lines[5]


def _run(line: str, cwd: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, OMP_NUM_THREADS="2", PYTHONUNBUFFERED="1")
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    t0, c0 = time.perf_counter(), _children_cpu_s()
    r = subprocess.run(
        shlex.split(line), cwd=cwd, env=env, capture_output=True, text=True, timeout=600
    )
    # the split (pytest -s): wall and CPU seconds (CPU does not grow with a loaded machine)
    print(f"{time.perf_counter() - t0:6.1f} s wall {_children_cpu_s() - c0:6.1f} s CPU  {line}")
    return r


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _robot_masks(root: Path) -> tuple[np.ndarray, np.ndarray]:
    """([F] t_ns, [F, H, W] bool robot-link pixels) of the one camera of a dataset's episode."""
    from robogs.format.dataset import Dataset, read_parquet

    ds = Dataset.open(root)
    ep = ds.episode(None)
    cam = ds.camera_names[0]
    seg = read_parquet(ep.table_path("segments")).to_pylist()
    robot = [r["label_id"] for r in seg if r["kind"] == "robot_link"]
    t = ep.frames(cam).column("t_ns").to_numpy()
    masks = np.stack([np.isin(lab, robot) for _, lab in ep.iter_labels(cam)])
    return t, masks


def _true_top_z(scene_ply: Path) -> float:
    """z (m) of the true table top: rays cast down onto the true scene mesh at three table
    points away from the robot and the box (they must agree)."""
    import trimesh

    mesh = trimesh.load(scene_ply, force="mesh")
    xy = np.array([[0.8, -0.4], [0.8, 0.4], [-0.2, 0.4]])
    origins = np.column_stack([xy, np.full(len(xy), 2.0)])
    hits, rays, _ = mesh.ray.intersects_location(origins, np.tile([0.0, 0.0, -1.0], (len(xy), 1)))
    top = np.array([hits[rays == i][:, 2].max() for i in range(len(xy))])
    assert np.ptp(top) < 1e-6, top
    return float(top[0])


def _errors(stdout: str) -> list[str]:
    return sorted(set(re.findall(r"^(\w\d{3}) error", stdout, re.M)))


@pytest.mark.slow
def test_recipe_recovers_the_cameras_and_rerenders_an_episode(tmp_path: Path):
    """110 s of CPU (2026-11-26; ~90 s wall on 2 idle cores, estimated; docs/reconstruct.md);
    129-134 s of CPU, 376-475 s wall, 3 runs in a row at load 7-8 beside a busy process
    (2026-11-28, h74; the SfM step's CPU the same before and after h74: 34.5-36.8 s)."""
    pytest.importorskip("pycolmap", reason="structure from motion needs the 'sfm' extra")
    from robogs.format.dataset import Dataset, read_parquet
    from robogs.format.frames import quat_to_matrix_np

    lines = recipe_lines()
    for line in lines[:3]:
        r = _run(line.replace(FULL, SMALL), tmp_path)
        assert r.returncode == 0, f"{line}\n{r.stderr[-2000:]}"
        if line.startswith("robogs convert"):
            assert "60 of 60 images registered" in r.stdout
        if line.startswith("robogs reconstruct"):
            out = r.stdout + r.stderr
            assert "cameras from SfM moved onto the URDF" in out
            assert "alignment to the URDF (apply)" in out
    ds = Dataset.open(tmp_path / "scan-posed")
    sfm = ds.manifest["provenance"]["sfm"]
    assert sfm["registered"] == sfm["images"] == 60
    assert sfm["frame"].startswith("robot"), sfm
    tab = read_parquet(ds.resolve("episodes/static/cameras/orbit/extrinsics.parquet"))
    p = np.stack([tab.column(c).to_numpy() for c in "xyz"], -1)
    q = np.stack([tab.column(c).to_numpy() for c in ("qw", "qx", "qy", "qz")], -1)
    truth = json.loads((tmp_path / "scan.ground_truth.json").read_text())
    Tt = np.asarray(truth["T_world_cam"])
    err = np.linalg.norm(p - Tt[:, :3, 3], axis=1)
    print(f"margins: camera centres {err.max() * 1e3:.1f} mm of {10 * truth['scene_size_m']:.1f}")
    d = np.einsum("nji,njk->nik", quat_to_matrix_np(q), Tt[:, :3, :3])
    ang = np.degrees(np.arccos(np.clip((np.trace(d, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    print(f"margins: camera rotations {ang.max():.2f} deg of 1")
    # the cameras are the oracle; the pre-alignment's residual only says whether its hull fit
    # held, so each failure message carries the other figures (which one broke, and the SfM)
    seen = json.dumps({"centre_mm": err.max() * 1e3, "rot_deg": ang.max(), "sfm": sfm})
    assert err.max() < 0.01 * truth["scene_size_m"], seen
    assert ang.max() < 1.0, seen
    print(f"margins: SfM pre-alignment {sfm['prealign']['rms_mm']:.2f} mm RMS of {PREALIGN_RMS_MM}")
    assert sfm["prealign"]["rms_mm"] < PREALIGN_RMS_MM, seen
    report = ds.manifest["provenance"]["reconstruction"]["report"]
    align = report["alignment"]
    print(f"margins: URDF residual {align['rms_mm']:.2f} mm RMS of 5")
    assert align["rms_mm"] <= 5.0, align  # links below the coverage at this size left out
    # the table is written as its support plane, the box rests on it; the plane's height is
    # measured against the true top (a ray cast down onto the true scene mesh)
    sup = report["support"]["table"]
    assert sup["objects_rested"].keys() == {"box"}, sup
    true_top = _true_top_z(tmp_path / "scan.ground_truth.ply")
    err_mm = sup["height_mm"] - true_top * 1e3
    print(f"margins: table plane {err_mm:+.1f} mm from the true top, of {TABLE_TOP_MM:g}")
    assert abs(err_mm) <= TABLE_TOP_MM, sup
    r = _run(lines[3], tmp_path)
    assert r.returncode == 0 and _errors(r.stdout) == [], r.stdout[-3000:]
    # re-rendered along a recorded episode of the same robot
    for line in lines[4:]:
        r = _run(line, tmp_path)
        ok = (0, 1) if line.startswith("robogs-validate") else (0,)
        assert r.returncode in ok, f"{line}\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}"
    assert _errors(r.stdout) == [], r.stdout[-3000:]
    t_rec, rec = _robot_masks(tmp_path / "episode")
    t_ren, ren = _robot_masks(tmp_path / "replay")
    near = np.abs(t_rec[None, :] - t_ren[:, None]).argmin(1)
    gap_ms = np.abs(t_rec[near] - t_ren).max() / 1e6
    assert gap_ms < 20.0, gap_ms  # the recording's frames are ~33 ms apart
    inter = (ren & rec[near]).sum()
    iou = inter / (ren | rec[near]).sum()
    print(f"margins: re-rendered robot IoU {iou:.3f} of > {IOU_MIN}")
    assert iou > IOU_MIN, iou
