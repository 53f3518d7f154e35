"""Gradient-driven densification and pruning (Kerbl et al. 2023, §5.2; 2DGS keeps the same rules).

Between refinements the view-space positional gradient of every visible Gaussian is
accumulated (its norm in NDC units, ``|dL/dx_px| * (W/2, H/2)``, as the reference CUDA code
reports it; ``train.screen_gradient`` derives dL/dx_px from the gradient of the 3D centre). At a refinement step, Gaussians whose mean gradient exceeds ``grad_threshold`` are

* **cloned** (a copy at the same place, moved by the optimiser afterwards) when their largest
  scale is at most ``percent_dense x extent``;
* **split** into two, sampled from the Gaussian itself (the surfel's tangent plane for 2DGS),
  with scales divided by 1.6, otherwise.

Then Gaussians with opacity below ``min_opacity`` or a largest scale above
``max_scale_fraction x extent`` are pruned. Randomness comes from a generator seeded by the step,
so a resumed run refines exactly as an uninterrupted one.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from robogs.format.frames import quat_to_matrix

from .model import GaussianModel

__all__ = ["DensifyConfig", "GradientStats", "refine"]


@dataclass(frozen=True)
class DensifyConfig:
    """Densification thresholds (3DGS / gsplat ``DefaultStrategy`` defaults, except the gradient
    threshold: 2e-4 densifies about half of the Gaussians at 100-300 px image widths, where NDC
    gradients are smaller than at the ~1000 px of the 3DGS benchmarks; 5e-4 about 15 %)."""

    grad_threshold: float = 5e-4
    percent_dense: float = 0.01
    min_opacity: float = 0.005
    max_scale_fraction: float = 0.1
    max_gaussians: int = 200_000


class GradientStats:
    """Running sums of view-space gradient norms and visibility counts, per Gaussian."""

    def __init__(self, n: int, device: torch.device) -> None:
        self.grad = torch.zeros(n, device=device, dtype=torch.float64)
        self.count = torch.zeros(n, device=device, dtype=torch.float64)

    def add(self, means2d_grad: torch.Tensor, radii: torch.Tensor, width: int, height: int) -> None:
        """Accumulate one view: ``means2d_grad`` [N, 2] (px), ``radii`` [N, 2] (0 where culled)."""
        visible = (radii > 0).any(dim=1)
        g = means2d_grad.detach().to(torch.float64)
        # scaled by Python numbers: a torch.tensor([...], device=cuda) here would be a
        # host-to-device copy, which waits for the device, in every training step
        g = torch.stack([g[:, 0] * (0.5 * width), g[:, 1] * (0.5 * height)], dim=1)
        self.grad += torch.where(visible, g.norm(dim=1), 0.0)
        self.count += visible.to(torch.float64)

    def mean(self) -> torch.Tensor:
        return self.grad / self.count.clamp(min=1.0)

    def reset(self, n: int) -> None:
        self.grad = torch.zeros(n, device=self.grad.device, dtype=torch.float64)
        self.count = torch.zeros(n, device=self.grad.device, dtype=torch.float64)


def _split_samples(
    model: GaussianModel, idx: torch.Tensor, gen: torch.Generator
) -> dict[str, torch.Tensor]:
    """Two Gaussians per index, centres drawn from N(mean, Sigma), scales / 1.6."""
    p = model.params
    means = p["means"].detach()[idx]
    R = quat_to_matrix(
        p["quats"].detach()[idx] / p["quats"].detach()[idx].norm(dim=1, keepdim=True)
    )
    s = p["log_scales"].detach()[idx].exp()
    if s.shape[1] == 2:
        s = torch.cat([s, torch.zeros_like(s[:, :1])], dim=1)
    noise = torch.randn((2, len(idx), 3), generator=gen, dtype=torch.float64).to(means)
    offs = torch.einsum("nij,knj->kni", R, noise * s)
    out = {
        "means": (means[None] + offs).reshape(-1, 3),
        "log_scales": (p["log_scales"].detach()[idx] - torch.log(torch.tensor(1.6))).repeat(2, 1),
    }
    for k in ("quats", "opacity_logits", "sh_dc", "sh_rest"):
        t = p[k].detach()[idx]
        out[k] = t.repeat(2, *([1] * (t.ndim - 1)))
    return out


def refine(
    model: GaussianModel,
    stats: GradientStats,
    cfg: DensifyConfig,
    step: int,
    *,
    seed: int = 0,
    densify: bool = True,
) -> dict[str, int]:
    """One refinement: clone, split, prune. Returns counts (cloned, split, pruned, total).

    Runs on the model's device. It synchronises with the device (``nonzero`` sizes the index
    lists, the counts are read back): acceptable once per ``densify_every`` training steps. The
    split samples are drawn on the CPU from a generator seeded by the step (the same on every
    device) and copied over.
    """
    n0 = len(model)
    extent = model.extent
    cloned = split = 0
    keep_extra = torch.ones(n0, dtype=torch.bool, device=model.params["means"].device)
    if densify and n0 < cfg.max_gaussians:
        grads = stats.mean()
        big = grads >= cfg.grad_threshold
        max_scale = model.params["log_scales"].detach().exp().max(dim=1).values
        small = max_scale <= cfg.percent_dense * extent
        room = cfg.max_gaussians - n0
        clone_idx = torch.nonzero(big & small)[:, 0][:room]
        split_idx = torch.nonzero(big & ~small)[:, 0][: max(0, (room - len(clone_idx)) // 2)]
        gen = torch.Generator().manual_seed(int(seed) * 1_000_003 + int(step))
        new: dict[str, torch.Tensor] | None = None
        if len(clone_idx):
            new = {k: model.params[k].detach()[clone_idx] for k in model.params}
            cloned = len(clone_idx)
        if len(split_idx):
            sp = _split_samples(model, split_idx, gen)
            new = sp if new is None else {k: torch.cat([new[k], sp[k]]) for k in new}
            keep_extra[split_idx] = False
            split = len(split_idx)
        if new is not None:
            model.append(new)
    n1 = len(model)
    keep = torch.ones(n1, dtype=torch.bool, device=keep_extra.device)
    keep[:n0] = keep_extra
    opacity = torch.sigmoid(model.params["opacity_logits"].detach())
    max_scale = model.params["log_scales"].detach().exp().max(dim=1).values
    prune = (opacity < cfg.min_opacity) | (max_scale > cfg.max_scale_fraction * extent)
    prune |= ~torch.isfinite(model.params["means"].detach()).all(dim=1)
    keep &= ~prune
    if keep.sum() == 0:  # never prune everything; keep the most opaque
        keep[int(torch.argmax(opacity))] = True
    model.keep(keep)
    stats.reset(len(model))
    return {
        "cloned": cloned,
        "split": split,
        "pruned": int(n1 - len(model)) - split,
        "total": len(model),
    }
