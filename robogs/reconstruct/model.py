"""Trainable Gaussians with their Adam state, and the tensor surgery densification needs.

Parameters are stored in pre-activation form (the splat PLY layout): centres, quaternions
(w, x, y, z), log-scales (2 for surfels, 3 for 3D Gaussians), opacity logits, SH DC and the
higher SH bands. Each has its own Adam parameter group and learning rate (Kerbl et al. 2023).
Cloning, splitting and pruning keep the Adam moments of surviving Gaussians and start new ones
at zero, as the 3DGS reference does.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from robogs.format.render import Gaussians

__all__ = ["GaussianModel", "LearningRates", "PARAM_NAMES"]

PARAM_NAMES = ("means", "quats", "log_scales", "opacity_logits", "sh_dc", "sh_rest")


@dataclass(frozen=True)
class LearningRates:
    """Adam step sizes (3DGS defaults; ``means`` is multiplied by the scene extent, m)."""

    means: float = 1.6e-4
    means_final: float = 1.6e-6
    quats: float = 1e-3
    log_scales: float = 5e-3
    opacity_logits: float = 5e-2
    sh_dc: float = 2.5e-3
    sh_rest: float = 2.5e-3 / 20.0


class GaussianModel:
    """N Gaussians as leaf tensors plus one Adam optimiser.

    Args:
        tensors: name -> tensor for every name in :data:`PARAM_NAMES` (``sh_rest`` may have 0
            coefficients).
        lrs: learning rates.
        extent: scene extent, m (scales the centre learning rate).
    """

    def __init__(self, tensors: dict[str, torch.Tensor], lrs: LearningRates, extent: float) -> None:
        self.lrs = lrs
        self.extent = float(extent)
        self.params = {k: tensors[k].detach().clone().requires_grad_(True) for k in PARAM_NAMES}
        groups = [{"params": [self.params[k]], "lr": self._lr(k), "name": k} for k in PARAM_NAMES]
        # on a GPU, torch's fused Adam: two launches per group and step instead of ~15 (the
        # training step is launch-bound there); on the CPU the default loop, as before
        fused = all(t.is_cuda for t in self.params.values())
        self.optimizer = torch.optim.Adam(groups, lr=0.0, eps=1e-15, fused=fused or None)

    def _lr(self, name: str) -> float:
        lr = getattr(self.lrs, name)
        return lr * self.extent if name == "means" else lr

    def __len__(self) -> int:
        return int(self.params["means"].shape[0])

    @property
    def kind(self) -> str:
        return "2dgs" if self.params["log_scales"].shape[1] == 2 else "3dgs"

    def gaussians(self, extra: torch.Tensor | None = None) -> Gaussians:
        """The differentiable :class:`Gaussians` of the current parameters."""
        p = self.params
        sh = torch.cat([p["sh_dc"], p["sh_rest"]], dim=1)
        return Gaussians(
            p["means"], p["quats"], p["log_scales"], p["opacity_logits"], sh, extra=extra
        )

    def set_means_lr(self, progress: float) -> None:
        """Log-linear decay of the centre learning rate from ``means`` to ``means_final``."""
        t = min(max(progress, 0.0), 1.0)
        lr0, lr1 = self.lrs.means * self.extent, self.lrs.means_final * self.extent
        lr = lr0 ** (1 - t) * lr1**t
        for g in self.optimizer.param_groups:
            if g["name"] == "means":
                g["lr"] = lr

    # -- surgery ---------------------------------------------------------------------------
    def _replace(self, name: str, new: torch.Tensor, state: dict[str, torch.Tensor] | None) -> None:
        old = self.params[name]
        param = new.detach().requires_grad_(True)
        for g in self.optimizer.param_groups:
            if g["params"][0] is old:
                g["params"][0] = param
        self.optimizer.state.pop(old, None)
        if state is not None:
            self.optimizer.state[param] = state
        self.params[name] = param

    def keep(self, mask: torch.Tensor) -> None:
        """Keep only the Gaussians where ``mask`` [N] is True (moments kept)."""
        for k in PARAM_NAMES:
            st = self.optimizer.state.get(self.params[k])
            new_state = None
            if st:
                new_state = {
                    "step": st["step"],
                    "exp_avg": st["exp_avg"][mask],
                    "exp_avg_sq": st["exp_avg_sq"][mask],
                }
            self._replace(k, self.params[k][mask], new_state)

    def append(self, tensors: dict[str, torch.Tensor]) -> None:
        """Add Gaussians (new Adam moments are zero)."""
        for k in PARAM_NAMES:
            old = self.params[k]
            st = self.optimizer.state.get(old)
            new_state = None
            if st:
                z = torch.zeros_like(tensors[k])
                new_state = {
                    "step": st["step"],
                    "exp_avg": torch.cat([st["exp_avg"], z]),
                    "exp_avg_sq": torch.cat([st["exp_avg_sq"], z]),
                }
            self._replace(k, torch.cat([old.detach(), tensors[k].to(old)]), new_state)

    def reset_opacity(self, max_opacity: float = 0.01) -> None:
        """Clamp every opacity to ``max_opacity`` (logit space) and clear its moments."""
        cap = torch.logit(torch.tensor(max_opacity))
        new = torch.minimum(
            self.params["opacity_logits"].detach(), cap.to(self.params["opacity_logits"])
        )
        st = self.optimizer.state.get(self.params["opacity_logits"])
        new_state = None
        if st:
            new_state = {
                "step": st["step"],
                "exp_avg": torch.zeros_like(new),
                "exp_avg_sq": torch.zeros_like(new),
            }
        self._replace("opacity_logits", new, new_state)

    # -- checkpoint state ---------------------------------------------------------------------
    def state(self) -> dict[str, dict[str, torch.Tensor]]:
        """Tensors only: parameters and Adam moments (for ``torch.save``)."""
        out: dict[str, dict[str, torch.Tensor]] = {
            "params": {},
            "exp_avg": {},
            "exp_avg_sq": {},
            "step": {},
        }
        for k in PARAM_NAMES:
            p = self.params[k]
            out["params"][k] = p.detach().clone()
            st = self.optimizer.state.get(p)
            if st:
                out["exp_avg"][k] = st["exp_avg"].clone()
                out["exp_avg_sq"][k] = st["exp_avg_sq"].clone()
                out["step"][k] = torch.as_tensor(st["step"]).clone()
        return out

    @classmethod
    def from_state(
        cls,
        state: dict[str, dict[str, torch.Tensor]],
        lrs: LearningRates,
        extent: float,
        device: torch.device,
    ) -> GaussianModel:
        model = cls({k: v.to(device) for k, v in state["params"].items()}, lrs, extent)
        for k in PARAM_NAMES:
            if k in state["exp_avg"]:
                # the fused (GPU) Adam keeps its step count on the parameter's device
                step_device = device if model.optimizer.defaults["fused"] else "cpu"
                model.optimizer.state[model.params[k]] = {
                    "step": state["step"][k].to(torch.float32).to(step_device),
                    "exp_avg": state["exp_avg"][k].to(device),
                    "exp_avg_sq": state["exp_avg_sq"][k].to(device),
                }
        return model
