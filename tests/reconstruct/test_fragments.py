"""segment.drop_fragments: each target keeps its main pieces, floaters and stray bits go."""

from __future__ import annotations

import numpy as np
import trimesh

from robogs.reconstruct.pipeline import _without_fragments
from robogs.reconstruct.segment import drop_fragments, face_targets


def _scene() -> tuple[trimesh.Trimesh, np.ndarray, list[int]]:
    """A table slab (target 1), a floater above it (also voted 1, 1/100 of the area), a box
    on the table (target 2, a ball) and a second, equal table slab (target 1: two real pieces)."""
    parts = [
        (trimesh.creation.box((1.0, 1.0, 0.05)), (0, 0, 0), 1),
        (trimesh.creation.box((0.1, 0.1, 0.005)), (0, 0, 0.5), 1),
        (trimesh.creation.icosphere(3, radius=0.1), (0.3, 0.3, 0.125), 2),
        (trimesh.creation.box((1.0, 1.0, 0.05)), (2.0, 0, 0), 1),
    ]
    meshes, targets, sizes = [], [], []
    for m, t, k in parts:
        m = m.copy()
        m.apply_translation(t)
        meshes.append(m)
        targets.append(np.full(len(m.vertices), k))
        sizes.append(len(m.faces))
    return trimesh.util.concatenate(meshes), np.concatenate(targets), sizes


def test_the_floater_goes_and_real_pieces_stay():
    mesh, vt, sizes = _scene()
    keep = drop_fragments(mesh, vt)
    start = np.cumsum([0, *sizes])
    expected = np.ones(len(mesh.faces), bool)
    expected[start[1] : start[2]] = False  # the floater only
    np.testing.assert_array_equal(keep, expected)
    out, vt2, n = _without_fragments(mesh, vt)
    assert n == sizes[1] and len(out.faces) == len(mesh.faces) - sizes[1]
    assert out.vertices[:, 2].max() < 0.3  # the table's top is no longer the floater's
    np.testing.assert_array_equal(
        np.bincount(face_targets(out, vt2)), [0, sizes[0] + sizes[3], sizes[2]]
    )


def test_a_neighbours_bit_voted_to_the_wrong_target_goes():
    """The ball's top cap voted to the table is a fragment of the table's label."""
    mesh, vt, sizes = _scene()
    ball = np.zeros(len(mesh.faces), bool)
    ball[sum(sizes[:2]) : sum(sizes[:3])] = True
    v_ball = np.unique(np.asarray(mesh.faces)[ball])
    cap = v_ball[mesh.vertices[v_ball, 2] > 0.125 + 0.08]
    vt = vt.copy()
    vt[cap] = 1
    ft = face_targets(mesh, vt)
    stray = ball & (ft == 1)
    assert stray.sum() > 10
    keep = drop_fragments(mesh, vt)
    assert not keep[stray].any()
    assert keep[ball & (ft == 2)].all() and keep[: sizes[0]].all()


def test_nothing_to_drop_returns_the_same_mesh():
    m = trimesh.creation.icosphere(2)
    vt = np.ones(len(m.vertices), np.int64)
    out, vt2, n = _without_fragments(m, vt)
    assert n == 0 and out is m and vt2 is vt
