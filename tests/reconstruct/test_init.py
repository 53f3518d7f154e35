"""Seeds: on the URDF meshes at the recorded joint state, or uniform in the workspace box.

Oracles: the fixture's own meshes posed by its own kinematics (``MultiviewTruth.meshes``), and the
visible true surface, which the workspace box must hold.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from robogs.format.dataset import Dataset
from robogs.reconstruct.init import InitConfig, initial_points, initial_tensors
from robogs.reconstruct.views import load_capture

LINKS = ("base_link", "link1", "link2")


@pytest.fixture(scope="module")
def capture(tiny_scene):
    root, truth = tiny_scene
    ds = Dataset.open(root)
    return ds, load_capture(ds), truth


def test_urdf_seeds_lie_on_the_link_meshes_at_the_recorded_pose(capture):
    ds, cap, truth = capture
    ip = initial_points(ds, cap, cap.views, InitConfig(mode="urdf", spacing_m=0.01))
    links = trimesh.util.concatenate([truth.meshes[n] for n in LINKS])
    _, dist, face = trimesh.proximity.closest_point(links, ip.points)
    assert dist.max() < 1e-5  # STL float32 vertices
    # surfels lie in the faces: their normals are the face normals (edges may pick a neighbour)
    dots = np.abs((ip.normals * links.face_normals[face]).sum(1))
    assert (dots > 0.999).mean() > 0.95
    # every link is covered at about the requested spacing
    for n in LINKS:
        m = truth.meshes[n]
        near = np.abs(m.nearest.signed_distance(ip.points)) < 1e-5
        assert near.sum() >= 0.3 * m.area / 0.01**2, n
    # colours come from the views: link1 is orange (0.85, 0.45, 0.12 before shading)
    on1 = np.abs(truth.meshes["link1"].nearest.signed_distance(ip.points)) < 1e-5
    seen = ip.colors[on1]
    seen = seen[np.abs(seen - 0.5).sum(1) > 1e-9]  # 0.5 grey: seen by no view
    assert len(seen) and (seen[:, 0] > seen[:, 2]).mean() > 0.9


def test_random_seeds_fill_the_workspace_box(capture):
    ds, cap, truth = capture
    ip = initial_points(ds, cap, cap.views, InitConfig(mode="random", random_count=4000, seed=3))
    assert ip.points.shape == (4000, 3) and np.isnan(ip.normals).all()
    assert (ip.points >= ip.lo).all() and (ip.points <= ip.hi).all()
    # uniform: each octant of the box holds about an eighth (binomial sd ~ 21)
    mid = 0.5 * (ip.lo + ip.hi)
    octant = ((ip.points > mid) * np.array([1, 2, 4])).sum(1)
    assert np.abs(np.bincount(octant, minlength=8) - 500).max() < 100
    # the box holds the surface the cameras see, to a coarse hull voxel (2 x 1.2 m / 48)
    ref, _ = truth.visible_surface_points(20_000)
    slack = 0.05
    assert (ref >= ip.lo - slack).all() and (ref <= ip.hi + slack).all()
    t = initial_tensors(ip, kind="2dgs", sh_degree=1)
    assert t["means"].shape == (4000, 3) and t["log_scales"].shape == (4000, 2)
    assert t["sh_rest"].shape == (4000, 3, 3)
