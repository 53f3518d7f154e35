"""Lag between other pairs of streams that observe the same motion (T015, T016).

T015, object pose vs a camera's 2-D boxes: each recorded object pose is projected into the
camera (the asset mesh's convex hull through the pinhole model of its static extrinsics and
intrinsics), and the centre of the projected box is compared with the centre of the object's
box in each frame (the ``boxes2d`` rows, or the boxes of its label masks). The lag of the image
centres behind the projected ones is fitted by :func:`~robogs.format.checks.sync.
estimate_stream_lag` (in px), on the projected centres smoothed in time (a local quadratic
fit: linearly interpolated raw poses pull the lag towards the phases where the box stamps fall
midway between poses, see :func:`box_centre_lag`); its 95 % interval takes Student's t of the
jackknife blocks and adds T012's error of the camera offset. The frames are stamped by the camera, whose own offset against
the robot T012 measures; that offset is removed, so T015 reports how late the *pose stream* is
on the robot's clock, and a late camera is reported once (by T012).

T016, wrench vs contact: contact starts when the object starts to move. For every rise of the
force magnitude out of its floor (the sensor's offset removed), the object's displacement from
its rest position around it is extrapolated back to zero along its first millimetres of motion,
and the force back to its floor along its rise; the lag is the mean of ``t_force - t_motion``
over the pushes (Student's t interval). At least three pushes are needed. What a lag means
depends on how the robot pushes, read from the ``command_kind`` of the episode's ``actions``
stream (:func:`control_mode`):

* a positive lag (wrench late) is an error under any control: a force cannot follow the motion
  it causes;
* position (or velocity) commands: a stiff pusher touches, loads and moves the object at once,
  so a clean recording gives a lag within the sampling, and a negative one (wrench early) is an
  error too;
* effort commands (force control): the force builds up to break the object away, so it leads
  the motion by a physical amount (tens of ms); a negative lag is a note, reported with its size;
* no ``command_kind``: the sign of a negative lag is physically ambiguous; it is a note that says
  both readings.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..errors import RobogsError
from ..findings import Finding
from ..frames import quat_to_matrix_np
from ._common import column, frame_stamps
from .assets import hull_vertices
from .context import CheckContext, InputReported
from .registry import Check, check
from .stale import held_mask
from .streaming import entity_series
from .sync import _POSE_COLS, StreamLag, _project, cached_camera_lag, estimate_stream_lag

__all__ = [
    "ContactLag",
    "box_centre_lag",
    "contact_lag",
    "control_mode",
    "projected_centres",
    "smooth_series",
]

#: rms speed (px/s) of the projected object below which a camera cannot time it
_MIN_PX_SPEED = 5.0
#: share by which removing a lag must lower the box-centre rms to count as seen (below it the
#: boxes' pixel quantisation, not the timing, dominates the residuals)
_MIN_GAIN = 0.05
#: jackknife blocks for the (short) box series
_BOX_BLOCKS = 8
#: half-span (ns) and most samples each side of the projected centres' smoothing
_SMOOTH_NS = 40_000_000
_SMOOTH_MAX = 5
#: samples smoothed at once
_SMOOTH_CHUNK = 32_768
#: two-sided 97.5 % Student's t quantiles by degrees of freedom (1..10; beyond: 2.0)
_T975 = (12.71, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228)
#: window around a force rise searched for the object's rest and motion, ns
_CONTACT_WINDOW_NS = 250_000_000
#: displacement (m) from rest taken as "moving" at least (and 6 sigma of the pose noise)
_MOVE_M = 1e-3
#: pushes a wrench lag needs before it is reported (its interval comes from their spread)
_MIN_PUSHES = 3
#: span after the first moving sample over which the start of the motion is fitted, ns
_ONSET_FIT_NS = 60_000_000


# --------------------------------------------------------------------------- shared


def _poses(ctx: CheckContext, rel: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per object of an ``object_poses`` table: fresh (not held) stamps [N] and [N, 7]
    ``x, y, z, qw, qx, qy, qz``; series whose stamps do not increase are left out (T001)."""
    out = {}
    for name, (t, v) in entity_series(ctx, rel, "object", _POSE_COLS).items():
        if t.size < 3 or not np.all(np.diff(t) > 0) or not np.all(np.isfinite(v)):
            continue  # T001 / I009
        keep = ~held_mask(t, v)
        out[name] = (t[keep], v[keep])
    return out


