"""Every registered fast backend (the tiled torch one, and numba when installed) against the
dense oracle. The list is built at collection time from the backends that load, so nothing is
skipped: without numba only the torch backend is parametrized."""

from __future__ import annotations

import pytest

from robogs.format.render import RenderConfig, available_backends, render

FAST = ["torch"] + [b for b in ("numba",) if b in available_backends()]
FIELDS = ("rgb", "alpha", "depth_expected", "depth_median", "normals", "extra")


@pytest.mark.parametrize("backend", FAST)
@pytest.mark.parametrize("kind", ["3dgs", "2dgs"])
@pytest.mark.parametrize("tile_size", [None, 5])
def test_fast_backend_matches_dense(make_gaussians, make_camera, backend, kind, tile_size):
    g = make_gaussians(500, kind, seed=21, scale=(0.02, 0.12), opacity_shift=3.0, extra=3)
    cam = make_camera()
    cfg = RenderConfig(kind=kind, tile_size=tile_size, background=(0.3, 0.3, 0.3))
    a = render(g, cam, config=cfg, backend=backend)
    b = render(g, cam, config=cfg, backend="dense")
    assert float((b.alpha > 0.999).float().mean()) > 0.2
    d = {f: float((getattr(a, f) - getattr(b, f)).abs().max()) for f in FIELDS}
    assert max(d.values()) <= 1e-5, d
