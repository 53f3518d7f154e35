"""Umeyama/ICP alignment recovers known similarities; binding round-trips exactly."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from robogs.format.errors import InputError
from robogs.reconstruct.align import Similarity, align_to_meshes, umeyama
from robogs.reconstruct.bind import bind_to_mesh, bound_positions


def _sim(seed: int, scale: float, deg: float, t_mm: float) -> Similarity:
    rng = np.random.default_rng(seed)
    axis = rng.normal(size=3)
    R = Rotation.from_rotvec(np.radians(deg) * axis / np.linalg.norm(axis)).as_matrix()
    return Similarity(scale, R, rng.normal(size=3) * t_mm * 1e-3)


def test_umeyama_recovers_a_similarity_exactly():
    S = _sim(0, 1.37, 40.0, 200.0)
    src = np.random.default_rng(1).normal(size=(50, 3))
    est = umeyama(src, S.apply(src))
    assert est.scale == pytest.approx(1.37, rel=1e-12)
    assert np.allclose(est.R, S.R, atol=1e-12) and np.allclose(est.t, S.t, atol=1e-12)
    rigid = umeyama(src, S.apply(src), with_scale=False)
    assert rigid.scale == 1.0 and np.linalg.det(rigid.R) == pytest.approx(1.0)


def test_umeyama_never_returns_a_reflection():
    src = np.random.default_rng(2).normal(size=(30, 3))
    mirrored = src * np.array([1.0, 1.0, -1.0])
    est = umeyama(src, mirrored)
    assert np.linalg.det(est.R) == pytest.approx(1.0)


def test_umeyama_refuses_degenerate_input():
    with pytest.raises(InputError):
        umeyama(np.zeros((5, 3)), np.zeros((5, 3)))
    with pytest.raises(InputError):
        umeyama(np.zeros((2, 3)), np.zeros((2, 3)))


def test_icp_alignment_undoes_a_small_similarity():
    # two "links" (boxes) at the reference pose; the reconstruction is their surfaces moved by S
    a = trimesh.creation.box(extents=(0.2, 0.1, 0.05))
    b = trimesh.creation.cylinder(radius=0.04, height=0.25, sections=32).apply_translation(
        (0.2, 0.1, 0.1)
    )
    S = _sim(3, 1.03, 4.0, 8.0)
    pts = {
        n: S.apply(np.asarray(trimesh.sample.sample_surface(m, 4000, seed=k)[0]))
        for k, (n, m) in enumerate({"a": a, "b": b}.items())
    }
    res = align_to_meshes(pts, {"a": a, "b": b}, samples=60_000)
    back = res.transform.compose(S)  # should be the identity
    assert back.scale == pytest.approx(1.0, abs=2e-3)
    assert back.rotation_deg < 0.3
    assert np.linalg.norm(back.t) < 1.5e-3
    assert res.median_mm < 0.6 < res.before_rms_mm


def test_binding_round_trip_is_exact_and_uses_the_nearest_face():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    rng = np.random.default_rng(4)
    p = rng.normal(size=(500, 3))
    p = p / np.linalg.norm(p, axis=1, keepdims=True) * rng.uniform(0.09, 0.11, (500, 1))
    face, uv, off = bind_to_mesh(p, mesh)
    assert (face >= 0).all()
    back = bound_positions(mesh, face, uv, off)
    assert np.abs(back - p).max() < 1e-6  # float32 storage of uv/offset
    # brute force: no face is nearer than the chosen one
    closest, dist, _ = trimesh.proximity.closest_point(mesh, p)
    tri = mesh.triangles[face]
    chosen = trimesh.triangles.closest_point(tri, p)
    assert np.allclose(np.linalg.norm(chosen - p, axis=1), dist, atol=1e-9)
    # offsets are signed along the outward face normal: points outside the sphere are positive
    r = np.linalg.norm(p, axis=1)
    assert (
        np.sign(off[np.abs(r - 0.1) > 0.003]) == np.sign(r - 0.1)[np.abs(r - 0.1) > 0.003]
    ).all()


@pytest.mark.parametrize("seed_offset", [0, 100, 200, 300])
def test_an_excluded_blob_neither_biases_the_fit_nor_the_rms_but_is_reported(seed_offset):
    """Three boxes seen exactly (moved by a known similarity) and a fourth reconstructed as a
    blob 1.5x its size: with it the RMS is the blob's; left out, the transform is recovered,
    the RMS is the true surfaces' and the blob's median residual is still reported.

    Several sample seeds: offset 100 once put the clean fit 6 mm (1000 points) to 985 mm (3000
    points) off, because the refinement's Tukey scale collapsed on these exact samples (h82).
    The points are exact surface samples, so the oracle (identity after undoing the similarity,
    zero residual on the true surfaces, the blob's ~20 mm) does not depend on their number:
    1000 per box keeps four seeds at about the cost of the former single seed at 3000.
    """
    meshes = {
        f"l{i}": trimesh.creation.box((0.1, 0.08, 0.06)).apply_translation(c)
        for i, c in enumerate([(0, 0, 0), (0.4, 0, 0), (0, 0.3, 0.1), (0.2, 0.2, 0.4)])
    }
    S = _sim(3, 0.8, 25.0, 100.0)
    inv = Similarity(1 / S.scale, S.R.T, -(S.R.T @ S.t) / S.scale)
    pts = {}
    for i, (n, m) in enumerate(meshes.items()):
        p, _ = trimesh.sample.sample_surface(m, 1000, seed=10 + i + seed_offset)
        if n == "l3":  # the blob: 1.5x about its centre
            c = m.centroid
            p = c + 1.5 * (p - c)
        pts[n] = inv.apply(p)
    biased = align_to_meshes(pts, meshes)
    clean = align_to_meshes(pts, meshes, exclude={"l3"})
    assert clean.excluded == ["l3"] and biased.excluded == []
    assert clean.rms_mm < 0.1 and biased.rms_mm > 1.0  # the blob in the fit: the counterfactual
    back = clean.transform.compose(inv)  # the identity when the similarity is recovered
    assert abs(back.scale - 1.0) < 1e-4 and back.rotation_deg < 1e-2
    assert np.linalg.norm(back.t) < 1e-4
    # the blob's faces lie 15-25 mm outside the box's (half its 30-50 mm half-sizes), more by
    # its edges
    assert 10.0 < clean.per_target_mm["l3"] < 30.0 and set(clean.per_target_mm) == set(meshes)
