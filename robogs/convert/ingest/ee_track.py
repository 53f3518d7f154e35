"""Which robot link, if any, a recorded pose stream follows (a pose's role from its meaning).

A pose topic given in a robot link's frame (usually the base) is compared with forward
kinematics of the joint states at the pose stamps. For every link ``l`` the constant offset
``d`` (m, in the link frame) that best explains the poses is the least-squares solution of
``p_i ≈ t_l(q_i) + R_l(q_i) d``; because ``R`` is a rotation the normal equations reduce to
``d = mean_i R_l(q_i)^T (p_i - t_l(q_i))``. The residual RMS (m) says how well the link's path
explains the poses. Only positions are compared.

The stream *tracks* the best link when its residual RMS is below ``max(abs_tol_m,
rel_tol * spread)`` (``spread``: RMS distance of the poses from their mean) and the poses move
(``spread >= min_spread_m``). Every link rigidly attached to the tracked one fits as well (with
another offset): the one whose origin lies nearest the poses (smallest ``|d|``) is chosen, ties
within 1 mm going to the link furthest down the tree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from robogs.format.kinematics import Chain

__all__ = ["LinkFit", "link_fits", "tracked_link"]


@dataclass(frozen=True)
class LinkFit:
    """How well one link's path explains a pose stream.

    Attributes:
        link: URDF link name.
        rms_m: residual RMS after the best constant offset (m).
        offset_m: that offset's length (m).
        spread_m: RMS distance of the poses from their mean (m).
        samples: poses compared.
    """

    link: str
    rms_m: float
    offset_m: float
    spread_m: float
    samples: int


def link_fits(
    chain: Chain,
    frame: str,
    joint_t_ns: np.ndarray,
    joint_q: np.ndarray,
    pose_t_ns: np.ndarray,
    pose_xyz: np.ndarray,
) -> list[LinkFit]:
    """Fit of every link to poses given in link ``frame``, in ``chain.link_names`` order.

    Args:
        chain: the robot.
        frame: link the poses are expressed in.
        joint_t_ns: [M] sorted joint stamps (ns); joint_q: [M, J] positions in
            ``chain.joint_names`` order (rad or m).
        pose_t_ns: [N] pose stamps (ns); pose_xyz: [N, 3] positions in ``frame`` (m).

    Returns:
        One :class:`LinkFit` per link; empty when fewer than 10 poses fall within the joint
        stamps.
    """
    jt = np.asarray(joint_t_ns, np.int64)
    pt = np.asarray(pose_t_ns, np.int64)
    inside = (pt >= jt[0]) & (pt <= jt[-1]) if jt.size else np.zeros(pt.size, bool)
    if int(inside.sum()) < 10:
        return []
    pt, p = pt[inside], np.asarray(pose_xyz, np.float64)[inside]
    x = (jt - jt[0]).astype(np.float64)
    xq = (pt - jt[0]).astype(np.float64)
    q = np.stack([np.interp(xq, x, joint_q[:, k]) for k in range(joint_q.shape[1])], axis=1)
    with torch.no_grad():
        T = chain.forward(torch.as_tensor(q, dtype=torch.float64)).numpy()  # [N, L, 4, 4]
    T_root_frame = T[:, chain.link_index(frame)]
    p_root = np.einsum("nij,nj->ni", T_root_frame[:, :3, :3], p) + T_root_frame[:, :3, 3]
    spread = float(np.sqrt(np.mean(np.sum((p_root - p_root.mean(0)) ** 2, axis=1))))
    out = []
    for k, name in enumerate(chain.link_names):
        R, t = T[:, k, :3, :3], T[:, k, :3, 3]
        local = np.einsum("nji,nj->ni", R, p_root - t)  # R^T (p - t)
        d = local.mean(axis=0)
        r = p_root - t - np.einsum("nij,j->ni", R, d)
        rms = float(np.sqrt(np.mean(np.sum(r * r, axis=1))))
        out.append(LinkFit(name, rms, float(np.linalg.norm(d)), spread, int(pt.size)))
    return out


def tracked_link(
    fits: list[LinkFit],
    *,
    abs_tol_m: float = 0.003,
    rel_tol: float = 0.05,
    min_spread_m: float = 0.005,
) -> LinkFit | None:
    """The link a pose stream tracks (see the module docstring), or None."""
    if not fits or fits[0].spread_m < min_spread_m:
        return None
    best = min(f.rms_m for f in fits)
    tol = max(abs_tol_m, rel_tol * fits[0].spread_m)
    if best > tol:
        return None
    ok = [(i, f) for i, f in enumerate(fits) if f.rms_m <= best + 0.2 * tol]
    near = min(f.offset_m for _, f in ok)
    return max((i, f) for i, f in ok if f.offset_m <= near + 0.001)[1]
