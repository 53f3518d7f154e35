"""frames.py against scipy.spatial.transform.Rotation (xyzw, converted explicitly) and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation, Slerp

from robogs.format import frames as F


def wxyz(r: Rotation) -> np.ndarray:
    q = r.as_quat()  # scipy: x, y, z, w
    return np.concatenate([q[..., 3:], q[..., :3]], axis=-1)


def same_rotation(qa: np.ndarray, qb: np.ndarray) -> float:
    """Max deviation of |<qa, qb>| from 1 (q and -q are the same rotation)."""
    return float(np.max(np.abs(np.abs(np.sum(qa * qb, axis=-1)) - 1.0)))


@pytest.fixture
def rots() -> Rotation:
    return Rotation.random(500, random_state=7)


def test_quat_to_matrix_matches_scipy(rots: Rotation) -> None:
    q = wxyz(rots)
    assert np.abs(F.quat_to_matrix(q) - rots.as_matrix()).max() < 1e-14
    # unnormalised input is normalised first
    assert np.abs(F.quat_to_matrix(3.5 * q) - rots.as_matrix()).max() < 1e-14
    # float32 torch keeps its dtype
    R32 = F.quat_to_matrix(torch.tensor(q, dtype=torch.float32))
    assert R32.dtype == torch.float32
    assert np.abs(R32.numpy() - rots.as_matrix()).max() < 1e-6


def test_matrix_to_quat_round_trip_and_canonical(rots: Rotation) -> None:
    q = F.matrix_to_quat(rots.as_matrix())
    assert same_rotation(q, wxyz(rots)) < 1e-14
    assert (q[:, 0] >= 0).all()
    assert np.abs(np.linalg.norm(q, axis=-1) - 1).max() < 1e-15


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -2, 3)])
@pytest.mark.parametrize("angle", [0.0, 1e-9, math.pi / 2, math.pi - 1e-9, math.pi])
def test_matrix_to_quat_hard_angles(axis: tuple[float, ...], angle: float) -> None:
    """Shepperd's pivot keeps precision at 0 and pi, where the trace formula breaks down."""
    rv = np.asarray(axis, dtype=float) / np.linalg.norm(axis) * angle
    r = Rotation.from_rotvec(rv)
    q = F.matrix_to_quat(r.as_matrix())
    assert same_rotation(q, wxyz(r)) < 1e-15
    assert np.abs(F.quat_to_matrix(q) - r.as_matrix()).max() < 1e-15


def test_multiply_conjugate_inverse_rotate(rots: Rotation) -> None:
    a, b = rots[:250], rots[250:]
    ab = F.quat_multiply(wxyz(a), wxyz(b))
    assert same_rotation(ab, wxyz(a * b)) < 1e-14
    v = np.random.default_rng(0).normal(size=(250, 3))
    assert np.abs(F.quat_rotate(wxyz(a), v) - a.apply(v)).max() < 1e-14
    # rotate == matrix product
    assert (
        np.abs(F.quat_rotate(wxyz(a), v) - np.einsum("nij,nj->ni", a.as_matrix(), v)).max() < 1e-14
    )
    assert same_rotation(F.quat_conjugate(wxyz(a)), wxyz(a.inv())) < 1e-15
    q = 2.0 * wxyz(a)
    ident = F.quat_multiply(q, F.quat_inverse(q))
    assert np.abs(ident - np.array([1.0, 0, 0, 0])).max() < 1e-15


def test_quat_normalize_sign() -> None:
    q = np.array([[-2.0, 0.0, 0.0, 0.0], [0.0, -3.0, 0.0, 4.0]])
    out = F.quat_normalize(q)
    assert np.abs(out - np.array([[1, 0, 0, 0], [0, -0.6, 0, 0.8]])).max() < 1e-15


def test_slerp_closed_form_and_shortest_arc() -> None:
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    th0, th1 = 0.3, 2.1
    q0 = wxyz(Rotation.from_rotvec(axis * th0))
    q1 = wxyz(Rotation.from_rotvec(axis * th1))
    t = np.linspace(0, 1, 11)
    out = F.quat_slerp(np.broadcast_to(q0, (11, 4)), np.broadcast_to(q1, (11, 4)), t)
    expect = wxyz(Rotation.from_rotvec(axis[None] * (th0 + t[:, None] * (th1 - th0))))
    assert same_rotation(out, expect) < 1e-14
    # -q1 is the same rotation: the shortest arc gives the same path
    out_neg = F.quat_slerp(np.broadcast_to(q0, (11, 4)), np.broadcast_to(-q1, (11, 4)), t)
    assert same_rotation(out_neg, expect) < 1e-14
    # the other way round the long arc would have passed through angle > th1 - th0
    ang = F.quat_angle_between(np.broadcast_to(q0, (11, 4)), out)
    assert np.abs(ang - t * (th1 - th0)).max() < 1e-12


