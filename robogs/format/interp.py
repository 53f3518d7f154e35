"""Interpolation of sampled streams at arbitrary int64-nanosecond times.

Stamps stay int64 until a difference of two stamps is taken, so no precision is lost on long
epochs (a float64 holds absolute epoch nanoseconds only to ~256 ns). Weights are
``(t_query - t_i) / (t_{i+1} - t_i)`` with both differences formed in int64.

Functions accept numpy arrays or torch tensors. Results are torch tensors on the values' device
when the values are torch tensors, and numpy arrays otherwise.

Outside the sampled range ``[t_ns[0], t_ns[-1]]`` (inclusive) the ``outside`` policy applies:
``"raise"`` (default) raises :class:`~robogs.format.errors.InputError`; ``"clamp"`` holds the
first/last sample; ``"nan"`` returns NaN for those queries.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import torch

from robogs.format.errors import InputError
from robogs.format.frames import quat_normalize, quat_slerp

__all__ = ["OUTSIDE_POLICIES", "bracket", "interp_linear", "interp_pose"]

Outside = Literal["raise", "clamp", "nan"]
OUTSIDE_POLICIES: tuple[str, ...] = ("raise", "clamp", "nan")


def _stamps(x: Any, name: str) -> torch.Tensor:
    if isinstance(x, torch.Tensor):
        t = x
    else:
        arr = np.asarray(x)
        if arr.dtype.kind not in "iu":
            raise InputError(f"{name} must be integer nanoseconds, got dtype {arr.dtype}")
        t = torch.from_numpy(np.ascontiguousarray(arr, dtype=np.int64))
    if t.is_floating_point() or t.is_complex() or t.dtype == torch.bool:
        raise InputError(f"{name} must be integer nanoseconds, got dtype {t.dtype}")
    return t.to(torch.int64)


def bracket(
    t_query_ns: Any, t_ns: Any, *, outside: Outside = "raise"
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Find the samples around each query time.

    Args:
        t_query_ns: [...] int64 query stamps, ns.
        t_ns: [N] int64 sample stamps, ns, strictly increasing.
        outside: policy for queries outside ``[t_ns[0], t_ns[-1]]``.

    Returns:
        ``(i0, i1, w, out)``: [...] int64 indices of the bracketing samples, [...] float64
        weight of ``i1`` (in [0, 1]; clamped outside the range), and a [...] bool mask of
        queries outside the range. Tensors live on ``t_ns``'s device.

    Raises:
        InputError: empty or non-increasing ``t_ns``, a bad policy, or (with
            ``outside="raise"``) a query outside the range.
    """
    if outside not in OUTSIDE_POLICIES:
        raise InputError(f"outside must be one of {OUTSIDE_POLICIES}, got {outside!r}")
    t = _stamps(t_ns, "t_ns")
    tq = _stamps(t_query_ns, "t_query_ns").to(t.device)
    if t.ndim != 1 or t.numel() == 0:
        raise InputError(f"t_ns must be a non-empty 1-D array, got shape {tuple(t.shape)}")
    if t.numel() > 1:
        steps = t[1:] - t[:-1]
        if bool((steps <= 0).any()):
            k = int(torch.nonzero(steps <= 0)[0, 0]) + 1
            raise InputError(
                "t_ns must be strictly increasing",
                where=f"sample {k} (t_ns={int(t[k])})",
                hint="sort the stream and drop duplicate stamps first",
            )
    out = (tq < t[0]) | (tq > t[-1])
    if outside == "raise" and bool(out.any()):
        first = int(tq[out].reshape(-1)[0])
        raise InputError(
            f"{int(out.sum())} query time(s) outside the sampled range [{int(t[0])}, {int(t[-1])}] ns",
            where=f"t_query_ns={first}",
            hint="pass outside='clamp' or outside='nan' to allow it",
        )
    n = t.numel()
    if n == 1:
        i0 = torch.zeros_like(tq)
        return i0, i0, torch.zeros(tq.shape, dtype=torch.float64, device=t.device), out
    i0 = (torch.searchsorted(t, tq, right=True) - 1).clamp(0, n - 2)
    i1 = i0 + 1
    num = (tq - t[i0]).to(torch.float64)
    den = (t[i1] - t[i0]).to(torch.float64)
    w = (num / den).clamp(0.0, 1.0)
    return i0, i1, w, out


