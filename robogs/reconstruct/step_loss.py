"""The loss of one training step, captured as a CUDA graph on a GPU.

The loss (``losses.py``: L1 + D-SSIM, normal consistency, depth distortion) is about a hundred
small kernels forward and as many backward. On a GPU the training step is bound by launching
them from Python, not by the device. :class:`StepLoss` evaluates the loss as a function of
tensors only (the view's camera enters as :func:`losses.pixel_rays`), so on CUDA it can be
captured once per combination of active terms and image size with
``torch.cuda.make_graphed_callables`` and replayed for every view: one graph launch forward and
one backward. On the CPU, or with ``graphs=False``, the same function runs eagerly. Values and
gradients are those of the eager function (``tests/reconstruct/test_step_loss.py``).
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable

import torch

from .losses import depth_distortion, normal_consistency, photometric_loss

__all__ = ["StepLoss", "step_loss"]


def step_loss(
    rgb: torch.Tensor,
    target: torch.Tensor,
    *terms: torch.Tensor,
    lambda_dssim: float,
    lambda_normal: float = 0.0,
    lambda_dist: float = 0.0,
) -> torch.Tensor:
    """The training loss of one view (a 0-d tensor).

    Args:
        rgb: [H, W, 3] render.
        target: [H, W, 3] image in [0, 1].
        terms: the inputs of the active optional terms, in this order: with ``lambda_normal``
            > 0, (normals [H, W, 3], alpha [H, W], depth [H, W], rays [H, W, 2]); then with
            ``lambda_dist`` > 0, (alpha [H, W], extra [H, W, 2]).
        lambda_dssim, lambda_normal, lambda_dist: weights (0: the term is left out).
    """
    loss = photometric_loss(rgb, target, lambda_dssim)
    rest = list(terms)
    if lambda_normal > 0:
        normals, alpha, depth, rays = rest[:4]
        del rest[:4]
        loss = loss + lambda_normal * normal_consistency(normals, alpha, depth, rays)
    if lambda_dist > 0:
        alpha, extra = rest[:2]
        del rest[:2]
        loss = loss + lambda_dist * depth_distortion(alpha, extra)
    if rest:
        raise TypeError(f"step_loss: {len(rest)} inputs left over for the active terms")
    return loss


def _sample(t: torch.Tensor) -> torch.Tensor:
    """A detached copy with the same ``requires_grad``: the graph's own static input."""
    return t.detach().clone().requires_grad_(t.requires_grad)


class StepLoss:
    """The step loss, through one CUDA graph per (active terms, image size) where allowed.

    Each graph keeps its own memory pool (about the loss's peak memory at that image size), so
    at most ``max_graphs`` are captured; further combinations run eagerly. A training run needs
    at most three per image size (the terms switch on at ``dist_from`` and ``normal_from``).

    Args:
        lambda_dssim: weight of D-SSIM.
        graphs: capture on CUDA (False: always eager).
        max_graphs: most graphs captured.
    """

    def __init__(self, lambda_dssim: float, graphs: bool = True, max_graphs: int = 12) -> None:
        self.lambda_dssim = float(lambda_dssim)
        self.graphs = graphs
        self.max_graphs = max_graphs
        self._graphed: dict[tuple, Callable[..., torch.Tensor]] = {}
        #: why capture was given up (None: it was not); training then runs eagerly
        self.fallback_reason: str | None = None

    def __call__(
        self,
        rgb: torch.Tensor,
        target: torch.Tensor,
        *terms: torch.Tensor,
        lambda_normal: float = 0.0,
        lambda_dist: float = 0.0,
    ) -> torch.Tensor:
        fn = functools.partial(
            step_loss,
            lambda_dssim=self.lambda_dssim,
            lambda_normal=float(lambda_normal),
            lambda_dist=float(lambda_dist),
        )
        args = (rgb, target, *terms)
        use_graph = (
            self.graphs
            and self.fallback_reason is None
            and rgb.is_cuda
            and torch.is_grad_enabled()
            and all(a.is_cuda for a in args)
        )
        if not use_graph:
            return fn(*args)
        key = (
            fn.keywords["lambda_normal"],
            fn.keywords["lambda_dist"],
            tuple((tuple(a.shape), a.dtype, a.requires_grad, a.device) for a in args),
        )
        graphed = self._graphed.get(key)
        if graphed is None and len(self._graphed) >= self.max_graphs:
            return fn(*args)
        if graphed is None:
            try:
                graphed = torch.cuda.make_graphed_callables(
                    fn, tuple(_sample(a) for a in args), allow_unused_input=True
                )
            except RuntimeError as e:  # a driver or allocator that cannot capture: eager
                self.fallback_reason = f"CUDA graph capture of the step loss failed: {e}"
                warnings.warn(
                    self.fallback_reason + "; training goes on without graphs", stacklevel=2
                )
                return fn(*args)
            self._graphed[key] = graphed
        return graphed(*args)
