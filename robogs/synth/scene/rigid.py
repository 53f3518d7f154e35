"""Small numpy rigid-transform helpers for the synthetic generator.

Kept separate from ``robogs.format.frames`` on purpose: the generator is the
ground truth that tests those utilities, so it must not share their code.

Conventions: quaternions are (w, x, y, z); ``T_a_b`` maps points in frame b to
frame a; URDF ``rpy`` means R = Rz(yaw) @ Ry(pitch) @ Rx(roll).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_to_matrix",
    "matrix_to_rpy",
    "axis_angle_matrix",
    "make_T",
    "invert_T",
    "matrix_to_quat",
    "quat_to_matrix",
    "yaw_quat",
    "transform_points",
]


def rot_x(a: float) -> np.ndarray:
    """[3, 3] rotation about x by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """[3, 3] rotation about y by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """[3, 3] rotation about z by ``a`` rad."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw (rad) to a [3, 3] rotation."""
    r, p, y = (float(v) for v in rpy)
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix` (pitch in [-pi/2, pi/2])."""
    pitch = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
    if abs(np.cos(pitch)) > 1e-9:
        roll = np.arctan2(R[2, 1], R[2, 2])
        yaw = np.arctan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: fold yaw into roll
        roll = np.arctan2(-R[1, 2], R[1, 1])
        yaw = 0.0
    return np.array([roll, pitch, yaw])


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues' formula, batched: unit ``axis`` [3], ``angle`` [B] rad -> [B, 3, 3]."""
    angle = np.asarray(angle, dtype=np.float64)
    x, y, z = (float(v) for v in axis)
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    s = np.sin(angle)[..., None, None]
    c = np.cos(angle)[..., None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def make_T(R: np.ndarray | None = None, p: np.ndarray | None = None) -> np.ndarray:
    """[4, 4] homogeneous transform from a rotation and a translation (metres)."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def invert_T(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (any leading batch dimensions)."""
    R = T[..., :3, :3]
    p = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    out[..., 3, 3] = 1.0
    return out


# Own copy on purpose: synth builds the oracles, so it must not share robogs.format.frames.
def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrices [..., 3, 3] to unit quaternions [..., 4] (w, x, y, z), w >= 0.

    Shepperd's method: pick the largest of (w, x, y, z) squared for stability.
    """
    R = np.asarray(R, dtype=np.float64)
    m = R.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=-1)
    k = np.argmax(cand, axis=-1)
    q = np.empty((m.shape[0], 4))
    # case w largest
    s = np.sqrt(np.maximum(1.0 + tr, 1e-300)) * 2.0
    qw = np.stack(
        [
            0.25 * s,
            (m[:, 2, 1] - m[:, 1, 2]) / s,
            (m[:, 0, 2] - m[:, 2, 0]) / s,
            (m[:, 1, 0] - m[:, 0, 1]) / s,
        ],
        -1,
    )
    s = np.sqrt(np.maximum(1.0 + m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2], 1e-300)) * 2.0
    qx = np.stack(
        [
            (m[:, 2, 1] - m[:, 1, 2]) / s,
            0.25 * s,
            (m[:, 0, 1] + m[:, 1, 0]) / s,
            (m[:, 0, 2] + m[:, 2, 0]) / s,
        ],
        -1,
    )
    s = np.sqrt(np.maximum(1.0 - m[:, 0, 0] + m[:, 1, 1] - m[:, 2, 2], 1e-300)) * 2.0
    qy = np.stack(
        [
            (m[:, 0, 2] - m[:, 2, 0]) / s,
            (m[:, 0, 1] + m[:, 1, 0]) / s,
            0.25 * s,
            (m[:, 1, 2] + m[:, 2, 1]) / s,
        ],
        -1,
    )
    s = np.sqrt(np.maximum(1.0 - m[:, 0, 0] - m[:, 1, 1] + m[:, 2, 2], 1e-300)) * 2.0
    qz = np.stack(
        [
            (m[:, 1, 0] - m[:, 0, 1]) / s,
            (m[:, 0, 2] + m[:, 2, 0]) / s,
            (m[:, 1, 2] + m[:, 2, 1]) / s,
            0.25 * s,
        ],
        -1,
    )
    for i, cq in enumerate((qw, qx, qy, qz)):
        sel = k == i
        q[sel] = cq[sel]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    return q.reshape(R.shape[:-2] + (4,))


# Own copy on purpose: synth builds the oracles, so it must not share robogs.format.frames.
def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Quaternions [..., 4] (w, x, y, z), normalised here, to rotations [..., 3, 3]."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.stack(
        [
            1 - 2 * (y * y + z * z),
            2 * (x * y - w * z),
            2 * (x * z + w * y),
            2 * (x * y + w * z),
            1 - 2 * (x * x + z * z),
            2 * (y * z - w * x),
            2 * (x * z - w * y),
            2 * (y * z + w * x),
            1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return R.reshape(q.shape[:-1] + (3, 3))


def yaw_quat(yaw: np.ndarray) -> np.ndarray:
    """Quaternions [..., 4] (w, x, y, z) of rotations about +z by ``yaw`` rad, w >= 0."""
    yaw = np.asarray(yaw, dtype=np.float64)
    q = np.stack(
        [np.cos(yaw / 2), np.zeros_like(yaw), np.zeros_like(yaw), np.sin(yaw / 2)], axis=-1
    )
    return np.where(q[..., :1] < 0, -q, q)


def transform_points(T: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Apply ``T`` [..., 4, 4] to points [..., N, 3] (metres)."""
    return np.einsum("...ij,...nj->...ni", T[..., :3, :3], pts) + T[..., None, :3, 3]
