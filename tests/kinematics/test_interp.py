"""Stream interpolation at int64-ns times against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from robogs.format import frames as F
from robogs.format.errors import InputError
from robogs.format.interp import bracket, interp_linear, interp_pose

EPOCH = 1_763_800_000_123_456_789  # ns since 1970, late 2025: beyond float64's integer precision


def test_linear_exact_on_linear_signal_at_epoch_scale() -> None:
    rng = np.random.default_rng(0)
    t = EPOCH + np.cumsum(rng.integers(1_000_000, 50_000_000, size=40)).astype(np.int64)
    slope = np.array([0.5, -2.0, 3.0])  # per second
    vals = (t - EPOCH)[:, None] * 1e-9 * slope + np.array([1.0, 0.0, -1.0])
    tq = rng.integers(t[0], t[-1], size=500, dtype=np.int64)
    out = interp_linear(tq, t, vals)
    expect = (tq - EPOCH)[:, None] * 1e-9 * slope + np.array([1.0, 0.0, -1.0])
    assert isinstance(out, np.ndarray) and out.shape == (500, 3)
    assert np.abs(out - expect).max() < 1e-12


def test_one_nanosecond_resolution() -> None:
    t = np.array([EPOCH, EPOCH + 1_000_000_000], dtype=np.int64)
    out = interp_linear(np.array([EPOCH + 1, EPOCH + 999_999_999]), t, np.array([0.0, 1.0]))
    assert out[0] == pytest.approx(1e-9, rel=1e-12)
    assert out[1] == pytest.approx(1 - 1e-9, rel=1e-12)
    # the naive float64 route loses the nanosecond entirely
    naive = (float(EPOCH + 1) - float(EPOCH)) / 1e9
    assert naive != pytest.approx(1e-9, rel=1e-3)


def test_samples_are_reproduced_and_outside_policies() -> None:
    t = np.array([10, 20, 40], dtype=np.int64)
    v = np.array([[1.0, 5.0], [2.0, 6.0], [4.0, 0.0]])
    assert np.array_equal(interp_linear(t, t, v), v)
    assert np.array_equal(interp_linear(np.array([30]), t, v), [[3.0, 3.0]])
    q = np.array([5, 10, 40, 45], dtype=np.int64)
    with pytest.raises(InputError, match="outside"):
        interp_linear(q, t, v)
    assert np.array_equal(interp_linear(q, t, v, outside="clamp"), v[[0, 0, 2, 2]])
    nan = interp_linear(q, t, v, outside="nan")
    assert np.isnan(nan[[0, 3]]).all() and np.array_equal(nan[[1, 2]], v[[0, 2]])
    with pytest.raises(InputError, match="outside must be"):
        interp_linear(q, t, v, outside="extrapolate")


def test_bad_stamps() -> None:
    v = np.zeros((3, 1))
    with pytest.raises(InputError, match="strictly increasing"):
        interp_linear(np.array([1]), np.array([1, 1, 2]), v)
    with pytest.raises(InputError, match="integer"):
        interp_linear(np.array([1.5]), np.array([1, 2, 3]), v)
    with pytest.raises(InputError, match="non-empty"):
        interp_linear(np.array([1]), np.array([], dtype=np.int64), np.zeros((0, 1)))
    with pytest.raises(InputError, match="rows"):
        interp_linear(np.array([1]), np.array([1, 2]), v)


def test_single_sample_and_query_shapes() -> None:
    assert np.array_equal(interp_linear(np.array([7]), np.array([7]), np.array([[3.0]])), [[3.0]])
    t = np.arange(0, 100, 10, dtype=np.int64)
    v = np.arange(10, dtype=np.float64)
    out = interp_linear(np.array([[5, 15, 25], [35, 45, 55]]), t, v)
    assert out.shape == (2, 3) and np.array_equal(out, [[0.5, 1.5, 2.5], [3.5, 4.5, 5.5]])
    i0, i1, w, outside = bracket(np.array([0, 85, 90]), t)
    assert i0.tolist() == [0, 8, 8] and i1.tolist() == [1, 9, 9]
    assert w.tolist() == [0.0, 0.5, 1.0] and not outside.any()


def test_torch_in_torch_out_and_grad() -> None:
    t = torch.tensor([0, 1_000, 3_000], dtype=torch.int64)
    v = torch.tensor([[0.0], [1.0], [3.0]], dtype=torch.float32, requires_grad=True)
    out = interp_linear(torch.tensor([500, 2_000]), t, v)
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    assert torch.allclose(out, torch.tensor([[0.5], [2.0]]))
    out.sum().backward()
    assert torch.allclose(v.grad[:, 0], torch.tensor([0.5, 1.0, 0.5]))


def test_pose_slerp_closed_form() -> None:
    axis = np.array([0.0, 0.6, 0.8])
    t = np.array([EPOCH, EPOCH + 2_000_000_000, EPOCH + 3_000_000_000], dtype=np.int64)
    angles = np.array([0.0, 1.0, 2.5])
    quats = np.stack([np.r_[math.cos(a / 2), math.sin(a / 2) * axis] for a in angles])
    quats[1] *= -1  # same rotation, opposite sign: must not take the long way round
    pos = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [1.0, 2.0, 5.0]])
    tq = np.array(
        [EPOCH + 500_000_000, EPOCH + 2_500_000_000, EPOCH + 3_000_000_000], dtype=np.int64
    )
    p, q = interp_pose(tq, t, pos, quats)
    assert np.abs(p - [[0.25, 0.5, 0.75], [1.0, 2.0, 4.0], [1.0, 2.0, 5.0]]).max() < 1e-15
    expect_angle = np.array([0.25, 1.75, 2.5])
    expect = np.stack([np.r_[math.cos(a / 2), math.sin(a / 2) * axis] for a in expect_angle])
    assert np.abs(q - expect).max() < 1e-14
    assert (q[:, 0] >= 0).all()
    ang = F.quat_angle_between(q, expect)
    assert ang.max() < 1e-14
    p_nan, q_nan = interp_pose(np.array([EPOCH - 1]), t, pos, quats, outside="nan")
    assert np.isnan(p_nan).all() and np.isnan(q_nan).all()
    with pytest.raises(InputError, match="positions must be"):
        interp_pose(tq, t, pos[:, :2], quats)