def _values(x: Any) -> tuple[torch.Tensor, bool]:
    if isinstance(x, torch.Tensor):
        v = x
        is_np = False
    else:
        v = torch.from_numpy(np.ascontiguousarray(np.asarray(x)))
        is_np = True
    if not v.is_floating_point():
        v = v.to(torch.float64)
    return v, is_np


def _out(x: torch.Tensor, is_np: bool) -> Any:
    return x.detach().cpu().numpy() if is_np else x


def interp_linear(t_query_ns: Any, t_ns: Any, values: Any, *, outside: Outside = "raise") -> Any:
    """Piecewise-linear interpolation of a sampled stream (e.g. joint positions).

    Angles are interpolated as plain numbers (no wrapping at +-pi).

    Args:
        t_query_ns: [...Q] int64 query stamps, ns.
        t_ns: [N] int64 sample stamps, ns, strictly increasing.
        values: [N, ...] samples (any trailing shape).
        outside: ``"raise"``, ``"clamp"`` or ``"nan"`` (see module docstring).

    Returns:
        [...Q, ...] interpolated values, dtype of ``values`` (float64 for integer input);
        torch on ``values``' device if ``values`` is a tensor, numpy otherwise.
    """
    v, is_np = _values(values)
    i0, i1, w, out = bracket(t_query_ns, t_ns, outside=outside)
    if v.shape[0] != _stamps(t_ns, "t_ns").numel():
        raise InputError(
            f"values has {v.shape[0]} rows but t_ns has {_stamps(t_ns, 't_ns').numel()} stamps"
        )
    i0, i1, w, out = (x.to(v.device) for x in (i0, i1, w, out))
    wv = w.to(v.dtype).reshape(*w.shape, *([1] * (v.ndim - 1)))
    v0, v1 = v[i0], v[i1]
    res = v0 + wv * (v1 - v0)
    if outside == "nan" and bool(out.any()):
        mask = out.reshape(*out.shape, *([1] * (v.ndim - 1)))
        res = torch.where(mask, torch.full_like(res, float("nan")), res)
    return _out(res, is_np)


def interp_pose(
    t_query_ns: Any,
    t_ns: Any,
    positions: Any,
    quats_wxyz: Any,
    *,
    outside: Outside = "raise",
) -> tuple[Any, Any]:
    """Interpolate a pose stream: linear in position, slerp (shortest arc) in rotation.

    Args:
        t_query_ns: [...Q] int64 query stamps, ns.
        t_ns: [N] int64 sample stamps, ns, strictly increasing.
        positions: [N, 3] metres.
        quats_wxyz: [N, 4] unit quaternions (w, x, y, z); sign flips between samples are
            harmless (the shorter arc is taken).
        outside: ``"raise"``, ``"clamp"`` or ``"nan"``.

    Returns:
        ``(positions [...Q, 3], quats [...Q, 4])``; quaternions are unit with ``w >= 0``.
        Torch if ``positions`` is a tensor, numpy otherwise.
    """
    p, is_np = _values(positions)
    q, _ = _values(quats_wxyz)
    q = q.to(dtype=p.dtype, device=p.device)
    if p.ndim != 2 or p.shape[1] != 3 or q.shape != (p.shape[0], 4):
        raise InputError(
            f"positions must be [N, 3] and quats [N, 4], got {tuple(p.shape)} and {tuple(q.shape)}"
        )
    i0, i1, w, out = bracket(t_query_ns, t_ns, outside=outside)
    if p.shape[0] != _stamps(t_ns, "t_ns").numel():
        raise InputError("positions/quats rows do not match the number of stamps")
    i0, i1, w, out = (x.to(p.device) for x in (i0, i1, w, out))
    wp = w.to(p.dtype)
    pos = p[i0] + wp[..., None] * (p[i1] - p[i0])
    qn = quat_normalize(q)
    rot = quat_slerp(qn[i0], qn[i1], wp)
    if outside == "nan" and bool(out.any()):
        pos = torch.where(out[..., None], torch.full_like(pos, float("nan")), pos)
        rot = torch.where(out[..., None], torch.full_like(rot, float("nan")), rot)
    return _out(pos, is_np), _out(rot, is_np)
