"""Rotations and rigid transforms (batched torch, numpy accepted).

Conventions (normative for robogs):

* Quaternions are scalar-first ``(w, x, y, z)``, Hamilton product, unit norm for rotations.
  ``q`` and ``-q`` are the same rotation; functions that return a quaternion canonicalise it
  to ``w >= 0``.
* ``T_a_b`` is a 4x4 homogeneous transform mapping points in frame ``b`` to frame ``a``:
  ``p_a = T_a_b @ p_b``. Composition: ``T_a_c = T_a_b @ T_b_c``.
* Camera axes are OpenCV (x right, y down, z forward). OpenGL cameras (x right, y up,
  z backward) convert with :data:`T_CV_GL`.
* The world is z-up (ROS/URDF). A y-up world (OpenGL, glTF, nerfstudio exports) converts with
  :data:`T_ZUP_YUP`.

Every function takes torch tensors with any leading batch dimensions (float32 or float64, CPU or
CUDA; results follow the input's dtype and device) and is differentiable. Passing numpy arrays
instead returns numpy arrays (float64 unless the input is float32).

The numpy face :func:`quat_to_matrix_np` / :func:`matrix_to_quat_np` is pure numpy (float64) and
never imports torch, so torch-free paths (quick validation, ingest) share this one home; torch is
imported on first use of the torch face.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

__all__ = [
    "quat_normalize",
    "quat_multiply",
    "quat_conjugate",
    "quat_inverse",
    "quat_rotate",
    "quat_to_matrix",
    "matrix_to_quat",
    "quat_to_matrix_np",
    "matrix_to_quat_np",
    "quat_slerp",
    "quat_angle_between",
    "axis_angle_to_matrix",
    "rotvec_to_matrix",
    "matrix_to_rotvec",
    "rotation_angle",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_to_matrix",
    "make_T",
    "invert_T",
    "compose",
    "transform_points",
    "T_CV_GL",
    "T_ZUP_YUP",
    "cam_gl_to_cv",
    "cam_cv_to_gl",
    "world_yup_to_zup",
    "world_zup_to_yup",
]

_F = TypeVar("_F", bound=Callable[..., Any])


class _LazyTorch:
    """Stands in for the torch module until first use, then replaces itself by it."""

    def __getattr__(self, name: str) -> Any:
        import torch as _torch

        globals()["torch"] = _torch
        return getattr(_torch, name)


if not TYPE_CHECKING:
    torch = _LazyTorch()
_NP_TYPES = (np.ndarray, np.generic)


def _to_torch(x: Any) -> Any:
    if isinstance(x, np.generic):
        x = np.asarray(x)
    if isinstance(x, np.ndarray):
        if x.dtype == np.float32:
            return torch.from_numpy(np.ascontiguousarray(x))
        return torch.from_numpy(np.ascontiguousarray(x, dtype=np.float64))
    return x


def _to_numpy(x: Any) -> Any:
    if isinstance(x, torch.Tensor):
        return x.detach().cpu().numpy()
    if isinstance(x, tuple):
        return tuple(_to_numpy(v) for v in x)
    return x


def _numpy_compatible(fn: _F) -> _F:
    """Let a torch function take numpy arrays and answer in numpy."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        is_np = any(isinstance(a, _NP_TYPES) for a in args) or any(
            isinstance(v, _NP_TYPES) for v in kwargs.values()
        )
        if not is_np:
            return fn(*args, **kwargs)
        args2 = [_to_torch(a) for a in args]
        kwargs2 = {k: _to_torch(v) for k, v in kwargs.items()}
        return _to_numpy(fn(*args2, **kwargs2))

    return wrapper  # type: ignore[return-value]


def _as_float(x: Any, like: torch.Tensor | None = None) -> torch.Tensor:
    """A float tensor (dtype/device of ``like`` when given, else float64 for python scalars)."""
    if isinstance(x, torch.Tensor):
        if like is not None:
            return x.to(dtype=like.dtype, device=like.device)
        return x if x.is_floating_point() else x.to(torch.float64)
    if like is not None:
        return torch.as_tensor(x, dtype=like.dtype, device=like.device)
    return torch.as_tensor(x, dtype=torch.float64)


