"""The joint-value tensor every forward-kinematics model takes (one check for ``Chain`` and
``MDHTable``)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from robogs.format.errors import InputError

__all__ = ["as_joint_tensor"]


def as_joint_tensor(q, joint_names: Sequence[str]) -> torch.Tensor:
    """``q`` as a floating tensor shaped ``[..., len(joint_names)]``.

    A numpy array or list becomes float64; an integer tensor becomes float64; a floating tensor
    keeps its dtype and device. Units are the joints' own (rad or m).

    Raises:
        InputError: the last axis does not have one value per joint.
    """
    if not isinstance(q, torch.Tensor):
        q = torch.as_tensor(np.asarray(q), dtype=torch.float64)
    if not q.is_floating_point():
        q = q.to(torch.float64)
    if q.ndim == 0 or q.shape[-1] != len(joint_names):
        raise InputError(
            f"q has shape {tuple(q.shape)}, expected [..., {len(joint_names)}]",
            hint=f"joint order: {list(joint_names)}",
        )
    return q
