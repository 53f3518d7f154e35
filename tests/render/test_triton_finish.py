"""The fused finish of a triton render (``triton_finish.py``) against ``finish_output``.

Runs where the ``triton`` backend runs (CUDA, or the CPU under ``TRITON_INTERPRET=1``); skipped
with the registry's reason elsewhere. The oracle is the same render with
``triton_raster._FUSED_FINISH`` off (torch ops): every output, and the gradients of every
Gaussian field through losses that read all outputs or only some (the kernel's paths for
outputs without a gradient).
"""

from __future__ import annotations

import pytest
import torch

from robogs.format.render import RenderConfig, available_backends, render
from robogs.format.render.backends import backend_entries

HAVE = "triton" in available_backends()
REASON = next((str(e.reason) for e in backend_entries() if e.name == "triton"), "not registered")
DEVICE = "cuda" if torch.cuda.is_available() else "cpu"
pytestmark = pytest.mark.skipif(not HAVE, reason=f"triton backend unavailable: {REASON}")

OUTPUTS = ("rgb", "alpha", "depth_expected", "depth_median", "normals", "extra", "radii")
LEAVES = ("means", "quats", "log_scales", "opacity_logits", "sh", "extra")


def _loss(out, which: tuple[str, ...]) -> torch.Tensor:
    gen = torch.Generator().manual_seed(7)
    total = out.rgb.new_zeros(())
    for name in which:
        t = getattr(out, name)
        w = torch.rand(t.shape, generator=gen, dtype=torch.float64).to(t)
        total = total + (w * t).sum()
    return total


def _run(make_gaussians, make_camera, monkeypatch, kind, extra, fused, which):
    from robogs.format.render import triton_raster as tr

    monkeypatch.setattr(tr, "_FUSED_FINISH", fused)
    g = make_gaussians(120, kind, seed=3, spread=0.5, extra=extra, dtype=torch.float32)
    g = type(g)(**{k: (v.to(DEVICE) if v is not None else None) for k, v in vars(g).items()})
    for k in LEAVES:
        if getattr(g, k) is not None:
            getattr(g, k).requires_grad_(True)
    cam = make_camera(37, 29, dtype=torch.float32, device=DEVICE)
    cfg = RenderConfig(kind=kind, validate=False, tile_size=8, background=(0.2, 0.5, 0.9))
    out = render(g, cam, config=cfg, backend="triton")
    if which:
        _loss(out, which).backward()
    grads = {k: getattr(g, k).grad for k in LEAVES if getattr(g, k) is not None}
    return out, grads


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
@pytest.mark.parametrize("extra", [0, 2])
def test_fused_finish_outputs_equal_finish_output(
    make_gaussians, make_camera, monkeypatch, kind, extra
):
    want, _ = _run(make_gaussians, make_camera, monkeypatch, kind, extra, False, ())
    got, _ = _run(make_gaussians, make_camera, monkeypatch, kind, extra, True, ())
    for name in OUTPUTS:
        a, b = getattr(got, name), getattr(want, name)
        assert a.shape == b.shape and a.dtype == b.dtype, name
        torch.testing.assert_close(a, b, rtol=2e-6, atol=1e-7, msg=name)
    assert (
        float(want.alpha.detach().max()) > 0.5
        and float((want.alpha.detach() == 0).float().mean()) > 0.02
    )


@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
@pytest.mark.parametrize(
    "which",
    [
        ("rgb", "alpha", "depth_expected", "depth_median", "normals", "extra"),
        ("rgb",),
        ("depth_expected", "normals"),
        ("alpha", "extra"),
    ],
)
def test_fused_finish_gradients_equal_finish_output(
    make_gaussians, make_camera, monkeypatch, kind, which
):
    _, want = _run(make_gaussians, make_camera, monkeypatch, kind, 2, False, which)
    _, got = _run(make_gaussians, make_camera, monkeypatch, kind, 2, True, which)
    assert "extra" in want  # the extra channels' gradient path is checked too
    for k in want:
        if want[k] is None:
            assert got[k] is None or float(got[k].abs().max()) == 0.0, k
            continue
        scale = float(want[k].abs().max())
        if scale == 0.0:  # a field the loss does not reach (extra through rgb alone)
            assert float(got[k].abs().max()) == 0.0, k
            continue
        torch.testing.assert_close(got[k], want[k], rtol=1e-4, atol=1e-5 * scale, msg=k)
