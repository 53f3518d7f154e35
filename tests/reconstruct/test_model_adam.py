"""The model's Adam through densification surgery and a checkpoint, on every device present.

On CUDA the model uses torch's fused Adam (its step count lives on the GPU); on the CPU the
default loop. The oracle is the CPU model trained without interruption on the same gradients:
both must give the same parameters after the same steps, surgery and a state round trip.
"""

from __future__ import annotations

import pytest
import torch

from robogs.reconstruct.model import PARAM_NAMES, GaussianModel, LearningRates

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def _tensors(n: int, device: str) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(3)
    shapes = {
        "means": (n, 3),
        "quats": (n, 4),
        "log_scales": (n, 3),
        "opacity_logits": (n, 1),
        "sh_dc": (n, 1, 3),
        "sh_rest": (n, 3, 3),
    }
    return {k: torch.randn(*s, generator=g).to(device) for k, s in shapes.items()}


def _step(model: GaussianModel, weight: float) -> None:
    """One Adam step on a smooth loss whose gradient depends on the parameters."""
    loss = sum((weight * p.square() + p.sin()).sum() for p in model.params.values())
    loss.backward()
    model.optimizer.step()
    model.optimizer.zero_grad(set_to_none=True)


def _train(model: GaussianModel, round_trip: bool, device: str) -> GaussianModel:
    lrs = LearningRates()
    for i in range(3):
        _step(model, 0.5 + i)
    n = len(model)
    keep = torch.arange(n, device=model.params["means"].device) % 3 != 1
    model.keep(keep)
    model.append({k: v[:2] * 0.5 for k, v in _tensors(4, device).items()})
    model.reset_opacity()
    _step(model, 2.0)
    if round_trip:
        model = GaussianModel.from_state(model.state(), lrs, 1.7, torch.device(device))
    for i in range(2):
        _step(model, 1.0 + i)
    return model


@pytest.mark.parametrize("device", DEVICES)
def test_adam_survives_surgery_and_a_checkpoint(device: str) -> None:
    ref = _train(GaussianModel(_tensors(12, "cpu"), LearningRates(), 1.7), False, "cpu")
    got = _train(GaussianModel(_tensors(12, device), LearningRates(), 1.7), True, device)
    fused = got.optimizer.defaults["fused"]
    assert bool(fused) == (device == "cuda")
    for k in PARAM_NAMES:
        a, b = ref.params[k].detach(), got.params[k].detach().cpu()
        assert a.shape == b.shape
        # float32 Adam on different kernels: same to rounding (the steps move them by ~1e-2)
        torch.testing.assert_close(b, a, rtol=1e-5, atol=1e-6, msg=f"{k} on {device}")
        st = got.optimizer.state[got.params[k]]
        assert float(st["step"]) == 6.0
        assert st["step"].device.type == ("cuda" if fused else "cpu")
