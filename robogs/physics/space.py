"""Parameter space: the ordered set of (owner, parameter) slots a model is fitted over.

The fitter works on a matrix ``theta [M, Q]``: M parameter sets (problems, finite-difference
perturbations) times Q slots. A slot belongs either to the base model (owner ``"base"``) or to
an effect (owner = effect name). Slots not being fitted sit at their zero value, which switches
their effect off, so one rollout serves every candidate model at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from robogs.physics.effects import Effect, Param

__all__ = ["Slot", "ParamSpace", "BASE"]

BASE = "base"


@dataclass(frozen=True)
class Slot:
    """One fitted quantity: ``owner`` is ``"base"`` or an effect name."""

    owner: str
    param: Param

    @property
    def key(self) -> str:
        """``owner.param`` as used in reports."""
        return f"{self.owner}.{self.param.name}"


class ParamSpace:
    """Slots of the base parameters followed by those of the given effects.

    Args:
        base: the base model's refitted parameters (their ``zero`` is the nominal value).
        effects: effects whose parameters get slots.
    """

    def __init__(self, base: Sequence[Param], effects: Sequence[Effect]) -> None:
        self.base = tuple(base)
        self.effects = tuple(effects)
        slots = [Slot(BASE, p) for p in self.base]
        for e in self.effects:
            slots.extend(Slot(e.name, p) for p in e.params)
        self.slots: tuple[Slot, ...] = tuple(slots)
        self._index = {(s.owner, s.param.name): i for i, s in enumerate(self.slots)}
        self.lower = np.array([s.param.lower for s in self.slots], dtype=float)
        self.upper = np.array([s.param.upper for s in self.slots], dtype=float)
        self.zero = np.array([s.param.zero for s in self.slots], dtype=float)
        self.scale = np.array(
            [max(abs(s.param.nominal), 1e-3 * (s.param.upper - s.param.lower)) for s in self.slots],
            dtype=float,
        )

    def __len__(self) -> int:
        return len(self.slots)

    def index(self, owner: str, name: str) -> int:
        """Column of a slot."""
        return self._index[(owner, name)]

    def owner_columns(self, owner: str) -> list[int]:
        """Columns of all slots of one owner."""
        return [i for i, s in enumerate(self.slots) if s.owner == owner]

    def theta_dict(self, theta: torch.Tensor, owner: str) -> dict[str, torch.Tensor]:
        """Views ``name -> theta[:, i:i+1]`` ([M, 1]) for one owner's slots."""
        return {
            s.param.name: theta[:, i : i + 1] for i, s in enumerate(self.slots) if s.owner == owner
        }

    def defaults(
        self, m: int = 1, *, dtype: torch.dtype = torch.float64, device=None
    ) -> torch.Tensor:
        """``[m, Q]`` with every slot at its zero value (the base model)."""
        z = torch.as_tensor(self.zero, dtype=dtype, device=device)
        return z.unsqueeze(0).repeat(m, 1)
