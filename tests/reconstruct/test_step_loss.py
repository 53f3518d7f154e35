"""The step loss: its terms against their definitions, and its CUDA graphs against eager runs.

Oracles: on every machine, ``step_loss`` against the loss written out from ``losses.py``'s
full-image functions (``depth_normals`` on the camera, the border masked); on CUDA, the graphed
loss and its gradients against the eager function, replayed for views with other intrinsics and
images (a graph that kept the first view's camera or data would fail), and a short training run
with graphs against one without.
"""

from __future__ import annotations

import math

import pytest
import torch

from robogs.format.render import Camera
from robogs.reconstruct.image_metrics import ssim
from robogs.reconstruct.losses import depth_distortion, depth_normals, pixel_rays
from robogs.reconstruct.step_loss import StepLoss, step_loss
from robogs.reconstruct.train import TrainConfig, train
from robogs.reconstruct.views import View

cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
LD, LN, LX = 0.2, 0.05, 10.0


def _camera(seed: int, H: int = 18, W: int = 22) -> Camera:
    g = torch.Generator().manual_seed(seed)
    f = 20.0 + 10.0 * float(torch.rand(1, generator=g))
    return Camera(
        width=W, height=H, fx=f, fy=f * 1.1, cx=W / 2 + float(torch.randn(1, generator=g)),
        cy=H / 2 - 1.3, T_world_cam=torch.eye(4, dtype=torch.float64),
    )  # fmt: skip


def _images(seed: int, H: int = 18, W: int = 22, dtype=torch.float64, device="cpu") -> dict:
    """Render-like inputs: a tilted plane's depth with a hole, smooth normals, alpha, extra."""
    g = torch.Generator().manual_seed(seed)
    r = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)  # noqa: E731
    yy, xx = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    depth = 1.0 + 0.02 * xx + 0.01 * yy + 0.005 * r(H, W)
    depth[3:6, 4:9] = 0.0  # no surface: masked out of the normal term
    n = torch.stack([0.2 + 0.1 * r(H, W), -0.1 + 0.1 * r(H, W), -torch.ones(H, W)], dim=-1)
    out = {
        "rgb": r(H, W, 3),
        "target": r(H, W, 3),
        "normals": n / n.norm(dim=-1, keepdim=True),
        "alpha": 0.3 + 0.7 * r(H, W),
        "depth": depth,
        "extra": torch.stack([depth * 0.9, depth * depth * 0.95], dim=-1),
    }
    return {k: v.to(dtype=dtype, device=device) for k, v in out.items()}


def _reference(x: dict, cam: Camera) -> torch.Tensor:
    """The loss of one view from the full-image definitions."""
    l1 = (x["rgb"] - x["target"]).abs().mean()
    photo = (1 - LD) * l1 + LD * (1.0 - ssim(x["rgb"], x["target"], crop=False))
    N, ok = depth_normals(x["depth"], cam)
    err = x["alpha"] * (1.0 - (x["normals"] * N).sum(-1))
    normal = (err * ok).sum() / ok.sum()
    return photo + LN * normal + LX * depth_distortion(x["alpha"], x["extra"])


def _terms(x: dict, rays: torch.Tensor) -> list[torch.Tensor]:
    return [x["normals"], x["alpha"], x["depth"], rays, x["alpha"], x["extra"]]


def test_pixel_rays_are_the_pinhole_back_projection():
    cam = _camera(1)
    rays = pixel_rays(cam, torch.float64, "cpu")
    assert rays.shape == (18, 22, 2)
    i, j = 7, 13  # row, column
    assert float(rays[i, j, 0]) == pytest.approx((j + 0.5 - cam.cx) / cam.fx, rel=1e-15)
    assert float(rays[i, j, 1]) == pytest.approx((i + 0.5 - cam.cy) / cam.fy, rel=1e-15)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_step_loss_equals_the_written_out_loss(seed: int):
    cam, x = _camera(seed), _images(seed)
    rays = pixel_rays(cam, torch.float64, "cpu")
    got = step_loss(
        x["rgb"], x["target"], *_terms(x, rays),
        lambda_dssim=LD, lambda_normal=LN, lambda_dist=LX,
    )  # fmt: skip
    want = _reference(x, cam)
    assert float(got) == pytest.approx(float(want), rel=1e-12)
    # the normal term is not negligible here: leaving it out changes the loss
    photo = step_loss(x["rgb"], x["target"], lambda_dssim=LD)
    assert abs(float(want) - float(photo)) > 1e-3


def test_step_loss_rejects_inputs_the_terms_do_not_use():
    x = _images(0)
    with pytest.raises(TypeError, match="left over"):
        step_loss(x["rgb"], x["target"], x["alpha"], lambda_dssim=LD)


