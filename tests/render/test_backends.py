"""Backend registry: built-ins, user registration, entry points, unavailable backends."""

from __future__ import annotations

import doctest

import pytest
import torch
from plugin_dist import write_dist

from robogs.format.errors import RobogsError
from robogs.format.plugins import PluginWarning
from robogs.format.render import available_backends, backends, pipeline, register_backend, render


def test_builtin_backends_are_listed():
    found = {e.name: e for e in backends.backend_entries()}
    assert found["torch"].ok and found["dense"].ok
    assert {"torch", "dense"} <= set(available_backends())
    # the optional fused CPU backend is either usable or says why not
    numba = found["numba"]
    assert numba.ok or ("numba" in numba.reason and "numba" not in available_backends())


def test_registered_backend_is_used(make_gaussians, make_camera):
    calls = []

    def shifted(g, cam, cfg):
        calls.append(len(g))
        return backends.get_backend("dense")(g, cam, cfg)

    with backends.REGISTRY.sandbox():
        register_backend("test-shifted", shifted)
        assert available_backends()["test-shifted"] is shifted
        g = make_gaussians(5, "3dgs")
        out = render(g, make_camera(), backend="test-shifted")
        assert calls == [5]
        ref = render(g, make_camera(), backend="torch")
        assert float((out.rgb - ref.rgb).abs().max()) < 1e-10
    assert "test-shifted" not in available_backends()


def test_unknown_backend_raises(make_gaussians, make_camera):
    with pytest.raises(RobogsError, match="unknown render backend 'nope'"):
        render(make_gaussians(2, "3dgs"), make_camera(), backend="nope")


def test_entry_points_are_loaded(tmp_path, monkeypatch, make_gaussians, make_camera):
    write_dist(
        tmp_path,
        "robogs-labrender",
        "labrender",
        "from robogs.format.render.dense import render_dense\nNOT_A_FUNCTION = 3\n",
        """
        [robogs.backends]
        ep-dense = labrender:render_dense
        ep-broken = no_such_module_xyz:fn
        ep-bad = labrender:NOT_A_FUNCTION
        """,
    )
    with monkeypatch.context() as mp, backends.REGISTRY.sandbox():
        mp.syspath_prepend(str(tmp_path))
        with pytest.warns(PluginWarning) as caught:
            found = {e.name: e for e in backends.backend_entries()}
        assert len(caught) == 2  # one per broken plug-in
        assert found["ep-dense"].ok and found["ep-dense"].source == "robogs-labrender"
        assert "no_such_module_xyz" in found["ep-broken"].reason
        assert "int is not callable" in found["ep-bad"].reason
        out = render(make_gaussians(3, "3dgs"), make_camera(), backend="ep-dense")
        assert out.rgb.shape == (29, 37, 3)
        with pytest.raises(RobogsError, match="'ep-broken' from distribution 'robogs-labrender'"):
            render(make_gaussians(3, "3dgs"), make_camera(), backend="ep-broken")


def test_render_docstring_example_runs():
    result = doctest.testmod(pipeline, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


def test_outputs_follow_input_device_and_dtype(make_gaussians, make_camera):
    g = make_gaussians(10, "3dgs", dtype=torch.float32)
    out = render(g, make_camera(dtype=torch.float64))
    assert out.rgb.dtype == torch.float32 and out.rgb.device == g.means.device
