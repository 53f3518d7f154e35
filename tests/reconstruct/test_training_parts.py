"""Losses, the trainable model's Adam surgery and densification, against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from robogs.format.frames import quat_to_matrix
from robogs.format.render import Camera
from robogs.reconstruct.densify import DensifyConfig, GradientStats, refine
from robogs.reconstruct.losses import depth_distortion, depth_normals
from robogs.reconstruct.model import PARAM_NAMES, GaussianModel, LearningRates


def test_distortion_equals_the_pairwise_sum():
    rng = np.random.default_rng(0)
    w = rng.uniform(0, 0.3, (5, 7, 6))  # weights of 6 Gaussians at 5x7 pixels
    z = rng.uniform(0.5, 2.0, (5, 7, 6))
    brute = np.zeros((5, 7))
    for i in range(6):
        for j in range(i + 1, 6):
            brute += w[..., i] * w[..., j] * (z[..., i] - z[..., j]) ** 2
    A = torch.tensor(w.sum(-1))
    extra = torch.tensor(np.stack([(w * z).sum(-1), (w * z * z).sum(-1)], -1))
    assert float(depth_distortion(A, extra)) == pytest.approx(brute.mean(), rel=1e-12)


def test_depth_normals_of_a_plane():
    cam = Camera(
        width=20,
        height=16,
        fx=18.0,
        fy=18.0,
        cx=10.0,
        cy=8.0,
        T_world_cam=torch.eye(4, dtype=torch.float64),
    )
    n_true = torch.tensor([0.3, -0.2, -1.0], dtype=torch.float64)
    n_true = n_true / n_true.norm()
    # plane n . X = -1 (in front of the camera); depth along each pixel ray: z = -1 / (n . r)
    u = (torch.arange(20, dtype=torch.float64) + 0.5 - 10.0) / 18.0
    v = (torch.arange(16, dtype=torch.float64) + 0.5 - 8.0) / 18.0
    r = torch.stack(
        [
            u[None, :].expand(16, 20),
            v[:, None].expand(16, 20),
            torch.ones(16, 20, dtype=torch.float64),
        ],
        -1,
    )
    depth = -1.0 / (r @ n_true)
    N, ok = depth_normals(depth, cam)
    assert ok[1:-1, 1:-1].all() and not ok[0].any()
    assert torch.allclose(N[ok], n_true.expand(int(ok.sum()), 3), atol=1e-10)


def _model(n: int = 6, kind: str = "2dgs") -> GaussianModel:
    g = torch.Generator().manual_seed(0)
    ns = 2 if kind == "2dgs" else 3
    t = {
        "means": torch.randn(n, 3, generator=g),
        "quats": torch.randn(n, 4, generator=g),
        "log_scales": torch.full((n, ns), math.log(0.01)),
        "opacity_logits": torch.zeros(n),
        "sh_dc": torch.randn(n, 1, 3, generator=g),
        "sh_rest": torch.zeros(n, 0, 3),
    }
    return GaussianModel(t, LearningRates(), extent=1.0)


def _step(model: GaussianModel) -> None:
    loss = sum((p**2).sum() for p in model.params.values())
    loss.backward()
    model.optimizer.step()
    model.optimizer.zero_grad()


def test_keep_and_append_carry_adam_moments():
    m = _model()
    _step(m)
    before = {k: m.optimizer.state[m.params[k]]["exp_avg"].clone() for k in PARAM_NAMES}
    keep = torch.tensor([True, False, True, True, False, True])
    m.keep(keep)
    assert len(m) == 4
    for k in PARAM_NAMES:
        assert torch.equal(m.optimizer.state[m.params[k]]["exp_avg"], before[k][keep])
    new = {k: v.detach()[:2].clone() for k, v in m.params.items()}
    m.append(new)
    assert len(m) == 6
    for k in PARAM_NAMES:
        st = m.optimizer.state[m.params[k]]["exp_avg"]
        assert torch.equal(st[:4], before[k][keep]) and (st[4:] == 0).all()
    _step(m)  # the optimiser still steps every group
    assert all(m.params[k].grad is None for k in PARAM_NAMES)


def test_refine_clones_small_splits_large_and_prunes_transparent():
    m = _model(4)
    with torch.no_grad():
        m.params["log_scales"][1] = math.log(0.05)  # large: split (percent_dense 0.01 x extent 1)
        m.params["opacity_logits"][3] = -10.0  # transparent: pruned
    stats = GradientStats(4, torch.device("cpu"))
    grads = torch.tensor([[1e-3, 0.0], [1e-3, 0.0], [0.0, 0.0], [0.0, 0.0]])
    stats.add(grads, torch.ones(4, 2), width=2, height=2)
    counts = refine(m, stats, DensifyConfig(grad_threshold=2e-4), step=100)
    assert counts["cloned"] == 1 and counts["split"] == 1 and counts["pruned"] == 1
    assert len(m) == 4 + 1 + 2 - 1 - 1  # clone, two halves replace the split one, one pruned
    # the split halves are smaller by 1.6 and lie in the surfel's plane
    halves = torch.isclose(m.params["log_scales"][:, 0], torch.tensor(math.log(0.05 / 1.6)))
    assert int(halves.sum()) == 2
    q = m.params["quats"][halves][0]
    normal = quat_to_matrix(q / q.norm())[:, 2]
    d = m.params["means"][halves] - _model(4).params["means"][1]
    assert torch.allclose(d @ normal, torch.zeros(2), atol=1e-6)
    assert len(stats.grad) == len(m) and stats.grad.sum() == 0


def test_refine_is_deterministic_per_step():
    outs = []
    for _ in range(2):
        m = _model(4)
        with torch.no_grad():
            m.params["log_scales"][:] = math.log(0.05)
        stats = GradientStats(4, torch.device("cpu"))
        stats.add(torch.full((4, 2), 1e-3), torch.ones(4, 2), 2, 2)
        refine(m, stats, DensifyConfig(), step=300, seed=5)
        outs.append(m.params["means"].detach().clone())
    assert torch.equal(outs[0], outs[1])


def test_progress_bar_shows_the_running_psnr():
    from io import StringIO

    from rich.console import Console

    from robogs.reconstruct.train import TrainConfig, train
    from robogs.reconstruct.views import View

    cam = Camera(
        width=16,
        height=12,
        fx=14.0,
        fy=14.0,
        cx=8.0,
        cy=6.0,
        T_world_cam=torch.eye(4, dtype=torch.float64),
    )
    target = torch.zeros(12, 16, 3)
    target[:, :8] = torch.tensor([0.8, 0.2, 0.1])
    views = [View(f"c/{i}", "c", i, i, cam, target, None) for i in range(2)]
    m = _model(6)
    init = {k: v.detach().clone() for k, v in m.params.items()}
    init["means"] = init["means"] * 0.1 + torch.tensor([0.0, 0.0, 1.0])
    buf = StringIO()
    console = Console(file=buf, force_terminal=True, width=160, color_system=None)
    res = train(
        views,
        init,
        TrainConfig(iterations=3, checkpoint_every=0, densify_from=1.0),
        extent=1.0,
        progress=True,
        console=console,
    )
    text = buf.getvalue()
    assert "3/3" in text and "PSNR" in text
    assert f"PSNR {res.psnr_history[-1]:5.2f} dB" in text  # the last step's training PSNR
    assert len(res.psnr_history) == 3