def test_slerp_matches_scipy_and_near_parallel(rots: Rotation) -> None:
    key = Rotation.concatenate([rots[0], rots[1]])
    ref = Slerp([0.0, 1.0], key)(np.array([0.25, 0.5, 0.9]))
    out = F.quat_slerp(
        wxyz(rots[0])[None].repeat(3, 0),
        wxyz(rots[1])[None].repeat(3, 0),
        np.array([0.25, 0.5, 0.9]),
    )
    assert same_rotation(out, wxyz(ref)) < 1e-13
    q = wxyz(rots[2])
    q_close = wxyz(rots[2] * Rotation.from_rotvec([1e-9, 0, 0]))
    mid = F.quat_slerp(q, q_close, 0.5)
    assert same_rotation(mid, wxyz(rots[2] * Rotation.from_rotvec([5e-10, 0, 0]))) < 1e-15
    assert np.isfinite(mid).all()


def test_axis_angle_and_rotvec(rots: Rotation) -> None:
    rv = rots.as_rotvec()
    angle = np.linalg.norm(rv, axis=-1)
    assert (
        np.abs(F.axis_angle_to_matrix(rv / angle[:, None], angle) - rots.as_matrix()).max() < 1e-14
    )
    assert np.abs(F.rotvec_to_matrix(rv) - rots.as_matrix()).max() < 1e-14
    small = np.array([[1e-10, -2e-10, 3e-11], [0.0, 0.0, 0.0], [1e-5, 0, 0]])
    assert (
        np.abs(F.rotvec_to_matrix(small) - Rotation.from_rotvec(small).as_matrix()).max()
        < 1e-16 + 1e-15
    )
    assert np.abs(F.matrix_to_rotvec(rots.as_matrix()) - rv).max() < 1e-13
    assert np.abs(F.matrix_to_rotvec(Rotation.from_rotvec(small).as_matrix()) - small).max() < 1e-15
    assert np.abs(F.rotation_angle(rots.as_matrix()) - rots.magnitude()).max() < 1e-14


def test_rotvec_gradient_finite_at_zero() -> None:
    rv = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    F.rotvec_to_matrix(rv).sum().backward()
    assert torch.isfinite(rv.grad).all()
    # d/d rv of R @ e at 0 is -[e]_x : check one entry against the closed form
    rv2 = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    (F.rotvec_to_matrix(rv2) @ torch.tensor([1.0, 0, 0], dtype=torch.float64))[1].backward()
    assert torch.allclose(rv2.grad, torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))


def test_rpy_and_elementary_rotations() -> None:
    rpy = np.random.default_rng(1).uniform(-3, 3, size=(100, 3))
    ref = Rotation.from_euler("xyz", rpy).as_matrix()  # extrinsic x, y, z = Rz Ry Rx
    assert np.abs(F.rpy_to_matrix(rpy) - ref).max() < 1e-14
    a = 0.7
    assert (
        np.abs(F.rot_x(np.float64(a)) - Rotation.from_rotvec([a, 0, 0]).as_matrix()).max() < 1e-15
    )
    assert np.abs(F.rot_y(np.array(a)) - Rotation.from_rotvec([0, a, 0]).as_matrix()).max() < 1e-15
    assert np.abs(F.rot_z(np.array(a)) - Rotation.from_rotvec([0, 0, a]).as_matrix()).max() < 1e-15


def test_transforms_make_invert_compose() -> None:
    rng = np.random.default_rng(2)
    R = Rotation.random(3 * 4, random_state=3).as_matrix().reshape(3, 4, 3, 3)
    t = rng.normal(size=(3, 4, 3))
    T = F.make_T(R, t)
    assert T.shape == (3, 4, 4, 4)
    assert np.array_equal(T[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], (3, 4, 4)))
    Ti = F.invert_T(T)
    assert np.abs(Ti - np.linalg.inv(T)).max() < 1e-13
    assert np.abs(F.compose(T, Ti) - np.eye(4)).max() < 1e-14
    A, B, C = T[0], T[1], T[2]
    assert np.abs(F.compose(A, B, C) - A @ B @ C).max() < 1e-13
    p = rng.normal(size=(4, 3))
    homog = np.einsum("nij,nj->ni", A, np.concatenate([p, np.ones((4, 1))], axis=1))[:, :3]
    assert np.abs(F.transform_points(A, p) - homog).max() < 1e-14


