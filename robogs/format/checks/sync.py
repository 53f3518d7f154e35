"""Time alignment between streams: camera to robot (T012), and streams that observe the same
motion (T013).

T013 compares a recorded end-effector pose stream with forward kinematics of the joint
states: see :func:`estimate_stream_lag`.

T012 is estimated from label boxes without rendering.

The bounding box of a robot link's labelled pixels in a frame must match the
bounding box of the link's projected geometry at the frame's stamp: forward
kinematics of the joints interpolated at ``t_ns + delta``, then the pinhole
camera. The extremes of a projected mesh are extremes of its projected convex
hull vertices, so only hull vertices are projected. The offset ``delta`` is fitted
by Gauss-Newton on the box edges that move (central differences in time), with a
constant bias per edge side (pixel conventions) and robust re-weighting that
drops occluded or clipped edges. It is the lag-estimation idea of
hand-eye/temporal calibration (e.g. Kalibr's camera-IMU time offset, Furgale et
al. 2013), reduced to box edges.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..errors import RobogsError
from ..findings import Finding
from ._common import MM, column, frame_stamps
from .context import CheckContext, InputReported
from .geometry import _world_from_root, joint_positions, link_geometry
from .registry import Check, check
from .stale import held_mask
from .streaming import batches, entity_series

__all__ = [
    "LagEstimate",
    "StreamLag",
    "cached_camera_lag",
    "estimate_camera_lag",
    "estimate_stream_lag",
]

_MAX_FRAMES = 300
_STEP_NS = 5_000_000
_MIN_SPEED_PX_PER_S = 20.0
_MAX_LAG_NS = 250_000_000


@dataclass(frozen=True)
class LagEstimate:
    """Fitted lag of a camera's images behind (or ahead of) its frame stamps.

    Attributes:
        offset_ms: how late the frame stamps are (stamp - true capture time), ms.
        stderr_ms: standard error of ``offset_ms``.
        edges: box edges used in the final fit.
        frames: frames used.
        residual_px: robust residual scale after the fit, px.
    """

    offset_ms: float
    stderr_ms: float
    edges: int
    frames: int
    residual_px: float


class _Model:
    """Projected link boxes at frame stamps shifted by a lag."""

    def __init__(self, ctx: CheckContext, ep, cam_stream: dict, links: dict[int, str]) -> None:
        import trimesh

        self.cam = ctx.camera(cam_stream["camera"])
        if self.cam.T_world_cam is None or self.cam.extrinsics != "static":
            raise InputReported("camera extrinsics")
        self.T_cam_world = np.linalg.inv(self.cam.T_world_cam)
        self.chain = ctx.fitted_chain()[0]
        self.ctx = ctx
        js = ctx.find_stream(ep, "joint_states")
        if js is None:
            raise InputReported("joint_states")
        self.t_js, self.q = joint_positions(ctx, ep, js, list(self.chain.joint_names))
        if self.t_js.size < 2 or not np.all(np.diff(self.t_js) > 0):
            raise InputReported("joint stamps")
        geo = link_geometry(ctx, prefer="visual")
        self.hulls: dict[str, np.ndarray] = {}
        for name in set(links.values()):
            g = geo.get(name)
            if (
                g is None
                or g.mm_problem
                or len(g.vertices) < 4
                or name not in self.chain.link_names
            ):
                continue
            try:
                self.hulls[name] = np.asarray(trimesh.convex.convex_hull(g.vertices).vertices)
            except Exception:  # flat geometry
                self.hulls[name] = g.vertices

    def boxes(
        self, t_ns: np.ndarray, link_of_obs: np.ndarray, frame_of_obs: np.ndarray, delta_ns: float
    ) -> np.ndarray:
        """[n_obs, 4] projected (x_min, y_min, x_max, y_max) px; NaN where undefined."""
        import torch

        from ..interp import interp_linear

        tq = np.rint(t_ns + delta_ns).astype(np.int64)
        inside = (tq >= self.t_js[0]) & (tq <= self.t_js[-1])
        q = interp_linear(np.clip(tq, self.t_js[0], self.t_js[-1]), self.t_js, self.q)
        T = _world_from_root(
            self.ctx, self.chain.forward(torch.as_tensor(q, dtype=torch.float64)), self.chain
        ).numpy()
        out = np.full((link_of_obs.size, 4), np.nan)
        cam = self.cam
        for name, hull in self.hulls.items():
            sel = link_of_obs == name
            if not sel.any():
                continue
            k = self.chain.link_index(name)
            T_cl = np.einsum("ij,fjk->fik", self.T_cam_world, T[:, k])  # [F, 4, 4]
            p = np.einsum("fij,vj->fvi", T_cl[:, :3, :3], hull) + T_cl[:, None, :3, 3]
            z = p[..., 2]
            uv = _project(cam, p)
            box = np.stack(
                [uv[..., 0].min(1), uv[..., 1].min(1), uv[..., 0].max(1), uv[..., 1].max(1)], 1
            )
            box[(z.min(1) <= 1e-3) | ~inside] = np.nan
            out[sel] = box[frame_of_obs[sel]]
        return out


def _project(cam, p: np.ndarray) -> np.ndarray:
    """Camera-frame points [..., 3] -> pixels [..., 2] (OpenCV model, pixel centres at +0.5)."""
    z = np.where(p[..., 2] > 1e-6, p[..., 2], 1e-6)
    x, y = p[..., 0] / z, p[..., 1] / z
    d = np.asarray(cam.distortion, np.float64)
    if cam.distortion_model in ("plumb_bob", "rational_polynomial") and d.size and np.any(d):
        k = np.zeros(8)
        k[: min(d.size, 8)] = d[:8]
        r2 = x * x + y * y
        radial = (1 + k[0] * r2 + k[1] * r2**2 + k[4] * r2**3) / (
            1 + k[5] * r2 + k[6] * r2**2 + k[7] * r2**3
        )
        x, y = (
            x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x),
            y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y,
        )
    elif cam.distortion_model == "equidistant" and d.size and np.any(d):
        r = np.sqrt(x * x + y * y)
        th = np.arctan(r)
        th_d = th * (1 + d[0] * th**2 + d[1] * th**4 + d[2] * th**6 + d[3] * th**8)
        scale = np.where(r > 1e-12, th_d / np.maximum(r, 1e-12), 1.0)
        x, y = x * scale, y * scale
    return np.stack([cam.fx * x + cam.cx, cam.fy * y + cam.cy], -1)


def estimate_camera_lag(ctx: CheckContext, ep, stream: str) -> LagEstimate | None:
    """Fit the lag of a camera stream's frame stamps against the robot's joint stamps.

    Returns None when the stream lacks what the fit needs (labels of robot links,
    a static camera, joint states, link geometry) or the links barely move.
    """
    st = ep.streams[stream]
    seg_stream = ctx.find_stream(ep, "segments")
    if (
        seg_stream is None
        or not isinstance(st.get("labels"), str)
        or not isinstance(st.get("frames"), str)
    ):
        return None
    seg = ctx.stream_table(ep, seg_stream, columns=("label_id", "kind", "target"))
    links = {
        int(r["label_id"]): str(r["target"]) for r in seg.to_pylist() if r["kind"] == "robot_link"
    }
    if not links:
        return None
    model = _Model(ctx, ep, st, links)
    f_t, f_idx = frame_stamps(
        ctx.stream_table(ep, stream, field="frames", columns=("t_ns", "frame_index"))
    )
    if f_t.size < 3 or not np.all(np.diff(f_t) > 0) or not np.all(np.diff(f_idx) > 0):
        return None
    lb = ctx.label_boxes(ep, stream)
    keep_f = f_idx[np.linspace(0, f_idx.size - 1, min(_MAX_FRAMES, f_idx.size)).round().astype(int)]
    sel = np.isin(lb.label_id, list(links)) & np.isin(lb.frame_index, keep_f)
    names = np.array([links.get(int(i), "") for i in lb.label_id[sel]], dtype=object)
    usable = np.isin(names, list(model.hulls))
    obs = np.stack([lb.x_min, lb.y_min, lb.x_max, lb.y_max], 1)[sel][usable].astype(np.float64)
    names, obs_f = names[usable], lb.frame_index[sel][usable]
    if obs.shape[0] == 0:
        return None
    used_frames, frame_of_obs = np.unique(obs_f, return_inverse=True)
    t_frames = f_t[np.searchsorted(f_idx, used_frames)]
    clipped = np.stack(
        [obs[:, 0] <= 0, obs[:, 1] <= 0, obs[:, 2] >= lb.width, obs[:, 3] >= lb.height], 1
    )
    return _fit(model, t_frames, names, frame_of_obs, obs, clipped, used_frames.size)


def _fit(
    model: _Model,
    t_frames: np.ndarray,
    names: np.ndarray,
    frame_of_obs: np.ndarray,
    obs: np.ndarray,
    clipped: np.ndarray,
    n_frames: int,
) -> LagEstimate | None:
    delta = 0.0
    side = np.broadcast_to(np.arange(4), obs.shape)
    inlier = ~clipped
    for _ in range(8):
        b0 = model.boxes(t_frames, names, frame_of_obs, delta)
        jac = (
            model.boxes(t_frames, names, frame_of_obs, delta + _STEP_NS)
            - model.boxes(t_frames, names, frame_of_obs, delta - _STEP_NS)
        ) / (2 * _STEP_NS)  # px/ns
        r = obs - b0
        ok = np.isfinite(r) & np.isfinite(jac) & inlier & (np.abs(jac) * 1e9 > _MIN_SPEED_PX_PER_S)
        if ok.sum() < 12:
            return None
        # unknowns: lag step (ns) and one bias per box side (px)
        A = np.zeros((int(ok.sum()), 5))
        A[:, 0] = jac[ok] * 1e6  # per ms
        A[np.arange(A.shape[0]), 1 + side[ok]] = 1.0
        sol, *_ = np.linalg.lstsq(A, r[ok], rcond=None)
        res = r[ok] - A @ sol
        scale = max(1.4826 * float(np.median(np.abs(res))), 0.3)
        step_ns = float(sol[0]) * 1e6
        delta += step_ns
        full = np.full(obs.shape, np.inf)
        full[ok] = np.abs(res)
        inlier = ~clipped & (full < 3.0 * scale)
        if abs(delta) > _MAX_LAG_NS:
            return None
        if abs(step_ns) < 5e4:
            break
    cov = np.linalg.pinv(A.T @ A) * scale**2
    return LagEstimate(
        offset_ms=-delta * 1e-6,
        stderr_ms=float(np.sqrt(cov[0, 0])),
        edges=int(ok.sum()),
        frames=int(n_frames),
        residual_px=scale,
    )


def cached_camera_lag(ctx: CheckContext, ep, stream: str) -> LagEstimate | None:
    """:func:`estimate_camera_lag`, once per camera stream and context (T012 and T015 share it);
    None when it cannot be estimated or its inputs are unreadable (reported elsewhere)."""

    def build() -> LagEstimate | None:
        try:
            return estimate_camera_lag(ctx, ep, stream)
        except (InputReported, RobogsError):
            return None

    return ctx.cached(("camera-lag", ep.id, stream), build)


# Checks share one shape by design: a @check(...) registration over a finding loop.
@check(
    "T012",
    group="time",
    severity="error",
    title="camera stamps agree with the robot's motion",
    quantity="fitted lag of frame stamps behind the joint stamps",
    unit="ms",
    budget="time.sync_ms",
    hint="the camera clock or offset_ns is off by this much; re-stamp the frames (the binding re-render "
    "check confirms it per frame)",
)
def _camera_lag(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.sync_ms")
    if not ctx.has_robot():
        return
    for ep, name, st in ctx.streams(("camera",)):
        est = cached_camera_lag(ctx, ep, name)  # unreadable inputs: reported by their checks
        if est is None:
            continue
        significant = abs(est.offset_ms) > 3.0 * est.stderr_ms
        if abs(est.offset_ms) > budget and significant:
            when = "late" if est.offset_ms > 0 else "early"
            yield chk.finding(
                f"camera {st.get('camera')!r}: frame stamps are {abs(est.offset_ms):.3g} ± {est.stderr_ms:.2g} ms "
                f"{when} relative to the robot's joint stamps (fit of {est.edges} link box edges in "
                f"{est.frames} frames, residual {est.residual_px:.2g} px)",
                value=est.offset_ms,
                budget=budget,
                file=st.get("frames"),
                episode=ep.id,
                stream=name,
            )


# --------------------------------------------------------------------------- stream to stream (T013)

#: value columns of a pose table
_POSE_COLS = ("x", "y", "z", "qw", "qx", "qy", "qz")
#: largest lag searched between two streams, ns
_MAX_STREAM_LAG_NS = 100_000_000
#: coarse grid step of the search, ns
_GRID_NS = 1_000_000
#: runs of contiguous observed samples a fit uses, and samples per run (:func:`motion_windows`)
_WINDOWS = 16
_PER_WINDOW = 250
#: smallest spacing of the forward-kinematics reference, ns
_REF_STEP_NS = 4_000_000
#: reference kept beyond the largest searched lag around each run, ns
_MARGIN_NS = 20_000_000
#: samples used by the coarse grid search (Gauss-Newton then uses all)
_GRID_SAMPLES = 500
#: contiguous blocks of the delete-one-block jackknife
_BLOCKS = 10
#: two-sided 97.5 % quantile of Student's t with _BLOCKS - 1 degrees of freedom
_T975 = 2.262
#: rms speed (m/s) below which a link does not move enough to time it
_MIN_SPEED = 1e-3


@dataclass(frozen=True)
class StreamLag:
    """Fitted lag of an observed stream behind a reference stream of the same motion.

    The model is ``p_obs(t) = p_ref(t - lag) + b`` with a constant offset ``b``: a positive lag
    means the observed values are late (they show the reference's past).

    Attributes:
        lag_ms: the lag, ms.
        stderr_ms: standard error from a delete-one-block jackknife over contiguous blocks
            (robust to the serial correlation of the residuals), ms.
        lo_ms, hi_ms: 95 % interval (Student's t with blocks - 1 degrees of freedom), ms.
        samples: observed samples used.
        rms_at_zero, rms_at_lag: residual rms (offset removed) at lag 0 and at the lag, in the
            units of the values (m for positions, px for image points).
    """

    lag_ms: float
    stderr_ms: float
    lo_ms: float
    hi_ms: float
    samples: int
    rms_at_zero: float
    rms_at_lag: float


def _shifted(t_ref: np.ndarray, p_ref: np.ndarray, tq: np.ndarray) -> np.ndarray:
    """[M, C] reference values linearly interpolated at float times ``tq`` (same origin),
    held at the first and last sample outside the reference's span (as ``np.interp``)."""
    i = np.clip(np.searchsorted(t_ref, tq, side="right") - 1, 0, t_ref.size - 2)
    w = np.clip((tq - t_ref[i]) / (t_ref[i + 1] - t_ref[i]), 0.0, 1.0)[:, None]
    return p_ref[i] * (1.0 - w) + p_ref[i + 1] * w


def _cost(r: np.ndarray) -> float:
    return float(np.sum((r - r.mean(axis=0)) ** 2))


def estimate_stream_lag(
    t_ref: np.ndarray,
    p_ref: np.ndarray,
    t_obs: np.ndarray,
    p_obs: np.ndarray,
    *,
    max_lag_ns: int = _MAX_STREAM_LAG_NS,
    blocks: int = _BLOCKS,
    min_speed: float = _MIN_SPEED,
) -> StreamLag | None:
    """Lag of ``p_obs`` behind ``p_ref`` (least squares on interpolated positions).

    The cost ``sum |p_obs(t) - p_ref(t - lag) - b|^2`` (``b`` the mean residual) is evaluated
    on a 1 ms grid over ``[-max_lag, max_lag]`` (on at most 500 evenly spaced samples), refined by a parabola through the best grid
    point and its neighbours, then by Gauss-Newton steps with the reference velocity (central
    differences of the interpolant). The interval comes from a delete-one-block jackknife
    (Efron and Tibshirani 1993, ch. 11; blocks keep the serial correlation inside).

    Args:
        t_ref: [N] int64 reference stamps, ns, strictly increasing.
        p_ref: [N, C] reference values (positions, m).
        t_obs: [M] int64 observed stamps, ns.
        p_obs: [M, C] observed values, same units and frame.
        max_lag_ns: largest lag searched.
        blocks: jackknife blocks.
        min_speed: rms speed of the reference (value units per s) below which the motion is too
            slow to time (None is returned).

    Returns:
        The estimate, or None when too few observed samples lie inside the reference's span
        or the reference barely moves.
    """
    if t_ref.size < 3 or t_obs.size < 4 * blocks:
        return None
    origin = int(t_ref[0])
    tr = (t_ref - origin).astype(np.float64)
    to = (t_obs - origin).astype(np.float64)
    inside = (to >= tr[0] + max_lag_ns) & (to <= tr[-1] - max_lag_ns)
    if inside.sum() < 4 * blocks:
        return None
    to, po = to[inside], np.asarray(p_obs, np.float64)[inside]
    pr = np.asarray(p_ref, np.float64)

    def resid(lag: float) -> np.ndarray:
        return po - _shifted(tr, pr, to - lag)

    grid = np.arange(-max_lag_ns, max_lag_ns + 1, _GRID_NS, dtype=np.float64)
    sub = np.unique(np.linspace(0, to.size - 1, min(to.size, _GRID_SAMPLES)).astype(np.int64))
    vals = _shifted(tr, pr, (to[sub][None, :] - grid[:, None]).ravel())  # every lag at once
    rg = po[sub][None] - vals.reshape(grid.size, sub.size, -1)
    costs = np.sum((rg - rg.mean(axis=1, keepdims=True)) ** 2, axis=(1, 2))
    i = int(np.clip(np.argmin(costs), 1, grid.size - 2))
    c0, c1, c2 = costs[i - 1], costs[i], costs[i + 1]
    curv = c0 - 2 * c1 + c2
    lag = grid[i] + (0.5 * _GRID_NS * (c0 - c2) / curv if curv > 0 else 0.0)
    h = 0.25 * _GRID_NS
    for _ in range(5):
        r = resid(lag)
        jac = (_shifted(tr, pr, to - lag + h) - _shifted(tr, pr, to - lag - h)) / (2 * h)
        r, jac = r - r.mean(axis=0), jac - jac.mean(axis=0)  # dr/dlag = v_ref(t - lag)
        jj = float(np.sum(jac * jac))
        if jj <= 0:
            return None
        step = -float(np.sum(jac * r)) / jj
        lag += step
        if abs(step) < 1e3:  # 1 us
            break
    r = resid(lag)
    jac = (_shifted(tr, pr, to - lag + h) - _shifted(tr, pr, to - lag - h)) / (2 * h)
    speed_rms = float(np.sqrt(np.mean(np.sum((jac - jac.mean(axis=0)) ** 2, axis=1)))) * 1e9
    if speed_rms < min_speed:
        return None
    reps = []
    for idx in np.array_split(np.arange(to.size), blocks):
        keep = np.ones(to.size, bool)
        keep[idx] = False
        rk = r[keep] - r[keep].mean(axis=0)
        jk = jac[keep] - jac[keep].mean(axis=0)
        reps.append(lag - float(np.sum(jk * rk)) / float(np.sum(jk * jk)))
    reps_a = np.array(reps)
    se = float(np.sqrt((blocks - 1) / blocks * np.sum((reps_a - reps_a.mean()) ** 2)))
    n = float(to.size)
    return StreamLag(
        lag_ms=lag * 1e-6,
        stderr_ms=se * 1e-6,
        lo_ms=(lag - _T975 * se) * 1e-6,
        hi_ms=(lag + _T975 * se) * 1e-6,
        samples=int(to.size),
        rms_at_zero=float(np.sqrt(_cost(resid(0.0)) / n)),
        rms_at_lag=float(np.sqrt(_cost(r) / n)),
    )


def motion_windows(
    t: np.ndarray, p: np.ndarray, *, windows: int = _WINDOWS, per: int = _PER_WINDOW
) -> np.ndarray:
    """Indices of the samples a lag fit uses: ``windows`` contiguous runs of ``per`` samples.

    A lag is timed by motion, so the runs with the longest path ``sum |p[k+1] - p[k]|`` are
    kept (in time order); a series of at most ``windows * per`` samples is kept whole. This
    bounds the cost of the fit, and of the reference it needs, on long episodes.

    Args:
        t: [N] stamps, ns, increasing.
        p: [N, C] values (e.g. positions, m).
    """
    n = t.size
    if n <= windows * per:
        return np.arange(n)
    k = n // per
    step = np.concatenate([[0.0], np.linalg.norm(np.diff(p, axis=0), axis=1)])
    step[~np.isfinite(step)] = 0.0  # non-finite values (I009) do not make a run move
    score = np.add.reduceat(step[: k * per], np.arange(k) * per)
    best = np.sort(np.argsort(score, kind="stable")[-windows:])
    return (best[:, None] * per + np.arange(per)[None, :]).ravel()


def _near(t_ref: np.ndarray, t_obs: np.ndarray, margin_ns: int) -> np.ndarray:
    """[N] bool: reference stamps within ``margin_ns`` of some observed stamp.

    The observed stamps come in contiguous runs; a run's span is widened by the margin."""
    keep = np.zeros(t_ref.size, bool)
    if t_obs.size == 0:
        return keep
    gaps = np.flatnonzero(np.diff(t_obs) > margin_ns)
    starts = t_obs[np.concatenate([[0], gaps + 1])] - margin_ns
    ends = t_obs[np.concatenate([gaps, [t_obs.size - 1]])] + margin_ns
    lo = np.searchsorted(t_ref, starts, side="left")
    hi = np.searchsorted(t_ref, ends, side="right")
    edge = np.zeros(t_ref.size + 1, np.int64)
    np.add.at(edge, lo, 1)
    np.add.at(edge, hi, -1)
    keep = np.cumsum(edge[:-1]) > 0
    # one sample beyond each span, so interpolation brackets every query
    keep[1:] |= keep[:-1]
    keep[:-1] |= keep[1:]
    return keep


def _fk_positions(
    ctx: CheckContext, js_rel: str, links: list[str], t_need: np.ndarray
) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
    """Fresh (not held) joint stamps near ``t_need`` and the FK positions (world, m) of
    ``links`` there: forward kinematics runs only where the fit will interpolate it."""
    import torch

    chain = ctx.fitted_chain()[0]
    qcols = tuple(f"position.{j}" for j in chain.joint_names)
    names = ctx.footer(js_rel).schema.to_arrow_schema().names
    if any(c not in names for c in qcols) or "t_ns" not in names or not qcols:
        return None
    ts, qs = [], []
    for b in batches(ctx, js_rel, ("t_ns", *qcols)):
        ts.append(column(b, "t_ns").astype(np.int64))
        qs.append(np.stack([column(b, c) for c in qcols], axis=1).astype(np.float64))
    if not ts:
        return None
    t, q = np.concatenate(ts), np.concatenate(qs)
    if t.size < 3 or not np.all(np.diff(t) > 0):
        return None  # reported by T001
    near = _near(t, np.sort(t_need), _MAX_STREAM_LAG_NS + _MARGIN_NS)
    near &= np.all(np.isfinite(q), axis=1)  # I009 reports the others
    t, q = t[near], q[near]
    fresh = ~held_mask(t, q)  # runs are far apart: a repeat across two runs is not held
    t, q = t[fresh], q[fresh]
    if t.size < 3:
        return None
    # decimated to >= _REF_STEP_NS: linear interpolation between samples 4 ms apart errs by
    # |a| dt^2 / 8 (2 um at 1 m/s^2), symmetric in time, so the lag is not biased
    every = max(1, int(round(_REF_STEP_NS / float(np.median(np.diff(t))))))
    t, q = t[::every], q[::every]
    with torch.inference_mode():
        T = _world_from_root(ctx, chain.forward(torch.as_tensor(q, dtype=torch.float64)), chain)
        pos = T[..., :3, 3].numpy()  # [N, L, 3]
    return t, {link: pos[:, chain.link_index(link)] for link in links}


def _ee_series(ctx: CheckContext, rel: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per link of an ee_poses table: (stamps, positions) of the fresh (not held) samples in
    the windows of most motion (:func:`motion_windows`)."""
    out = {}
    for link, (t, v) in entity_series(ctx, rel, "link", _POSE_COLS).items():
        if t.size < 3 or not np.all(np.diff(t) > 0):
            continue  # reported by T001
        sel = motion_windows(t, v[:, :3])  # first: the filters below then see 4,000 rows
        t, v = t[sel], v[sel]
        finite = np.all(np.isfinite(v), axis=1)  # I009 reports the others
        t, v = t[finite], v[finite]
        keep = ~held_mask(t, v)  # runs are far apart: a repeat across two runs is not held
        out[link] = (t[keep], v[keep, :3])
    return out


@check(
    "T013",
    group="time",
    severity="error",
    title="streams of the same motion agree in time",
    quantity="fitted lag of the end-effector poses behind forward kinematics of the joints",
    unit="ms",
    budget="time.lag_ms",
    hint="the pose stream is stamped late (or early) against the joints: correct its offset_ns "
    "by the lag, or stamp it where it is measured; the lag is fitted on fresh samples only",
)
def _stream_lag(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.lag_ms")
    if not ctx.has_robot():
        return
    try:
        chain = ctx.fitted_chain()[0]
    except (InputReported, RobogsError):
        return  # reported by G001
    for ep, name, st in ctx.streams(("ee_poses",)):
        js = ctx.find_stream(ep, "joint_states")
        rel = st.get("path")
        if js is None or not isinstance(rel, str):
            continue
        try:
            obs = {k: v for k, v in _ee_series(ctx, rel).items() if k in chain.link_names}
            t_need = np.concatenate([v[0] for v in obs.values()]) if obs else None
            ref = _fk_positions(ctx, ep.streams[js]["path"], sorted(obs), t_need) if obs else None
        except InputReported:
            continue
        if ref is None:
            continue
        t_ref, p_ref = ref
        for link, (t_obs, p_obs) in sorted(obs.items()):
            est = estimate_stream_lag(t_ref, p_ref[link], t_obs, p_obs)
            if est is None:
                continue
            significant = abs(est.lag_ms) > 3.0 * est.stderr_ms
            if abs(est.lag_ms) > budget and significant:
                when = "behind" if est.lag_ms > 0 else "ahead of"
                yield chk.finding(
                    f"link {link!r}: poses run {abs(est.lag_ms):.3g} ms {when} forward kinematics "
                    f"of {js!r} (95 % interval {est.lo_ms:.4g} to {est.hi_ms:.4g} ms, "
                    f"{est.samples} fresh samples); removing the lag takes the rms from "
                    f"{est.rms_at_zero * MM:.3g} to {est.rms_at_lag * MM:.3g} mm (offset removed)",
                    value=est.lag_ms,
                    budget=budget,
                    file=rel,
                    episode=ep.id,
                    stream=name,
                    link=link,
                )
