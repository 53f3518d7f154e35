"""Backend registry: built-ins, user registration, entry points, unavailable backends."""

from __future__ import annotations

import doctest
from importlib import metadata

import pytest
import torch

from robogs.format.errors import RobogsError
from robogs.format.render import available_backends, backends, pipeline, register_backend, render


def test_builtin_backends_are_listed():
    found = available_backends()
    assert found["torch"] == "ok" and found["dense"] == "ok"
    # the optional fused CPU backend is either usable or says why not
    assert "numba" in found and (found["numba"] == "ok" or "numba" in found["numba"])


def test_registered_backend_is_used(make_gaussians, make_camera):
    calls = []

    def shifted(g, cam, cfg):
        calls.append(len(g))
        return backends.get_backend("dense")(g, cam, cfg)

    register_backend("test-shifted", shifted)
    try:
        assert available_backends()["test-shifted"] == "ok"
        g = make_gaussians(5, "3dgs")
        out = render(g, make_camera(), backend="test-shifted")
        assert calls == [5]
        ref = render(g, make_camera(), backend="torch")
        assert float((out.rgb - ref.rgb).abs().max()) < 1e-10
    finally:
        backends._REGISTRY.pop("test-shifted")


def test_unknown_backend_raises(make_gaussians, make_camera):
    with pytest.raises(RobogsError, match="unknown render backend 'nope'"):
        render(make_gaussians(2, "3dgs"), make_camera(), backend="nope")


def test_entry_points_are_loaded(monkeypatch, make_gaussians, make_camera):
    good = metadata.EntryPoint(
        "ep-dense", "robogs.format.render.dense:render_dense", backends.ENTRY_POINT_GROUP
    )
    broken = metadata.EntryPoint("ep-broken", "no_such_module_xyz:fn", backends.ENTRY_POINT_GROUP)
    monkeypatch.setattr(
        backends.metadata,
        "entry_points",
        lambda group: [good, broken] if group == backends.ENTRY_POINT_GROUP else [],
    )
    monkeypatch.setattr(backends, "_entry_points_loaded", False)
    monkeypatch.setattr(backends, "_REGISTRY", dict(backends._REGISTRY))
    monkeypatch.setattr(backends, "_UNAVAILABLE", dict(backends._UNAVAILABLE))
    found = available_backends()
    assert found["ep-dense"] == "ok"
    assert "failed to load" in found["ep-broken"] and "no_such_module_xyz" in found["ep-broken"]
    out = render(make_gaussians(3, "3dgs"), make_camera(), backend="ep-dense")
    assert out.rgb.shape == (29, 37, 3)
    with pytest.raises(RobogsError, match="'ep-broken' is unavailable"):
        render(make_gaussians(3, "3dgs"), make_camera(), backend="ep-broken")


def test_render_docstring_example_runs():
    result = doctest.testmod(pipeline, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def test_outputs_follow_input_device_and_dtype(make_gaussians, make_camera):
    g = make_gaussians(10, "3dgs", dtype=torch.float32)
    out = render(g, make_camera(dtype=torch.float64))
    assert out.rgb.dtype == torch.float32 and out.rgb.device == g.means.device
