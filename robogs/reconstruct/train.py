"""Optimise Gaussians against the static views with the robogs rasterizer (2DGS by default).

The loss of Huang et al. 2024 (2DGS): ``0.8 L1 + 0.2 D-SSIM + lambda_n L_normal + lambda_d L_dist``
(see ``losses.py``), Adam with per-parameter learning rates and gradient-driven densification
(see ``densify.py``), as in Kerbl et al. 2023. One random training view per step; the view order
is a permutation per epoch drawn from a generator seeded by (seed, epoch), and every random
choice is seeded by the step, so a run resumed from a checkpoint ends with the same Gaussians as
an uninterrupted one (same device and thread count).

The step itself never waits for the device (no ``.item()``, ``float(tensor)``, ``.cpu()``): the
training PSNR of each step stays a 0-d device tensor, and the buffered values are copied to the
host in one transfer every ``log_every`` steps (and before a checkpoint and at the end), where the
progress bar and ``on_step`` are updated. The renderer's own syncs (the torch backend's tile
binning reads its intersection count) and those of a refinement (every ``densify_every`` steps,
``densify.refine``) remain; see ``design.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import torch

from robogs.format.errors import InputError
from robogs.format.render import RenderConfig, available_backends, render
from robogs.format.render.backends import get_backend

from .checkpoint import load_checkpoint, save_checkpoint
from .densify import DensifyConfig, GradientStats, refine
from .losses import depth_channels, pixel_rays
from .model import GaussianModel, LearningRates
from .step_loss import StepLoss
from .views import View

__all__ = ["TrainConfig", "TrainResult", "train", "screen_gradient", "resolve_backend"]


def screen_gradient(grad_means: torch.Tensor, means: torch.Tensor, camera: Any) -> torch.Tensor:
    """View-space positional gradient [N, 2], dL/d(px), from the gradient of the world centres.

    Moving a centre at depth z by one pixel along the image x (y) axis moves it z / fx (z / fy)
    along the camera's x (y) axis, so ``dL/du = (R_cw dL/dX)_x z / fx``. This is the quantity
    3DGS accumulates for densification (there read from the rasterizer's screen-space means).
    """
    T = camera.T_world_cam.to(dtype=means.dtype, device=means.device)
    R = T[:3, :3]
    g_cam = grad_means.detach() @ R  # rows: (R^T g)^T, camera axes
    z = ((means.detach() - T[:3, 3]) @ R[:, 2]).clamp(min=1e-6)
    return torch.stack([g_cam[:, 0] * z / camera.fx, g_cam[:, 1] * z / camera.fy], dim=1)


@dataclass(frozen=True)
class TrainConfig:
    """Training options. Fractions are of ``iterations``.

    Attributes:
        kind: ``2dgs`` (surfels, default) or ``3dgs``.
        iterations: optimisation steps.
        sh_degree: SH degree of the colour (0: view-independent).
        lambda_dssim: weight of D-SSIM in the photometric loss.
        lambda_normal: weight of the normal-consistency loss (2DGS only), from ``normal_from``.
        lambda_dist: weight of the depth-distortion loss (m^-2), from ``dist_from``.
        densify_from, densify_until, densify_every: refinement window and period (steps).
        opacity_reset_every: steps between opacity resets (0: never).
        background: colour behind the Gaussians, RGB in [0, 1].
        seed: random seed.
        checkpoint_every: steps between checkpoints (0: only when interrupted).
        log_every: steps between the host copies of the training PSNR (progress bar, ``on_step``;
            one transfer each); the last step is always logged.
        backend: render backend; ``auto`` is ``triton`` when the parameters are on a CUDA device
            and that backend is available, else ``torch`` (see :func:`resolve_backend`).
        cuda_graphs: on a CUDA device, capture the step's loss as CUDA graphs (see
            ``step_loss.py``; same values, two launches instead of a few hundred).
        lrs: learning rates.
        densify: densification thresholds.
    """

    kind: str = "2dgs"
    iterations: int = 3000
    sh_degree: int = 0
    lambda_dssim: float = 0.2
    lambda_normal: float = 0.05
    lambda_dist: float = 10.0
    normal_from: float = 0.3
    dist_from: float = 0.1
    densify_from: float = 0.1
    densify_until: float = 0.6
    densify_every: int = 100
    opacity_reset_every: int = 3000
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    checkpoint_every: int = 500
    log_every: int = 50
    backend: str = "auto"
    cuda_graphs: bool = True
    lrs: LearningRates = field(default_factory=LearningRates)
    densify: DensifyConfig = field(default_factory=DensifyConfig)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class TrainResult:
    """What training produced.

    Attributes:
        model: the trained Gaussians.
        iterations: steps done in total.
        resumed_from: step the run resumed at (0: fresh).
        psnr_history: training-view PSNR of every step, dB.
        refinements: counts of each refinement step.
    """

    model: GaussianModel
    iterations: int
    resumed_from: int
    psnr_history: list[float]
    refinements: list[dict[str, int]]


def resolve_backend(name: str, device: torch.device | str) -> str:
    """The render backend a run on ``device`` uses for ``name`` (``TrainConfig.backend``).

    ``auto``: ``triton`` on a CUDA device when ``available_backends()`` lists it, else ``torch``.
    Any other name is returned as given once the registry knows it and it is usable.

    Raises:
        InputError / PluginError: an unknown or unavailable backend (the message says why).
    """
    if name == "auto":
        cuda = torch.device(device).type == "cuda"
        return "triton" if cuda and "triton" in available_backends() else "torch"
    get_backend(name)  # a clear error before any training
    return name


def _psnr_on_device(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """0-d PSNR (dB, float64, on the images' device) of two images in [0, 1]; 99 where it is not
    finite (equal images, NaN), as ``image_metrics.psnr`` and then ``99.0`` did on the host."""
    mse = (pred.to(torch.float64) - target.to(torch.float64)).pow(2).mean()
    p = 10.0 * torch.log10(1.0 / mse)
    return torch.where(torch.isfinite(p), p, torch.full_like(p, 99.0))


def _gather(buf: list[torch.Tensor]) -> list[float]:
    """The buffered 0-d PSNRs as floats: one device-to-host transfer for all of them."""
    return torch.stack(buf).tolist()


def _view_at(step: int, n: int, seed: int) -> int:
    """Index of the view of ``step``: CPU generator and CPU tensors only (no device sync)."""
    epoch, k = divmod(step, n)
    gen = torch.Generator().manual_seed(int(seed) * 7919 + epoch)
    return int(torch.randperm(n, generator=gen)[k])


class _Progress:
    """A rich progress bar on stderr with the running PSNR (silent when disabled or not a terminal).

    ``console`` replaces the stderr console (tests pass one that records).
    """

    def __init__(self, enabled: bool, total: int, start: int, console: Any = None) -> None:
        self.bar = None
        if not enabled:
            return
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeRemainingColumn,
        )

        console = console if console is not None else Console(stderr=True)
        self.bar = Progress(
            TextColumn("[bold]training"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("PSNR {task.fields[psnr]} dB"),
            TextColumn("{task.fields[n]} Gaussians"),
            TimeRemainingColumn(),
            console=console,
            transient=False,
            disable=not console.is_terminal,
        )
        self.bar.start()
        self.task = self.bar.add_task("train", total=total, completed=start, psnr="--", n="--")

    def update(self, step: int, psnr_db: float, n: int) -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=step, psnr=f"{psnr_db:5.2f}", n=str(n))

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def train(
    views: list[View],
    init: dict[str, torch.Tensor],
    cfg: TrainConfig,
    *,
    extent: float,
    checkpoint: Path | None = None,
    fingerprint: str = "",
    progress: bool = False,
    console: Any = None,
    on_step: Callable[[int, dict[str, float]], None] | None = None,
) -> TrainResult:
    """Fit Gaussians to ``views``.

    Args:
        views: training views (images [H, W, 3] in [0, 1], cameras).
        init: initial parameter tensors (see ``init.initial_tensors``); their device is used.
        cfg: options.
        extent: scene extent, m (learning rate of the centres, densification scale limits).
        checkpoint: file to save to and resume from (None: no checkpoints).
        fingerprint: identifies the inputs; a checkpoint with another one is ignored.
        progress: show a progress bar (on stderr, when it is a terminal).
        console: a ``rich.console.Console`` for the progress bar instead of stderr.
        on_step: called with ``(step, {"psnr", "n"})`` after every ``cfg.log_every``-th step
            and after the last one (``psnr``: that step's training PSNR, dB; ``n``: Gaussians).

    Returns:
        The trained model and its history. KeyboardInterrupt propagates after the last
        completed step is checkpointed. With ``checkpoint``, the final state is saved too, so
        that an interruption in the steps after training (meshing, binding) resumes there.
    """
    device = init["means"].device
    if cfg.log_every < 1:
        raise InputError(
            f"log_every must be >= 1, got {cfg.log_every}", where="TrainConfig.log_every"
        )
    backend = resolve_backend(cfg.backend, device)
    start = 0
    history: list[float] = []
    refinements: list[dict[str, int]] = []
    doc = load_checkpoint(checkpoint, fingerprint) if checkpoint is not None else None
    if doc is not None:
        model = GaussianModel.from_state(doc["model"], cfg.lrs, extent, device)
        stats = GradientStats(len(model), device)
        stats.grad, stats.count = doc["grad"].to(device), doc["count"].to(device)
        start = int(doc["iteration"])
        history = list(doc["psnr_history"])
        refinements = [dict(r) for r in doc.get("refinements", [])]
    else:
        model = GaussianModel(init, cfg.lrs, extent)
        stats = GradientStats(len(model), device)
    resumed_from = start
    rcfg = RenderConfig(kind=cfg.kind, background=tuple(cfg.background), validate=False)
    n_views = len(views)
    # images and camera poses go to the device once: a copy from the host inside the step would
    # wait for the device (a pageable host-to-device copy synchronises the stream)
    cams = [replace(v.camera, T_world_cam=v.camera.T_world_cam.to(device)) for v in views]
    targets = [v.rgb.to(device) for v in views]
    dtype = model.params["means"].dtype
    # per-view pixel rays for the normal-consistency term, on the device once (see StepLoss)
    rays = (
        [pixel_rays(c, dtype, device) for c in cams]
        if cfg.kind == "2dgs" and cfg.lambda_normal > 0
        else None
    )
    step_loss = StepLoss(cfg.lambda_dssim, graphs=cfg.cuda_graphs)
    d_from, d_until = (
        int(cfg.densify_from * cfg.iterations),
        int(cfg.densify_until * cfg.iterations),
    )
    bar = _Progress(progress, cfg.iterations, start, console)
    step = start
    done = start
    pending: list[torch.Tensor] = []  # 0-d device PSNRs of the steps not yet in ``history``

    def flush() -> None:
        if pending:
            vals = _gather(pending)  # the one host transfer of the PSNRs
            history.extend(vals)
            pending.clear()

    def save(at: int) -> None:
        if checkpoint is not None:
            flush()
            save_checkpoint(
                checkpoint,
                fingerprint=fingerprint,
                iteration=at,
                model_state=model.state(),
                grad=stats.grad,
                count=stats.count,
                psnr_history=history[:at],
                refinements=refinements,
            )

    try:
        for step in range(start, cfg.iterations):
            i = _view_at(step, n_views, cfg.seed)
            cam, target = cams[i], targets[i]
            model.set_means_lr(step / max(cfg.iterations - 1, 1))
            use_dist = cfg.lambda_dist > 0 and step >= cfg.dist_from * cfg.iterations
            use_normal = (
                cfg.kind == "2dgs"
                and cfg.lambda_normal > 0
                and step >= cfg.normal_from * cfg.iterations
            )
            extra = depth_channels(model.params["means"], cam) if use_dist else None
            out = render(model.gaussians(extra), cam, config=rcfg, backend=backend)
            terms: list[torch.Tensor] = []
            if use_normal:
                terms += [out.normals, out.alpha, out.depth_expected, rays[i]]  # type: ignore[index]
            if use_dist:
                terms += [out.alpha, out.extra]
            loss = step_loss(
                out.rgb,
                target,
                *terms,
                lambda_normal=cfg.lambda_normal if use_normal else 0.0,
                lambda_dist=cfg.lambda_dist if use_dist else 0.0,
            )
            loss.backward()
            with torch.no_grad():
                pending.append(_psnr_on_device(out.rgb.detach().clamp(0, 1), target))
                g3 = model.params["means"].grad
                if d_from <= step < d_until and g3 is not None:
                    stats.add(
                        screen_gradient(g3, model.params["means"], cam),
                        out.radii,
                        cam.width,
                        cam.height,
                    )
            model.optimizer.step()
            model.optimizer.zero_grad(set_to_none=True)
            s1 = step + 1
            if d_from <= step < d_until and s1 % cfg.densify_every == 0 and s1 > d_from:
                # a refinement syncs (index selection sizes its outputs): once per densify_every
                refinements.append(
                    {"step": s1, **refine(model, stats, cfg.densify, s1, seed=cfg.seed)}
                )
            if cfg.opacity_reset_every and s1 % cfg.opacity_reset_every == 0 and s1 < d_until:
                model.reset_opacity()
            done = s1
            del out, loss, extra
            log_now = s1 % cfg.log_every == 0 or s1 == cfg.iterations
            if log_now:
                flush()
                bar.update(s1, history[-1], len(model))
            if cfg.checkpoint_every and s1 % cfg.checkpoint_every == 0 and s1 < cfg.iterations:
                save(s1)
            if log_now and on_step is not None:
                on_step(s1, {"psnr": history[-1], "n": float(len(model))})
    except KeyboardInterrupt:
        if done == step + 1 and done > start:  # interrupted between steps: the state is whole
            save(done)
        raise
    finally:
        bar.close()
    flush()
    del history[done:]  # a step cut short by an exception leaves no PSNR behind
    if done > start:
        save(done)  # the steps after training can be interrupted too
    return TrainResult(model, done, resumed_from, history, refinements)
