"""The vectorised play operator against the sequential definition."""

from __future__ import annotations

import numpy as np
import torch

from robogs.physics.arm.kinematic_model import play_scan


def _loop(x0: np.ndarray, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    out = np.empty_like(q)
    x = x0.copy()
    for k in range(q.shape[-2]):
        x = np.clip(x, q[..., k, :] - w, q[..., k, :] + w)
        out[..., k, :] = x
    return out


def test_play_scan_matches_the_loop_on_random_walks() -> None:
    rng = np.random.default_rng(0)
    for n in (1, 2, 7, 64, 1000, 1337):
        q = np.cumsum(rng.normal(0.0, 0.01, (3, 2, n, 4)), axis=-2)  # [M, T, N, J]
        w = rng.uniform(0.0, 0.05, (3, 1, 1, 4))
        x0 = q[..., 0, :] + rng.uniform(-1, 1, (3, 2, 4)) * w[:, :, 0]
        got = play_scan(torch.as_tensor(x0), torch.as_tensor(q), torch.as_tensor(w)).numpy()
        np.testing.assert_allclose(got, _loop(x0, q, w[:, :, 0]), rtol=0, atol=1e-15)


def test_play_scan_zero_width_follows_the_input_and_has_gradients() -> None:
    q = torch.linspace(0.0, 1.0, 50, dtype=torch.float64).reshape(1, 50, 1)
    w = torch.zeros(1, 1, dtype=torch.float64, requires_grad=True)
    x = play_scan(q[:, 0] - w, q, w.unsqueeze(-2))
    assert torch.equal(x.detach(), q)
    w2 = torch.full((1, 1), 0.1, dtype=torch.float64, requires_grad=True)
    play_scan(q[:, 0] - w2, q, w2.unsqueeze(-2)).sum().backward()
    assert w2.grad is not None and torch.isfinite(w2.grad).all()
    # a monotone ramp drags the state along the lower edge: x = q - w, d sum / dw = -50
    assert abs(float(w2.grad) + 50.0) < 1e-12