def _t975(dof: int) -> float:
    return _T975[dof - 1] if 1 <= dof <= len(_T975) else 2.0


# --------------------------------------------------------------------------- T015


def projected_centres(cam, T_world_obj: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """[N, 2] centres (px) of the boxes of ``hull`` (object frame, m) seen by ``cam`` at each
    pose ``T_world_obj`` [N, 4, 4]; NaN where a vertex lies behind the camera."""
    T_cam_obj = np.linalg.inv(cam.T_world_cam)[None] @ T_world_obj
    p = np.einsum("nij,vj->nvi", T_cam_obj[:, :3, :3], hull) + T_cam_obj[:, None, :3, 3]
    uv = _project(cam, p)
    c = 0.5 * (uv.min(axis=1) + uv.max(axis=1))
    c[p[..., 2].min(axis=1) <= 1e-3] = np.nan
    return c


def _pose_matrices(v: np.ndarray) -> np.ndarray:
    T = np.tile(np.eye(4), (v.shape[0], 1, 1))
    q = v[:, 3:7] / np.linalg.norm(v[:, 3:7], axis=1, keepdims=True)
    T[:, :3, :3] = quat_to_matrix_np(q)
    T[:, :3, 3] = v[:, :3]
    return T


def _object_labels(ctx: CheckContext, ep) -> dict[str, list[int]]:
    seg = ctx.find_stream(ep, "segments")
    if seg is None:
        return {}
    out: dict[str, list[int]] = {}
    for r in ctx.stream_table(ep, seg, columns=("label_id", "kind", "target")).to_pylist():
        if r["kind"] == "object" and r["target"]:
            out.setdefault(str(r["target"]), []).append(int(r["label_id"]))
    return out


def _camera_stream(ep, camera: str) -> str | None:
    for name, st in ep.streams.items():
        if isinstance(st, dict) and st.get("kind") == "camera" and st.get("camera") == camera:
            return name
    return None


def _frame_clock(ctx: CheckContext, ep, cam_stream: str | None) -> tuple[np.ndarray, np.ndarray]:
    """(frame indices, stamps) of a camera's frame table; empty when it has none."""
    if cam_stream is None or not isinstance(ep.streams[cam_stream].get("frames"), str):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    t, idx = frame_stamps(
        ctx.stream_table(ep, cam_stream, field="frames", columns=("t_ns", "frame_index"))
    )
    order = np.argsort(idx)
    return idx[order], t[order]


def _camera_offset_ms(ctx: CheckContext, ep, cam_stream: str | None) -> tuple[float, float] | None:
    """T012's lag of the camera's frame stamps behind the joints and its standard error (ms);
    None if unknown."""
    if cam_stream is None or not ctx.has_robot():
        return None
    est = cached_camera_lag(ctx, ep, cam_stream)
    return None if est is None else (float(est.offset_ms), float(est.stderr_ms))


def _observed_boxes(
    ctx: CheckContext, ep, camera: str, labels: list[int], cam
) -> tuple[np.ndarray, np.ndarray, str] | None:
    """Stamps [M] and centres [M, 2] (px) of an object's unclipped boxes in one camera, and
    the file they come from (``boxes2d`` rows, else the camera's label masks)."""
    cam_stream = _camera_stream(ep, camera)
    f_idx, f_t = _frame_clock(ctx, ep, cam_stream)
    cols = ("t_ns", "camera", "frame_index", "label_id", "x_min", "y_min", "x_max", "y_max")
    for name, st in ep.streams.items():
        if not (isinstance(st, dict) and st.get("kind") == "boxes2d"):
            continue
        rel = st.get("path")
        if not isinstance(rel, str):
            continue
        tab = ctx.stream_table(ep, name, columns=cols)
        sel = (column(tab, "camera").astype(str) == camera) & np.isin(
            column(tab, "label_id"), labels
        )
        if sel.sum() == 0:
            continue
        box = np.stack([column(tab, c, sel) for c in cols[4:]], 1).astype(np.float64)
        t = column(tab, "t_ns", sel).astype(np.int64)
        fi = column(tab, "frame_index", sel).astype(np.int64)
        return _unclipped(*_restamp(t, fi, f_idx, f_t), box, cam, rel)
    if cam_stream is None or not isinstance(ep.streams[cam_stream].get("labels"), str):
        return None
    lb = ctx.label_boxes(ep, cam_stream)
    sel = np.isin(lb.label_id, labels) & np.isin(lb.frame_index, f_idx)
    if not sel.any():
        return None
    fi = lb.frame_index[sel]
    t = f_t[np.searchsorted(f_idx, fi)]
    box = np.stack([lb.x_min, lb.y_min, lb.x_max, lb.y_max], 1)[sel].astype(np.float64)
    return _unclipped(t, fi, box, cam, ep.streams[cam_stream]["labels"])


def _restamp(
    t: np.ndarray, fi: np.ndarray, f_idx: np.ndarray, f_t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Box stamps taken from the frame table where it lists the frame (T011 checks the box
    stamps against it), else the boxes' own ``t_ns``."""
    if f_idx.size:
        k = np.clip(np.searchsorted(f_idx, fi), 0, f_idx.size - 1)
        known = f_idx[k] == fi
        t = np.where(known, f_t[k], t)
    return t, fi


def _unclipped(
    t: np.ndarray, fi: np.ndarray, box: np.ndarray, cam, rel: str
) -> tuple[np.ndarray, np.ndarray, str] | None:
    """Boxes touching the image border are left out (their centre does not follow the object);
    several boxes of the object in one frame (split by occlusion) become their union."""
    inside = (box[:, 0] > 0) & (box[:, 1] > 0) & (box[:, 2] < cam.width) & (box[:, 3] < cam.height)
    t, fi, box = t[inside], fi[inside], box[inside]
    if t.size == 0:
        return None
    frames, first, inv = np.unique(fi, return_index=True, return_inverse=True)
    lo = np.full((frames.size, 2), np.inf)
    hi = np.full((frames.size, 2), -np.inf)
    np.minimum.at(lo, inv, box[:, :2])
    np.maximum.at(hi, inv, box[:, 2:])
    tt = t[first]
    order = np.argsort(tt)
    return tt[order], (0.5 * (lo + hi))[order], rel


def smooth_series(t: np.ndarray, p: np.ndarray, k: int) -> np.ndarray:
    """[N, C] values ``p`` smoothed by a local quadratic fit in time over the ``2k + 1`` samples
    around each one (the first and last full windows at the ends), evaluated at its stamp.

    A local polynomial regression (Savitzky and Golay 1964; Cleveland 1979) on the stamps, so
    held samples left out do not skew it; symmetric windows shift no time. ``k < 2`` or fewer
    than ``2k + 1`` samples: ``p`` unchanged.

    Args:
        t: [N] int64 stamps, ns, increasing; p: [N, C] values.
    """
    n = t.size
    p = np.asarray(p, np.float64)
    if k < 2 or n < 2 * k + 1:
        return p
    out = np.empty_like(p)
    for lo in range(0, n, _SMOOTH_CHUNK):  # bounded memory on long episodes
        rows = np.arange(lo, min(n, lo + _SMOOTH_CHUNK))
        idx = np.clip(rows, k, n - 1 - k)[:, None] + np.arange(-k, k + 1)[None]  # [R, 2k+1]
        dt = (t[idx] - t[rows, None]).astype(np.float64) * 1e-9  # s from the evaluated sample
        A = np.stack([np.ones_like(dt), dt, dt * dt], axis=2)  # [R, 2k+1, 3]
        AtA = np.einsum("nki,nkj->nij", A, A)
        Atp = np.einsum("nki,nkc->nic", A, p[idx])
        out[rows] = np.linalg.solve(AtA, Atp)[:, 0]  # the constant term: the fit at dt = 0
    return out


def box_centre_lag(
    t_p: np.ndarray, c_p: np.ndarray, t_b: np.ndarray, c_b: np.ndarray
) -> StreamLag | None:
    """Lag (ms) of observed box centres ``c_b`` [M, 2] px at ``t_b`` behind the projected pose
    centres ``c_p`` [N, 2] px at ``t_p`` (int64 ns), by :func:`~robogs.format.checks.sync.
    estimate_stream_lag`, its interval with the Student's t of its :data:`_BOX_BLOCKS` blocks.

    The projected centres are smoothed first (:func:`smooth_series` over :data:`_SMOOTH_NS`
    each side). Linear interpolation of a noisy reference weights its noise by ``w^2 +
    (1 - w)^2`` at a fraction ``w`` between samples, so the least-squares cost is lowest where
    the shifted box stamps fall midway between poses: the lag is pulled towards those phases
    (0.8 ms for 0.2 mm pose noise at 120 Hz and 0.1 m/s). Smoothing makes neighbouring
    samples' noise nearly equal, and the pull with it.
    """
    dt = float(np.median(np.diff(t_p))) if t_p.size > 1 else 0.0
    k = int(np.clip(round(_SMOOTH_NS / dt), 2, _SMOOTH_MAX)) if dt > 0 else 0
    est = estimate_stream_lag(
        t_p,
        smooth_series(t_p, c_p, k),
        t_b,
        c_b,
        blocks=_BOX_BLOCKS,
        min_speed=_MIN_PX_SPEED,
    )
    if est is None:
        return None
    half = _t975(_BOX_BLOCKS - 1) * est.stderr_ms
    return dataclasses.replace(est, lo_ms=est.lag_ms - half, hi_ms=est.lag_ms + half)


@dataclass(frozen=True)
class _BoxLag:
    lag_ms: float  # the pose stream behind the camera's frames
    pose_lag_ms: float  # the pose stream behind the robot's clock (camera offset removed)
    lo_ms: float
    hi_ms: float
    stderr_ms: float
    samples: int
    rms_px: tuple[float, float]
    camera_offset_ms: float | None


def box_lag(ctx: CheckContext, ep, obj: str, camera: str, t_p, v_p) -> tuple[_BoxLag, str] | None:
    """T015's fit for one object in one camera (None: not enough to time it)."""
    cam = ctx.camera(camera)
    if cam.T_world_cam is None or cam.extrinsics != "static":
        return None
    labels = _object_labels(ctx, ep).get(obj)
    if not labels:
        return None
    obs = _observed_boxes(ctx, ep, camera, labels, cam)
    if obs is None:
        return None
    t_b, c_b, rel = obs
    try:
        hull = hull_vertices(ctx, obj)
    except (InputReported, RobogsError):
        hull = np.zeros((1, 3))  # no mesh: the object's origin
    c_p = projected_centres(cam, _pose_matrices(v_p), hull)
    ok = np.all(np.isfinite(c_p), axis=1)
    if ok.sum() < 3:
        return None
    est = box_centre_lag(t_p[ok], c_p[ok], t_b, c_b)
    if est is None:
        return None
    cam = _camera_offset_ms(ctx, ep, _camera_stream(ep, camera))
    cam_off, cam_se = cam if cam is not None else (None, 0.0)
    # boxes behind projected poses by L = camera offset - pose delay; the two errors add
    pose_lag = (cam_off or 0.0) - est.lag_ms
    se = float(np.hypot(est.stderr_ms, cam_se))
    half = _t975(_BOX_BLOCKS - 1) * se
    out = _BoxLag(
        lag_ms=-est.lag_ms,
        pose_lag_ms=pose_lag,
        lo_ms=pose_lag - half,
        hi_ms=pose_lag + half,
        stderr_ms=se,
        samples=est.samples,
        rms_px=(est.rms_at_zero, est.rms_at_lag),
        camera_offset_ms=cam_off,
    )
    return out, rel


@check(
    "T015",
    group="time",
    severity="error",
    title="object poses agree in time with the camera's boxes",
    quantity="fitted lag of the object poses behind the object's 2-D boxes (camera offset "
    "from T012 removed)",
    unit="ms",
    budget="time.lag_ms",
    hint="the object pose stream (mocap, tracker) is stamped late (or early) against the "
    "images: correct its offset_ns by the lag, or stamp it where it is measured",
)
def _object_box_lag(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.lag_ms")
    for ep, name, st in ctx.streams(("object_poses",)):
        rel = st.get("path")
        cams = sorted(
            {str(s.get("camera")) for s in ep.streams.values() if s.get("kind") == "camera"}
            | _box_cameras(ctx, ep)
        )
        if not isinstance(rel, str) or not cams:
            continue
        try:
            poses = _poses(ctx, rel)
        except InputReported:
            continue
        for obj, (t_p, v_p) in sorted(poses.items()):
            for camera in cams:
                try:
                    got = box_lag(ctx, ep, obj, camera, t_p, v_p)
                except (InputReported, RobogsError):
                    continue  # unreadable camera, boxes or labels: reported by their checks
                if got is None:
                    continue
                est, box_rel = got
                explains = est.rms_px[1] < (1.0 - _MIN_GAIN) * est.rms_px[0]
                if abs(est.pose_lag_ms) <= budget or abs(est.pose_lag_ms) <= 3 * est.stderr_ms:
                    continue
                if not explains:
                    continue  # the boxes are too coarse for the motion: no evidence either way
                when = "behind" if est.pose_lag_ms > 0 else "ahead of"
                cam_note = (
                    f"camera offset {est.camera_offset_ms:.3g} ms (T012) removed"
                    if est.camera_offset_ms is not None
                    else "camera offset unknown (no robot link labels), taken as 0"
                )
                yield chk.finding(
                    f"object {obj!r}: poses run {abs(est.pose_lag_ms):.3g} ms {when} the robot's "
                    f"clock as seen by camera {camera!r} (95 % interval {est.lo_ms:.4g} to "
                    f"{est.hi_ms:.4g} ms, {est.samples} boxes from {box_rel}; {cam_note}); "
                    f"removing it takes the box-centre rms from {est.rms_px[0]:.3g} to "
                    f"{est.rms_px[1]:.3g} px",
                    value=est.pose_lag_ms,
                    budget=budget,
                    file=rel,
                    episode=ep.id,
                    stream=name,
                )


def _box_cameras(ctx: CheckContext, ep) -> set[str]:
    out: set[str] = set()
    for name, st in ep.streams.items():
        if isinstance(st, dict) and st.get("kind") == "boxes2d" and isinstance(st.get("path"), str):
            try:
                tab = ctx.stream_table(ep, name, columns=("camera",))
            except InputReported:
                continue
            out |= set(tab.column("camera").unique().to_pylist())
    return out


# --------------------------------------------------------------------------- T016


@dataclass(frozen=True)
class ContactLag:
    """Lag of the wrench's contact onsets behind the object's motion onsets.

    Attributes:
        lag_ms: mean of ``t_force - t_motion`` over the pushes, ms (positive: wrench late).
        lo_ms, hi_ms: 95 % interval (Student's t over the pushes; one push: the sampling).
        stderr_ms: standard error, ms.
        pushes: force rises paired with a motion onset.
        lags_ms: the per-push lags, ms.
    """

    lag_ms: float
    lo_ms: float
    hi_ms: float
    stderr_ms: float
    pushes: int
    lags_ms: tuple[float, ...]


def _noise(x: np.ndarray) -> float:
    """Noise sigma of a series from its first differences (robust: MAD)."""
    d = np.diff(x, axis=0)
    return float(1.4826 * np.median(np.abs(d - np.median(d, axis=0))) / np.sqrt(2.0))


def _rises(t: np.ndarray, m: np.ndarray, hi: float) -> list[float]:
    """Times (ns) at which ``m`` leaves its floor on each rise above ``hi`` (held 3 samples,
    after 8 samples below it): the line through the two samples that bracket the level halfway
    between the floor (median of the 8 samples before) and the plateau (median of the 3 after),
    extrapolated back to the floor. Noise on the floor does not move it, unlike a threshold."""
    above = m > hi
    out = []
    k = 8
    while k < m.size - 3:
        if above[k] and not above[k - 1] and above[k : k + 3].all() and not above[k - 8 : k].any():
            floor = float(np.median(m[k - 8 : k - 1]))
            mid = 0.5 * (floor + float(np.median(m[k : k + 3])))
            i = k
            while i < k + 2 and m[i] <= mid:
                i += 1
            while i > k - 7 and m[i - 1] > mid:
                i -= 1
            slope = (m[i] - m[i - 1]) / float(t[i] - t[i - 1])
            if slope > 0:
                out.append(float(t[i - 1] - (m[i - 1] - floor) / slope))
            while k < m.size and above[k]:
                k += 1
        k += 1
    return out


def _motion_onset(t: np.ndarray, p: np.ndarray, t_force: float, sigma: float) -> float | None:
    """When the object starts to move near ``t_force`` (ns), or None.

    Its rest position is the median of the window's first half before ``t_force``; the first
    samples whose displacement along the motion exceeds the threshold (up to
    :data:`_ONSET_FIT_NS` later) are fitted by a line, extrapolated back to zero displacement.
    """
    w = (t >= t_force - _CONTACT_WINDOW_NS) & (t <= t_force + _CONTACT_WINDOW_NS)
    tw, pw = t[w], p[w]
    if tw.size < 8:
        return None
    thr = max(_MOVE_M, 6.0 * sigma)
    rest_sel = tw < t_force - 0.5 * _CONTACT_WINDOW_NS
    if rest_sel.sum() < 3:
        return None
    rest = np.median(pw[rest_sel], axis=0)
    d = np.linalg.norm(pw - rest, axis=1)
    if np.any(d[rest_sel] > thr):
        return None  # not at rest before the push
    over = np.flatnonzero(d > thr)
    if over.size == 0:
        return None
    a = over[0]
    fit = np.flatnonzero((tw >= tw[a]) & (tw <= tw[a] + _ONSET_FIT_NS))
    if fit.size < 2:
        fit = np.arange(a, min(a + 2, tw.size))
    if fit.size < 2:
        return None
    u = pw[fit[-1]] - rest
    u /= np.linalg.norm(u)
    along = (pw[fit] - rest) @ u  # displacement along the motion (noise across it ignored)
    tt = (tw[fit] - tw[a]).astype(np.float64)
    slope, icept = np.polyfit(tt, along, 1)
    if slope <= 0:
        return None
    return float(tw[a] - icept / slope)


def contact_lag(
    t_w: np.ndarray, f: np.ndarray, t_o: np.ndarray, p_o: np.ndarray
) -> ContactLag | None:
    """Lag of a wrench's force rises behind an object's motion onsets.

    Args:
        t_w: [N] int64 wrench stamps, ns (increasing); f: [N, 3] forces, N (any frame).
        t_o: [M] int64 object stamps, ns (increasing); p_o: [M, 3] positions, m.

    Returns:
        The lag, or None when the force never rises clearly out of its floor or no rise meets
        an object at rest that starts to move.
    """
    if t_w.size < 20 or t_o.size < 8:
        return None
    floor = np.median(f, axis=0)  # the sensor's offset (pushes last a minority of the time)
    m = np.linalg.norm(f - floor, axis=1)
    sig = _noise(m)
    top = float(np.percentile(m, 99))
    hi = max(8.0 * sig, 0.3 * top)
    if top < 2.0 * hi or not np.isfinite(hi):
        return None
    sig_p = _noise(p_o)
    lags = []
    for t_f in _rises(t_w, m, hi):
        t_m = _motion_onset(t_o, p_o, t_f, sig_p)
        if t_m is not None and abs(t_f - t_m) < 0.5 * _CONTACT_WINDOW_NS:
            lags.append((t_f - t_m) * 1e-6)
    if not lags:
        return None
    arr = np.array(lags)
    n = arr.size
    if n >= 3:
        se = float(arr.std(ddof=1) / np.sqrt(n))
        half = _t975(n - 1) * se
    else:  # the sampling bounds it: one period of each stream
        per = float(np.median(np.diff(t_w)) + np.median(np.diff(t_o))) * 1e-6
        se, half = per / np.sqrt(12.0), per
    lag = float(arr.mean())
    return ContactLag(lag, lag - half, lag + half, se, n, tuple(float(x) for x in arr))


def _wrench_series(ctx: CheckContext, rel: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    out = {}
    for name, (t, v) in entity_series(ctx, rel, "frame", ("fx", "fy", "fz")).items():
        if t.size >= 20 and np.all(np.diff(t) > 0) and np.all(np.isfinite(v)):
            out[name] = (t, v)
    return out


#: an ``actions`` stream's ``command_kind`` (the commanded quantity) -> how the pusher is controlled
_CONTROL = {"position": "position", "velocity": "position", "effort": "force"}


def control_mode(ep) -> tuple[str | None, str]:
    """How the robot pushes in an episode, from its ``actions`` stream's ``command_kind``:
    ``"position"`` (position or velocity commands: a stiff pusher that moves the object as the
    force rises), ``"force"`` (effort commands: the force builds up before the object breaks
    away), or None when no ``actions`` stream says; and the sentence that says where it was read.
    """
    kinds = sorted(
        {
            str(st.get("command_kind"))
            for st in ep.streams.values()
            if isinstance(st, dict) and st.get("kind") == "actions" and st.get("command_kind")
        }
    )
    modes = {_CONTROL[k] for k in kinds if k in _CONTROL}
    if len(modes) != 1:
        why = "mixed command kinds " + ", ".join(kinds) if modes else "no actions command_kind"
        return None, why
    return modes.pop(), "actions command_kind " + ", ".join(kinds)


@check(
    "T016",
    group="time",
    severity="error",
    title="wrench agrees in time with the contacts it measures",
    quantity="mean lag of the force rises behind the object's motion onsets",
    unit="ms",
    budget="time.sync_ms",
    hint="the force-torque stream is stamped off against the poses (a force cannot follow the "
    "motion it causes; under position control it rises as the object moves): correct its "
    "offset_ns by the lag",
)
def _wrench_contact_lag(chk: Check, ctx: CheckContext) -> Iterator[Finding]:
    budget = ctx.budget("time.sync_ms")
    for ep, name, st in ctx.streams(("wrenches",)):
        obj_stream = ctx.find_stream(ep, "object_poses")
        rel = st.get("path")
        if obj_stream is None or not isinstance(rel, str):
            continue
        try:
            wrenches = _wrench_series(ctx, rel)
            objects = _poses(ctx, ep.streams[obj_stream]["path"])
        except InputReported:
            continue
        mode, mode_why = control_mode(ep)
        for frame, (t_w, f) in sorted(wrenches.items()):
            best: tuple[str, ContactLag] | None = None
            for obj, (t_o, v_o) in sorted(objects.items()):
                est = contact_lag(t_w, f, t_o, v_o[:, :3])
                if est is not None and (best is None or est.pushes > best[1].pushes):
                    best = (obj, est)
            if best is None:
                continue
            obj, est = best
            if est.pushes < _MIN_PUSHES or abs(est.lag_ms) <= budget:
                continue
            if est.lo_ms <= 0.0 <= est.hi_ms or abs(est.lag_ms) <= 3.0 * est.stderr_ms:
                continue
            msg, severity = _contact_verdict(est, mode, mode_why)
            yield chk.finding(
                f"wrench {frame!r}: force rises run {abs(est.lag_ms):.3g} ms "
                f"{'behind' if est.lag_ms > 0 else 'ahead of'} the motion onsets of {obj!r} "
                f"(95 % interval {est.lo_ms:.4g} to {est.hi_ms:.4g} ms over {est.pushes} "
                f"pushes): {msg}",
                value=est.lag_ms,
                budget=budget,
                file=rel,
                episode=ep.id,
                stream=name,
                severity=severity,
            )


def _contact_verdict(est: ContactLag, mode: str | None, why: str) -> tuple[str, str | None]:
    """What a significant lag means under the control mode: the sentence and a severity
    (None: the check's, error)."""
    if est.lag_ms > 0:  # causality holds under any control
        return "a force cannot follow the motion it causes: the wrench is stamped late", None
    if mode == "position":
        return (
            f"position-controlled pushes ({why}) load and move the object at once: the wrench "
            "is stamped early",
            None,
        )
    if mode == "force":
        return (
            f"expected of force-controlled pushes ({why}): the force builds up to break the "
            "object away; a clock error within this lead cannot be told from it",
            "info",
        )
    return (
        f"the sign is ambiguous ({why}): a force-controlled push builds up before the object "
        "breaks away, while with position-controlled pushes the wrench is stamped early; "
        "record the actions stream's command_kind to decide",
        "info",
    )