# --------------------------------------------------------------------------- quaternions


@_numpy_compatible
def quat_normalize(q: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Unit quaternion with ``w >= 0``.

    Args:
        q: [..., 4] quaternion (w, x, y, z), any norm > 0.
        eps: norm floor to avoid division by zero.

    Returns:
        [..., 4] unit quaternion, canonical sign (w >= 0).
    """
    q = _as_float(q)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(eps)
    sign = torch.where(q[..., :1] < 0, -torch.ones_like(q[..., :1]), torch.ones_like(q[..., :1]))
    return q * sign


@_numpy_compatible
def quat_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product ``a ⊗ b`` (rotation ``b`` first, then ``a``).

    Args:
        a: [..., 4] (w, x, y, z).
        b: [..., 4] (w, x, y, z), broadcastable with ``a``.

    Returns:
        [..., 4] product, not renormalised.
    """
    a = _as_float(a)
    b = _as_float(b, like=a)
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        dim=-1,
    )


@_numpy_compatible
def quat_conjugate(q: torch.Tensor) -> torch.Tensor:
    """Conjugate ``(w, -x, -y, -z)``; the inverse rotation for a unit quaternion.

    Args:
        q: [..., 4] (w, x, y, z).
    """
    q = _as_float(q)
    return torch.cat((q[..., :1], -q[..., 1:]), dim=-1)