def test_on_the_cpu_nothing_is_captured():
    cam, x = _camera(0), _images(0)
    sl = StepLoss(LD)
    rays = pixel_rays(cam, torch.float64, "cpu")
    got = sl(x["rgb"], x["target"], *_terms(x, rays), lambda_normal=LN, lambda_dist=LX)
    assert float(got) == pytest.approx(float(_reference(x, cam)), rel=1e-12)
    assert sl._graphed == {} and sl.fallback_reason is None


def _grads(fn, x: dict, rays: torch.Tensor, normal: bool, dist: bool):
    leaves = {k: v.detach().clone().requires_grad_(k != "target") for k, v in x.items()}
    terms: list[torch.Tensor] = []
    if normal:
        terms += [leaves["normals"], leaves["alpha"], leaves["depth"], rays]
    if dist:
        terms += [leaves["alpha"], leaves["extra"]]
    loss = fn(
        leaves["rgb"], leaves["target"], *terms,
        lambda_normal=LN if normal else 0.0, lambda_dist=LX if dist else 0.0,
    )  # fmt: skip
    loss.backward()
    used = ["rgb"] + (["normals", "alpha", "depth"] if normal else []) + (["extra"] if dist else [])
    if dist:
        used.append("alpha")
    return float(loss), {k: leaves[k].grad.clone() for k in dict.fromkeys(used)}


@cuda
def test_cuda_graphs_match_the_eager_loss_and_gradients_view_after_view():
    sl = StepLoss(LD)
    eager = lambda *a, **kw: step_loss(*a, lambda_dssim=LD, **kw)  # noqa: E731
    seen = 0
    for normal, dist in [(False, False), (False, True), (True, True)]:
        for seed in (0, 1, 0, 2):  # a replay after other views' data and intrinsics
            cam = _camera(seed)
            x = _images(seed, dtype=torch.float32, device="cuda")
            rays = pixel_rays(cam, torch.float32, "cuda")
            v_g, g_g = _grads(sl, x, rays, normal, dist)
            v_e, g_e = _grads(eager, x, rays, normal, dist)
            assert v_g == pytest.approx(v_e, rel=1e-5, abs=1e-7), (normal, dist, seed)
            for k in g_e:
                torch.testing.assert_close(g_g[k], g_e[k], rtol=1e-4, atol=1e-7, msg=k)
            seen += 1
    assert sl.fallback_reason is None
    assert len(sl._graphed) == 3  # one graph per set of active terms, reused for every view
    assert seen == 12


@cuda
def test_cuda_training_with_graphs_matches_training_without():
    H, W = 12, 16
    views = []
    for i in range(3):
        cam = _camera(10 + i, H, W)
        target = torch.zeros(H, W, 3)
        target[:, : 4 + 2 * i] = torch.tensor([0.8, 0.2, 0.1])
        views.append(View(f"c/{i}", "c", i, i, cam, target, None))
    g = torch.Generator().manual_seed(0)
    n = 24
    init = {
        "means": torch.randn(n, 3, generator=g) * 0.1 + torch.tensor([0.0, 0.0, 1.0]),
        "quats": torch.randn(n, 4, generator=g),
        "log_scales": torch.full((n, 2), math.log(0.05)),
        "opacity_logits": torch.zeros(n),
        "sh_dc": torch.randn(n, 1, 3, generator=g),
        "sh_rest": torch.zeros(n, 0, 3),
    }
    init = {k: v.to("cuda") for k, v in init.items()}
    base = dict(
        iterations=10, log_every=5, checkpoint_every=0, dist_from=0.3, normal_from=0.5,
        densify_every=10_000, opacity_reset_every=0, backend="torch",
    )  # fmt: skip
    runs = [
        train(views, init, TrainConfig(**base, cuda_graphs=on), extent=1.0) for on in (True, False)
    ]
    with_g, without = runs
    assert with_g.psnr_history == pytest.approx(without.psnr_history, abs=1e-3)
    for k in with_g.model.params:
        torch.testing.assert_close(
            with_g.model.params[k], without.model.params[k], rtol=1e-4, atol=1e-5, msg=k
        )


@cuda
def test_beyond_max_graphs_the_loss_runs_eagerly():
    sl = StepLoss(LD, max_graphs=1)
    eager = lambda *a, **kw: step_loss(*a, lambda_dssim=LD, **kw)  # noqa: E731
    cam = _camera(0)
    x = _images(0, dtype=torch.float32, device="cuda")
    rays = pixel_rays(cam, torch.float32, "cuda")
    for normal, dist in [(False, False), (True, True), (False, False), (True, True)]:
        v_g, _ = _grads(sl, x, rays, normal, dist)
        v_e, _ = _grads(eager, x, rays, normal, dist)
        assert v_g == pytest.approx(v_e, rel=1e-5, abs=1e-7)
    assert len(sl._graphed) == 1 and sl.fallback_reason is None
