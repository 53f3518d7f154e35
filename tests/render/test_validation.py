"""Degenerate inputs are reported by the validators and refused by render()."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
import torch

from robogs.format.errors import InputError, RobogsError
from robogs.format.render import (
    RenderConfig,
    RenderInputError,
    render,
    validate_camera,
    validate_gaussians,
)


def test_valid_inputs_have_no_problems(make_gaussians, make_camera):
    assert validate_gaussians(make_gaussians(5, "3dgs"), "3dgs") == []
    assert validate_gaussians(make_gaussians(5, "2dgs"), "2dgs") == []
    assert validate_camera(make_camera()) == []


def test_nan_mean_is_refused_with_row_and_hint(make_gaussians, make_camera):
    g = make_gaussians(8, "3dgs")
    g.means[3, 1] = math.nan
    g.means[6, 0] = math.inf
    problems = validate_gaussians(g)
    assert [p.where for p in problems] == ["gaussians.means[3]"]
    with pytest.raises(RenderInputError) as err:
        render(g, make_camera())
    assert isinstance(err.value, InputError) and isinstance(err.value, RobogsError)
    assert str(err.value) == (
        "gaussians.means[3]: 2 row(s) hold NaN or inf "
        "(hint: drop or fix the Gaussians with non-finite positions)"
    )


@pytest.mark.parametrize(
    ("field", "row", "value", "where", "text"),
    [
        ("log_scales", 2, math.nan, "gaussians.log_scales[2]", "NaN or +inf"),
        ("log_scales", 1, math.inf, "gaussians.log_scales[1]", "NaN or +inf"),
        ("opacity_logits", 4, math.nan, "gaussians.opacity_logits[4]", "NaN"),
        ("sh", 0, math.inf, "gaussians.sh[0]", "NaN or inf"),
        ("extra", 5, math.nan, "gaussians.extra[5]", "NaN or inf"),
    ],
)
def test_non_finite_fields(make_gaussians, make_camera, field, row, value, where, text):
    g = make_gaussians(8, "3dgs")
    getattr(g, field)[row] = value
    problems = validate_gaussians(g)
    assert len(problems) == 1 and problems[0].where == where and text in problems[0].message
    with pytest.raises(RenderInputError, match=r"\[" + str(row) + r"\]"):
        render(g, make_camera())


def test_zero_scale_and_infinite_logit_are_accepted(make_gaussians, make_camera):
    g = make_gaussians(8, "3dgs")
    g.log_scales[0] = -math.inf  # a zero scale: a point, blurred by the 0.3 px^2 low-pass
    g.opacity_logits[1] = math.inf
    assert validate_gaussians(g) == []
    out = render(g, make_camera())
    assert bool(torch.isfinite(out.rgb).all())


def test_zero_quaternion(make_gaussians, make_camera):
    g = make_gaussians(8, "3dgs")
    g.quats[5] = 0.0
    problems = validate_gaussians(g)
    assert [p.where for p in problems] == ["gaussians.quats[5]"]
    with pytest.raises(RenderInputError, match="zero norm"):
        render(g, make_camera())


def test_shapes_kind_and_dtype(make_gaussians, make_camera):
    g = make_gaussians(8, "3dgs")
    with pytest.raises(RenderInputError, match="render kind is '2dgs'"):
        render(g, make_camera(), config=RenderConfig(kind="2dgs"))
    bad = replace(g, sh=g.sh[:, :5])
    assert "K = 5" in validate_gaussians(bad)[0].message
    bad = replace(g, opacity_logits=g.opacity_logits[:7])
    assert validate_gaussians(bad)[0].where == "gaussians.opacity_logits"
    bad = replace(g, quats=g.quats.float())
    assert "mix dtypes" in validate_gaussians(bad)[0].message
    bad = replace(g, means=g.means.long())
    assert "not a floating type" in validate_gaussians(bad)[0].message
    bad = replace(g, means=g.means.numpy())
    assert "not a torch.Tensor" in validate_gaussians(bad)[0].message


@pytest.mark.parametrize(
    ("change", "where"),
    [
        ({"fx": 0.0}, "camera.fx"),
        ({"fy": -3.0}, "camera.fy"),
        ({"fx": math.nan}, "camera.fx"),
        ({"width": 0}, "camera.width"),
        ({"height": -2}, "camera.height"),
        ({"width": 12.5}, "camera.width"),
        ({"cx": math.inf}, "camera.cx"),
        ({"near": 0.0}, "camera.near"),
        ({"far": 0.001}, "camera.far"),
        ({"distortion_model": "plumb_bob", "distortion": (0.1,)}, "camera.distortion"),
        ({"distortion_model": "kannala"}, "camera.distortion_model"),
        ({"T_world_cam": torch.eye(3)}, "camera.T_world_cam"),
        ({"T_world_cam": torch.diag(torch.tensor([2.0, 1.0, 1.0, 1.0]))}, "camera.T_world_cam"),
        ({"T_world_cam": torch.diag(torch.tensor([-1.0, 1.0, 1.0, 1.0]))}, "camera.T_world_cam"),
        ({"T_world_cam": torch.full((4, 4), math.nan)}, "camera.T_world_cam"),
    ],
)
def test_degenerate_cameras(make_gaussians, make_camera, change, where):
    cam = replace(make_camera(), **change)
    problems = validate_camera(cam)
    assert problems and problems[0].where == where
    with pytest.raises(RenderInputError, match=where.replace(".", r"\.")):
        render(make_gaussians(3, "3dgs"), cam)


def test_bad_config_is_refused(make_gaussians, make_camera):
    with pytest.raises(RenderInputError, match="config.tile_size"):
        render(make_gaussians(3, "3dgs"), make_camera(), config=RenderConfig(tile_size=0))


def test_empty_set_renders_the_background(make_gaussians, make_camera):
    g = make_gaussians(0, "3dgs")
    out = render(g, make_camera(), config=RenderConfig(background=(0.1, 0.2, 0.3)))
    assert out.rgb.shape == (29, 37, 3) and out.extra.shape == (29, 37, 2)
    assert torch.allclose(
        out.rgb, torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64).expand(29, 37, 3)
    )
    assert float(out.alpha.abs().max()) == 0.0