def test_camera_axes_cv_gl() -> None:
    # A point 2 m in front of an OpenGL camera is at z = -2 (GL looks down -z); OpenCV: z = +2.
    p_gl = np.array([0.1, 0.2, -2.0, 1.0])
    p_cv = F.T_CV_GL @ p_gl
    assert np.array_equal(p_cv, [0.1, -0.2, 2.0, 1.0])
    assert np.array_equal(F.T_CV_GL @ F.T_CV_GL, np.eye(4))
    T_world_gl = F.make_T(Rotation.random(random_state=4).as_matrix(), np.array([1.0, 2.0, 3.0]))
    T_world_cv = F.cam_gl_to_cv(T_world_gl)
    # same centre, forward axis flipped relative to GL's +z, same image-right axis
    assert np.array_equal(T_world_cv[:3, 3], T_world_gl[:3, 3])
    assert np.abs(T_world_cv[:3, 2] + T_world_gl[:3, 2]).max() < 1e-15
    assert np.abs(T_world_cv[:3, 0] - T_world_gl[:3, 0]).max() < 1e-15
    # the same world point has the same pixel-side coordinates either way
    X = np.array([0.3, -0.4, 0.5])
    x_gl = F.transform_points(F.invert_T(T_world_gl), X)
    x_cv = F.transform_points(F.invert_T(T_world_cv), X)
    assert np.abs(x_cv - x_gl * np.array([1, -1, -1])).max() < 1e-14
    assert np.abs(F.cam_cv_to_gl(T_world_cv) - T_world_gl).max() < 1e-15


def test_world_yup_zup() -> None:
    up_yup = np.array([0.0, 1.0, 0.0, 1.0])
    assert np.abs(F.T_ZUP_YUP @ up_yup - [0, 0, 1, 1]).max() == 0
    assert np.abs(F.T_ZUP_YUP @ np.array([0, 0, 1.0, 1]) - [0, -1, 0, 1]).max() == 0
    assert np.linalg.det(F.T_ZUP_YUP[:3, :3]) == pytest.approx(1.0)
    T = F.make_T(Rotation.random(random_state=5).as_matrix(), np.array([1.0, 2.0, 3.0]))
    Tz = F.world_yup_to_zup(T)
    assert np.abs(Tz[:3, 3] - [1.0, -3.0, 2.0]).max() < 1e-15
    assert np.abs(F.world_zup_to_yup(Tz) - T).max() < 1e-15


def test_batched_torch_dtype_and_grad() -> None:
    q = torch.randn(2, 3, 5, 4, dtype=torch.float64)
    R = F.quat_to_matrix(q)
    assert R.shape == (2, 3, 5, 3, 3)
    assert torch.allclose(F.quat_to_matrix(F.matrix_to_quat(R)), R, atol=1e-14)
    q32 = q.float().requires_grad_(True)
    F.quat_rotate(F.quat_normalize(q32), torch.ones(3)).sum().backward()
    assert q32.grad is not None and torch.isfinite(q32.grad).all()
    assert F.make_T(torch.eye(3, dtype=torch.float32), torch.zeros(7, 3)).shape == (7, 4, 4)


# --------------------------------------------------------------------------- numpy face


@pytest.mark.parametrize(
    ("q", "R"),
    [
        ((1.0, 0.0, 0.0, 0.0), np.eye(3)),
        ((0.0, 1.0, 0.0, 0.0), np.diag([1.0, -1.0, -1.0])),  # pi about x
        ((math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)), [[0, -1, 0], [1, 0, 0], [0, 0, 1]]),  # +z 90
        ((0.5, 0.5, 0.5, 0.5), [[0, 0, 1], [1, 0, 0], [0, 1, 0]]),  # 120 deg about (1,1,1)
    ],
)
def test_numpy_face_known_rotations(q: tuple[float, ...], R: object) -> None:
    R = np.asarray(R, dtype=float)
    assert np.abs(F.quat_to_matrix_np(np.asarray(q)) - R).max() < 1e-15
    assert np.abs(F.quat_to_matrix_np(-2.0 * np.asarray(q)) - R).max() < 1e-15  # sign, norm
    assert same_rotation(F.matrix_to_quat_np(R), np.asarray(q)) < 1e-15
    assert F.matrix_to_quat_np(R)[0] >= 0


def test_numpy_face_batch_shapes_round_trip_and_agrees_with_torch(rots: Rotation) -> None:
    q = wxyz(rots).reshape(5, 100, 4)
    R = F.quat_to_matrix_np(q)
    assert R.shape == (5, 100, 3, 3)
    assert np.abs(R - rots.as_matrix().reshape(5, 100, 3, 3)).max() < 1e-14
    q2 = F.matrix_to_quat_np(R)
    assert q2.shape == (5, 100, 4) and (q2[..., 0] >= 0).all()
    assert same_rotation(q2, q) < 1e-14
    assert np.abs(F.quat_to_matrix_np(q2) - R).max() < 1e-14
    # both faces agree (torch face on float64 tensors)
    Rt = F.quat_to_matrix(torch.as_tensor(q)).numpy()
    assert np.abs(Rt - R).max() < 1e-15
    assert np.abs(F.matrix_to_quat(torch.as_tensor(R)).numpy() - q2).max() < 1e-15
    # single quaternion and single matrix keep their shapes
    assert F.quat_to_matrix_np(q[0, 0]).shape == (3, 3)
    assert F.matrix_to_quat_np(R[0, 0]).shape == (4,)


def test_numpy_face_does_not_import_torch() -> None:
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from robogs.format.frames import quat_to_matrix_np, matrix_to_quat_np\n"
        "matrix_to_quat_np(quat_to_matrix_np(np.array([0.9, 0.1, -0.3, 0.2])))\n"
        "print('torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