@_numpy_compatible
def quat_inverse(q: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """Multiplicative inverse ``conj(q) / |q|^2`` (works for non-unit quaternions).

    Args:
        q: [..., 4] (w, x, y, z).
        eps: floor on ``|q|^2``.
    """
    q = _as_float(q)
    return quat_conjugate(q) / (q * q).sum(-1, keepdim=True).clamp_min(eps)


@_numpy_compatible
def quat_rotate(q: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors by unit quaternions: ``q ⊗ (0, v) ⊗ q*``.

    Uses ``v + 2 w (u × v) + 2 u × (u × v)`` with ``u = (x, y, z)``.

    Args:
        q: [..., 4] unit quaternion (w, x, y, z).
        v: [..., 3] vectors, broadcastable with ``q``'s batch.

    Returns:
        [..., 3] rotated vectors.
    """
    q = _as_float(q)
    v = _as_float(v, like=q)
    u, v = torch.broadcast_tensors(q[..., 1:], v)
    w = q[..., :1]
    uv = torch.linalg.cross(u, v, dim=-1)
    uuv = torch.linalg.cross(u, uv, dim=-1)
    return v + 2.0 * (w * uv + uuv)


@_numpy_compatible
def quat_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrix of a quaternion (normalised first).

    Args:
        q: [..., 4] (w, x, y, z), any non-zero norm.

    Returns:
        [..., 3, 3] rotation matrix ``R`` with ``R @ v == quat_rotate(q, v)``.
    """
    q = _as_float(q)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    rows = _matrix_entries(*q.unbind(-1))
    return torch.stack(rows, dim=-1).reshape(*q.shape[:-1], 3, 3)


def _matrix_entries(w: Any, x: Any, y: Any, z: Any) -> tuple[Any, ...]:
    """The 9 entries (row-major) of the rotation of a unit quaternion; numpy or torch."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1 - 2 * (yy + zz),
        2 * (xy - wz),
        2 * (xz + wy),
        2 * (xy + wz),
        1 - 2 * (xx + zz),
        2 * (yz - wx),
        2 * (xz - wy),
        2 * (yz + wx),
        1 - 2 * (xx + yy),
    )


def _shepperd_rows(R: Any) -> tuple[tuple[Any, ...], tuple[tuple[Any, ...], ...]]:
    """Shepperd's 4 pivots and 4 candidates (each 4 x its pivot component times the
    quaternion) of rotations ``R`` [..., 3, 3]; numpy or torch, unstacked."""
    r00, r01, r02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    r10, r11, r12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    r20, r21, r22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    tr = r00 + r11 + r22
    pivots = (1 + tr, 1 + 2 * r00 - tr, 1 + 2 * r11 - tr, 1 + 2 * r22 - tr)
    cand = (
        (pivots[0], r21 - r12, r02 - r20, r10 - r01),
        (r21 - r12, pivots[1], r01 + r10, r02 + r20),
        (r02 - r20, r01 + r10, pivots[2], r12 + r21),
        (r10 - r01, r02 + r20, r12 + r21, pivots[3]),
    )
    return pivots, cand


@_numpy_compatible
def matrix_to_quat(R: torch.Tensor) -> torch.Tensor:
    """Quaternion of a rotation matrix (Shepperd's method, robust for all angles).

    Shepperd (1978), "Quaternion from rotation matrix", J. Guidance & Control 1(3): of the four
    candidate formulas, use the one whose pivot (``1 + trace`` or ``1 + 2 R_ii - trace``) is
    largest, so the square root never approaches zero.

    Args:
        R: [..., 3, 3] rotation matrix (orthonormal, det +1).

    Returns:
        [..., 4] unit quaternion (w, x, y, z) with ``w >= 0``.
    """
    pivot_rows, cand_rows = _shepperd_rows(_as_float(R))
    pivots = torch.stack(pivot_rows, dim=-1)
    cand = torch.stack([torch.stack(c, dim=-1) for c in cand_rows], dim=-2)  # [..., 4, 4]
    best = pivots.argmax(dim=-1, keepdim=True)  # [..., 1]
    q = torch.gather(cand, -2, best[..., None].expand(*best.shape, 4)).squeeze(-2)
    return quat_normalize(q)


def quat_to_matrix_np(q: np.ndarray) -> np.ndarray:
    """Numpy face of :func:`quat_to_matrix` (float64, no torch).

    Args:
        q: [..., 4] quaternion (w, x, y, z), normalised here (norm floor 1e-12).

    Returns:
        [..., 3, 3] rotation matrix.
    """
    q = np.asarray(q, np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)
    rows = _matrix_entries(q[..., 0], q[..., 1], q[..., 2], q[..., 3])
    return np.stack(rows, axis=-1).reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat_np(R: np.ndarray) -> np.ndarray:
    """Numpy face of :func:`matrix_to_quat` (float64, no torch; Shepperd 1978, largest pivot).

    Args:
        R: [..., 3, 3] rotation matrix (orthonormal, det +1).

    Returns:
        [..., 4] unit quaternion (w, x, y, z) with ``w >= 0``.
    """
    pivot_rows, cand_rows = _shepperd_rows(np.asarray(R, np.float64))
    pivots = np.stack(pivot_rows, axis=-1)
    cand = np.stack([np.stack(c, axis=-1) for c in cand_rows], axis=-2)  # [..., 4, 4]
    best = np.argmax(pivots, axis=-1)[..., None, None]
    q = np.take_along_axis(cand, best, axis=-2)[..., 0, :]
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0, -q, q)


@_numpy_compatible
def quat_slerp(q0: torch.Tensor, q1: torch.Tensor, t: torch.Tensor | float) -> torch.Tensor:
    """Spherical linear interpolation along the shortest arc.

    Shoemake (1985), "Animating rotation with quaternion curves", SIGGRAPH. When
    ``dot(q0, q1) < 0`` the sign of ``q1`` is flipped so the path is the short one; nearly
    parallel inputs fall back to normalised linear interpolation.

    Args:
        q0: [..., 4] unit quaternion at t = 0.
        q1: [..., 4] unit quaternion at t = 1.
        t: [...] or scalar interpolation parameter (0..1; values outside extrapolate).

    Returns:
        [..., 4] unit quaternion, ``w >= 0``.
    """
    q0 = _as_float(q0)
    q1 = _as_float(q1, like=q0)
    t = _as_float(t, like=q0)[..., None]
    dot = (q0 * q1).sum(-1, keepdim=True)
    q1 = torch.where(dot < 0, -q1, q1)
    dot = dot.abs().clamp(max=1.0)
    theta = torch.acos(dot)
    sin_theta = torch.sin(theta)
    near = sin_theta < 1e-6
    safe_sin = torch.where(near, torch.ones_like(sin_theta), sin_theta)
    w0 = torch.where(near, 1 - t, torch.sin((1 - t) * theta) / safe_sin)
    w1 = torch.where(near, t, torch.sin(t * theta) / safe_sin)
    return quat_normalize(w0 * q0 + w1 * q1)


@_numpy_compatible
def quat_angle_between(q0: torch.Tensor, q1: torch.Tensor) -> torch.Tensor:
    """Geodesic angle between two rotations given as unit quaternions.

    Args:
        q0: [..., 4] (w, x, y, z).
        q1: [..., 4] (w, x, y, z).

    Returns:
        [...] angle in radians, in [0, pi].
    """
    q0 = _as_float(q0)
    q1 = _as_float(q1, like=q0)
    rel = quat_multiply(quat_conjugate(q0), q1)
    vec = rel[..., 1:].norm(dim=-1)
    return 2.0 * torch.atan2(vec, rel[..., 0].abs())


# --------------------------------------------------------------------------- rotation matrices


def _skew(v: torch.Tensor) -> torch.Tensor:
    """[..., 3] -> [..., 3, 3] cross-product matrix."""
    x, y, z = v.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack((o, -z, y, z, o, -x, -y, x, o), dim=-1).reshape(*v.shape[:-1], 3, 3)


@_numpy_compatible
def axis_angle_to_matrix(axis: torch.Tensor, angle: torch.Tensor | float) -> torch.Tensor:
    """Rodrigues' formula ``R = I + sin(a) K + (1 - cos(a)) K^2`` for a unit axis.

    Args:
        axis: [..., 3] rotation axis (normalised here).
        angle: [...] or scalar angle in radians (right-hand rule about ``axis``).

    Returns:
        [..., 3, 3] rotation matrix.
    """
    axis = _as_float(axis)
    angle = _as_float(angle, like=axis)
    axis = axis / axis.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    K = _skew(axis)
    s = torch.sin(angle)[..., None, None]
    c = torch.cos(angle)[..., None, None]
    eye = torch.eye(3, dtype=axis.dtype, device=axis.device)
    return eye + s * K + (1 - c) * (K @ K)


@_numpy_compatible
def rotvec_to_matrix(rotvec: torch.Tensor) -> torch.Tensor:
    """Rotation matrix of a rotation vector (axis * angle), smooth through zero.

    Args:
        rotvec: [..., 3] axis-angle vector, radians.

    Returns:
        [..., 3, 3] rotation matrix.
    """
    rotvec = _as_float(rotvec)
    theta2 = (rotvec * rotvec).sum(-1)
    small = theta2 < 1e-8
    theta2_safe = torch.where(small, torch.ones_like(theta2), theta2)
    theta = torch.sqrt(theta2_safe)
    # sin(t)/t and (1 - cos(t))/t^2 with Taylor series near 0 (keeps gradients finite).
    a = torch.where(small, 1 - theta2 / 6, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24, (1 - torch.cos(theta)) / theta2_safe)
    K = _skew(rotvec)
    eye = torch.eye(3, dtype=rotvec.dtype, device=rotvec.device)
    return eye + a[..., None, None] * K + b[..., None, None] * (K @ K)


@_numpy_compatible
def matrix_to_rotvec(R: torch.Tensor) -> torch.Tensor:
    """Rotation vector (axis * angle, angle in [0, pi]) of a rotation matrix.

    Goes through :func:`matrix_to_quat`, which stays accurate near 0 and pi.

    Args:
        R: [..., 3, 3] rotation matrix.

    Returns:
        [..., 3] rotation vector, radians.
    """
    q = matrix_to_quat(_as_float(R))
    vec = q[..., 1:]
    s = vec.norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(s, q[..., :1])
    small = s < 1e-8
    scale = torch.where(small, 2.0 / q[..., :1].clamp_min(1e-12), angle / torch.where(small, 1, s))
    return vec * scale


@_numpy_compatible
def rotation_angle(R: torch.Tensor) -> torch.Tensor:
    """Angle of a rotation matrix, accurate over [0, pi].

    Uses ``atan2(|vee(R - R^T)| / 2, (trace(R) - 1) / 2)``, which keeps precision near 0
    where ``acos`` loses it.

    Args:
        R: [..., 3, 3] rotation matrix (e.g. ``R_a^T @ R_b`` for the angle between two).

    Returns:
        [...] radians.
    """
    R = _as_float(R)
    v = torch.stack(
        (R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]),
        dim=-1,
    )
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    return torch.atan2(0.5 * v.norm(dim=-1), 0.5 * (tr - 1))


def _rot_axis(angle: Any, axis: int) -> torch.Tensor:
    a = _as_float(angle)
    c, s = torch.cos(a), torch.sin(a)
    o, i = torch.zeros_like(a), torch.ones_like(a)
    if axis == 0:
        m = (i, o, o, o, c, -s, o, s, c)
    elif axis == 1:
        m = (c, o, s, o, i, o, -s, o, c)
    else:
        m = (c, -s, o, s, c, o, o, o, i)
    return torch.stack(m, dim=-1).reshape(*a.shape, 3, 3)


@_numpy_compatible
def rot_x(angle: torch.Tensor | float) -> torch.Tensor:
    """[..., 3, 3] rotation about x by ``angle`` radians (right-hand rule)."""
    return _rot_axis(angle, 0)


@_numpy_compatible
def rot_y(angle: torch.Tensor | float) -> torch.Tensor:
    """[..., 3, 3] rotation about y by ``angle`` radians (right-hand rule)."""
    return _rot_axis(angle, 1)


@_numpy_compatible
def rot_z(angle: torch.Tensor | float) -> torch.Tensor:
    """[..., 3, 3] rotation about z by ``angle`` radians (right-hand rule)."""
    return _rot_axis(angle, 2)


@_numpy_compatible
def rpy_to_matrix(rpy: torch.Tensor) -> torch.Tensor:
    """URDF ``rpy``: fixed-axis roll about x, then pitch about y, then yaw about z.

    ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (ROS REP 103 / URDF ``<origin rpy>``).

    Args:
        rpy: [..., 3] (roll, pitch, yaw) radians.

    Returns:
        [..., 3, 3] rotation matrix.
    """
    rpy = _as_float(rpy)
    return _rot_axis(rpy[..., 2], 2) @ _rot_axis(rpy[..., 1], 1) @ _rot_axis(rpy[..., 0], 0)


# --------------------------------------------------------------------------- homogeneous transforms


@_numpy_compatible
def make_T(R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Homogeneous transform from a rotation and a translation.

    Args:
        R: [..., 3, 3] rotation.
        t: [..., 3] translation in metres (broadcast with ``R``'s batch).

    Returns:
        [..., 4, 4] ``[[R, t], [0, 0, 0, 1]]``.
    """
    R = _as_float(R)
    t = _as_float(t, like=R)
    batch = torch.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    R = R.expand(*batch, 3, 3)
    t = t.expand(*batch, 3)
    top = torch.cat((R, t[..., None]), dim=-1)
    bottom = torch.zeros(*batch, 1, 4, dtype=R.dtype, device=R.device)
    bottom[..., 0, 3] = 1.0
    return torch.cat((top, bottom), dim=-2)


@_numpy_compatible
def invert_T(T: torch.Tensor) -> torch.Tensor:
    """Inverse of a rigid transform, ``[[R^T, -R^T t], [0, 1]]`` (no general matrix inverse).

    Args:
        T: [..., 4, 4] rigid transform ``T_a_b``.

    Returns:
        [..., 4, 4] ``T_b_a``.
    """
    T = _as_float(T)
    Rt = T[..., :3, :3].transpose(-1, -2)
    t = -(Rt @ T[..., :3, 3:4])[..., 0]
    return make_T(Rt, t)


@_numpy_compatible
def compose(*Ts: torch.Tensor) -> torch.Tensor:
    """Chain transforms left to right: ``compose(T_a_b, T_b_c) == T_a_c``.

    Args:
        *Ts: [..., 4, 4] transforms with broadcastable batch shapes (at least one).

    Returns:
        [..., 4, 4] product ``Ts[0] @ Ts[1] @ ...``.
    """
    if not Ts:
        raise TypeError("compose() needs at least one transform")
    out = _as_float(Ts[0])
    for T in Ts[1:]:
        out = out @ _as_float(T, like=out)
    return out


@_numpy_compatible
def transform_points(T: torch.Tensor, p: torch.Tensor) -> torch.Tensor:
    """Apply ``T_a_b`` to points expressed in frame ``b``.

    Args:
        T: [..., 4, 4] transform (batch broadcast against ``p``'s leading dims).
        p: [..., 3] points in metres.

    Returns:
        [..., 3] points in frame ``a``.
    """
    T = _as_float(T)
    p = _as_float(p, like=T)
    return (T[..., :3, :3] @ p[..., None])[..., 0] + T[..., :3, 3]


# --------------------------------------------------------------------------- axis conventions

T_CV_GL: np.ndarray = np.diag([1.0, -1.0, -1.0, 1.0])
"""``T_cv_gl``: maps points in an OpenGL camera frame (x right, y up, z back) to the OpenCV
camera frame (x right, y down, z forward). It is its own inverse (``T_gl_cv == T_CV_GL``)."""

T_ZUP_YUP: np.ndarray = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
"""``T_zup_yup``: maps points of a y-up world (x right, y up, z toward the viewer; OpenGL, glTF)
to a z-up world (ROS/URDF), a +90 degree rotation about x: ``(x, y, z) -> (x, -z, y)``.
Its inverse is its transpose."""

_T_YUP_ZUP: np.ndarray = T_ZUP_YUP.T.copy()


def _const_like(M: np.ndarray, T: torch.Tensor) -> torch.Tensor:
    return torch.as_tensor(M, dtype=T.dtype, device=T.device)


@_numpy_compatible
def cam_gl_to_cv(T_world_camgl: torch.Tensor) -> torch.Tensor:
    """Camera pose with OpenGL axes -> the same camera with OpenCV axes.

    ``T_world_camcv = T_world_camgl @ T_gl_cv`` (nerfstudio/Blender c2w -> robogs extrinsics).

    Args:
        T_world_camgl: [..., 4, 4] camera-to-world, OpenGL camera axes.

    Returns:
        [..., 4, 4] camera-to-world, OpenCV camera axes.
    """
    T = _as_float(T_world_camgl)
    return T @ _const_like(T_CV_GL, T)


@_numpy_compatible
def cam_cv_to_gl(T_world_camcv: torch.Tensor) -> torch.Tensor:
    """Camera pose with OpenCV axes -> OpenGL axes (inverse of :func:`cam_gl_to_cv`).

    Args:
        T_world_camcv: [..., 4, 4] camera-to-world, OpenCV camera axes.

    Returns:
        [..., 4, 4] camera-to-world, OpenGL camera axes.
    """
    T = _as_float(T_world_camcv)
    return T @ _const_like(T_CV_GL, T)


@_numpy_compatible
def world_yup_to_zup(T_yup_x: torch.Tensor) -> torch.Tensor:
    """Re-express a pose given in a y-up world in the z-up world: ``T_zup_yup @ T_yup_x``.

    Args:
        T_yup_x: [..., 4, 4] pose of some frame x in the y-up world.

    Returns:
        [..., 4, 4] pose of x in the z-up world (the frame x itself is unchanged).
    """
    T = _as_float(T_yup_x)
    return _const_like(T_ZUP_YUP, T) @ T


@_numpy_compatible
def world_zup_to_yup(T_zup_x: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`world_yup_to_zup`: ``T_yup_zup @ T_zup_x``.

    Args:
        T_zup_x: [..., 4, 4] pose of some frame x in the z-up world.

    Returns:
        [..., 4, 4] pose of x in the y-up world.
    """
    T = _as_float(T_zup_x)
    return _const_like(_T_YUP_ZUP, T) @ T
