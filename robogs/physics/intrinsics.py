"""Camera intrinsics error, diagnosed from mask boundaries (sensor family, ``camera_intrinsics``).

A pinhole intrinsics error is an image-plane affine warp: a point the declared intrinsics
(fx, fy, cx, cy) put at (u, v) is seen by the true camera at

    u' = (u - cx) / (1 + dfx) + cx - dcx,    v' = (v - cy) / (1 + dfy) + cy - dcy,

with ``dfx = fx_declared / fx_true - 1`` (relative focal error, likewise ``dfy``) and
``dcx = cx_declared - cx_true`` [px] (likewise ``dcy``). So ONE render per frame at the declared
intrinsics suffices (:mod:`robogs.physics.masks`), and the fit is a 4-parameter warp
aligning the rendered label boundaries to the recorded ones: chamfer matching (Barrow et al.
1977; Borgefors 1988) by Gauss-Newton on the signed distance transform of every recorded label,
sampled at the warped boundary pixels of the same rendered label, with Huber weights (Huber
1964). One nuisance per kind of edge, a constant normal offset ``g``, absorbs the silhouette
growth of splats over their mesh; the base model (no intrinsics error) is those offsets alone.
With lens distortion the warp is exact for the pinhole part only.

What keeps the warp unbiased (each measured on synthetic scenes, ``bench/mask_intrinsics.py``):

* both boundaries are pixel-centre samplings, so at the right warp a boundary pixel's residual
  is one of two values a pixel apart, depending on the edge's sub-pixel phase; their mean is
  unbiased, their median is not. The Huber threshold is therefore at least one pixel
  (``_HUBER_MIN_PX``): with the usual 1.345 x robust scatter (0.05-0.4 px on such residuals)
  the fit was a median fit that pulled the warp to the pixel grid (a 1 % focal error between
  two mesh rasterisations came out 0.25 %);
* edges are used against the background, or between two labels whose rendered depths differ by
  more than ``_DEPTH_ORDER_REL`` (one occludes the other: its own silhouette). Contact edges (a
  box on the table, neighbouring links at a joint) have no certain depth order, the splats of
  both surfaces blend there and their offset varies along the edge; they biased dfy by -0.5 %
  and dcy by -0.2 px on every null scene. Occlusion edges are split by order (``"A>B"``: A in
  front, ``"A<B"``: B in front), since A's growth moves the edge outwards in one case and inwards
  in the other.

What remains is silhouette growth that varies along a label's edge (with the splats' projected
density and footprint: a table top seen at a grazing angle grows more at its far edge) and the
fixed quantisation of static edges; neither changes from frame to frame, so time blocks cannot
see them. The intervals therefore add a delete-a-label jackknife to the time-block one (see
:func:`_label_jackknife`).

Objects are rendered at their recorded poses and links by forward kinematics of the measured
joints: the fit looks at the camera chain, not at the physics model.

Diagnosis, in the style of :mod:`robogs.physics.diagnose` (one row per camera):

* ``delta_bic`` = ``n_eff ln(chi2_e / chi2_b) + k ln n_eff`` over the boundary pixels
  (winsorised at ``4 sigma``), with ``n_eff`` the number of boundary pixels over the design
  effect (Kish 1965): the jackknife variance of the warp over the variance it would have if the
  pixels were independent. Neighbouring pixels share an edge's quantisation and growth and
  frames repeat static labels (n_eff is 70-410 of 15 000-35 000 pixels on the synthetic
  scenes); with the raw pixel count null scenes reached ΔBIC = -2500;
* held-out error by contiguous time blocks of frames (``_N_FOLDS``), never random pixels: the
  warp and offsets are fitted on the other blocks and the boundary residual measured on the
  held-out one;
* 95 % intervals: the delete-a-block jackknife of the same fits (Kuensch 1989) and the
  delete-a-label jackknife, added in quadrature;
* effect size: how far the fitted warp moves the boundaries, RMS over the pixels of a frame
  (the largest over frames) in units of the boundary noise ``sigma`` (1.4826 MAD of the
  residuals of the fitted model, estimated from the data);
* a parameter that moves the boundaries by less than 0.05 px at its bound, or whose interval is
  wider than its bounds, is unidentifiable: fixed at 0, reported with an infinite interval;
* rivals, per part of the warp (focal: a scaling about the principal point; principal point: a
  shift): a camera rotation (pan/tilt) moves points by ``f (1 + x^2) dtheta``, nearly a
  principal-point shift; a camera translation shifts near points more than far ones. A rival is
  named when it reproduces a part's boundary change with cosine > 0.9.

Gate (all required): ``delta_bic <= -10``, held-out gain > ``HELDOUT_MIN_GAIN``, effect size
>= ``EFFECT_SIZE_MIN`` and at least one identifiable parameter. On null data (synthetic scenes
with the true intrinsics, seeds 0-7 at 160x120 and 0-3 at 320x240; ``bench/mask_intrinsics.py``)
ΔBIC stayed above +15, the held-out gain at most 0.021 and the effect size at most 0.42 sigma;
the thresholds (0.25, 1 sigma) sit above them, and a 1 % focal / 1 px principal point error is
still found (ΔBIC <= -84, gain >= 0.51, size >= 1.95 sigma).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from robogs.format.cameras import CameraModel
from robogs.physics.diagnose import DBIC_MAX, RIVAL_COSINE, EffectRow, ParamEstimate
from robogs.physics.effects import Effect, Param, register_effect
from robogs.physics.masks import MAX_FRAMES, RenderedFrame, mask_absent_reason

__all__ = [
    "NAME",
    "CameraIntrinsics",
    "IntrinsicsFit",
    "fit_warp",
    "contours_of",
    "analyse_contours",
    "fit_intrinsics",
    "diagnose_intrinsics",
    "corrected_camera",
    "HELDOUT_MIN_GAIN",
    "EFFECT_SIZE_MIN",
]

NAME = "camera_intrinsics"
HELDOUT_MIN_GAIN = 0.25
EFFECT_SIZE_MIN = 1.0
_N_FOLDS = 5
_MIN_PIXELS = 12
_HUBER = 1.345
#: smallest Huber threshold [px]: both boundaries are pixel-centre samplings, so at the right
#: warp a boundary pixel's residual takes one of two values a pixel apart (which one depends on
#: the edge's sub-pixel phase); only their mean is unbiased, so the loss must stay quadratic
#: over that pixel (a threshold of 1.345 x the robust scatter, often 0.05 px on such two-valued
#: residuals, is a median fit and drags the warp towards the grid: a 1 % focal error came out
#: 0.25 %)
_HUBER_MIN_PX = 1.0
#: an edge between two labels is used only where the rendered depths across it differ by more
#: than this fraction (the nearer label occludes the farther one); contact edges (a box on the
#: table, neighbouring links at a joint) have no certain depth order and their splats blend
_DEPTH_ORDER_REL = 0.03
_WINSOR = 4.0
#: parameter bounds: relative focal error, principal point shift as a fraction of the width
_BOUND_F = 0.3
_BOUND_C = 0.25
#: a parameter at its bound moving the boundaries by less than this (px RMS) is unidentifiable
_MIN_SENS_PX = 0.05

_SEPARATE_BY = (
    "a calibration target seen at several positions across the whole image and at several "
    "tilts, with the camera pose fitted per view (Zhang 2000): a pan/tilt moves points by "
    "f (1 + x^2) dtheta, more at the edges than a principal-point shift does, and a camera "
    "translation shifts near points more than far ones; fit a lens distortion model at the "
    "same time (radial distortion mimics a focal error away from the centre)"
)


@dataclass(frozen=True)
class CameraIntrinsics(Effect):
    """Error of the declared pinhole intrinsics, seen as an affine warp of the mask boundaries."""

    name: str = NAME
    family: str = "sensor"
    model: str = "camera"
    params: tuple[Param, ...] = (
        Param("dfx", "-", -_BOUND_F, _BOUND_F, 0.0, 0.02),
        Param("dfy", "-", -_BOUND_F, _BOUND_F, 0.0, 0.02),
        Param("dcx", "px", -1e4, 1e4, 0.0, 2.0),
        Param("dcy", "px", -1e4, 1e4, 0.0, 2.0),
    )
    needs: tuple[str, ...] = ("camera_masks",)
    separate_by: str = _SEPARATE_BY
    description: str = "declared focal lengths / principal point differ from the camera's"


register_effect(CameraIntrinsics(), replace=True)


# ----------------------------------------------------------------------------- contour data


@dataclass
class Contours:
    """Rendered boundary pixels and recorded signed distance maps of one camera.

    Points (arrays [P]): ``u, v`` pixel coordinates (centres at +0.5, recorded resolution),
    ``z`` rendered depth [m], ``crop`` index of the (frame, label) distance map, ``ch`` index
    of the edge kind in ``labels`` (``"A|none"``: A against the background, ``"A>B"``: A
    occludes B, ``"A<B"``: B occludes A; each kind of edge has its own offset, since splats grow
    over their mesh into what lies behind but are overlapped by an occluder's growth; ``involves``
    names the one or two labels of each kind), ``frame`` frame ordinal (time order). Crops:
    flattened signed distance [px] of each recorded label (negative inside, zero on the pixel
    edges of its boundary) and its gradient.
    """

    camera: CameraModel
    labels: list[str]
    involves: list[tuple[str, ...]]
    u: np.ndarray
    v: np.ndarray
    z: np.ndarray
    crop: np.ndarray
    ch: np.ndarray
    frame: np.ndarray
    sdf: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    off: np.ndarray
    w: np.ndarray
    h: np.ndarray
    x0: np.ndarray
    y0: np.ndarray
    n_frames: int

    def sample(self, uu: np.ndarray, vv: np.ndarray) -> tuple[np.ndarray, ...]:
        """Bilinear signed distance and gradient at (uu, vv) in each point's crop; valid mask."""
        x = uu - 0.5 - self.x0[self.crop]
        y = vv - 0.5 - self.y0[self.crop]
        w, h = self.w[self.crop], self.h[self.crop]
        ok = (x >= 0) & (y >= 0) & (x <= w - 1) & (y <= h - 1) & np.isfinite(x) & np.isfinite(y)
        xi = np.clip(np.floor(x), 0, np.maximum(w - 2, 0)).astype(np.int64)
        yi = np.clip(np.floor(y), 0, np.maximum(h - 2, 0)).astype(np.int64)
        fx_, fy_ = np.clip(x - xi, 0, 1), np.clip(y - yi, 0, 1)
        base = self.off[self.crop] + yi * w + xi
        out = []
        for a in (self.sdf, self.gx, self.gy):
            top = a[base] * (1 - fx_) + a[base + 1] * fx_
            bot = a[base + w] * (1 - fx_) + a[base + w + 1] * fx_
            out.append(top * (1 - fy_) + bot * fy_)
        return out[0], out[1], out[2], ok


_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def _signed_distance(mask: np.ndarray) -> np.ndarray:
    """Signed distance [px] to the edge of ``mask``: negative inside, 0 on pixel edges.

    Outside the image counts as far away (a mask cut by the image border has no edge there).
    """
    m = mask.astype(np.uint8)
    d_out = cv2.distanceTransform(1 - m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    d_in = cv2.distanceTransform(m, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.where(mask, 0.5 - d_in, d_out - 0.5).astype(np.float32)


def _neighbour(
    lab: np.ndarray, depth: np.ndarray, ys: np.ndarray, xs: np.ndarray, c: int
) -> tuple[np.ndarray, np.ndarray]:
    """Label across the edge at boundary pixels (ys, xs) of label ``c`` (first 4-neighbour that
    is not ``c``; ``c`` itself where none is, e.g. at the image border) and its rendered depth
    there [m] (0 for none)."""
    H, W = lab.shape
    out = np.full(ys.size, c, lab.dtype)
    z = np.zeros(ys.size)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        yy, xx = np.clip(ys + dy, 0, H - 1), np.clip(xs + dx, 0, W - 1)
        n = lab[yy, xx]
        take = (out == c) & (n != c)
        out[take] = n[take]
        z[take] = depth[yy, xx][take]
    return out, z


def _edge_kinds(
    fr: RenderedFrame, c: int, ys: np.ndarray, xs: np.ndarray
) -> tuple[np.ndarray, list[str]]:
    """Which boundary pixels of label ``c`` to use, and the kind of edge at each.

    Kinds: ``"A|none"`` (against unlabelled background), ``"A>B"`` (A occludes B: A's own
    silhouette) and ``"A<B"`` (B occludes A: B's silhouette). Edges between two labels whose
    rendered depths differ by less than ``_DEPTH_ORDER_REL`` are left out (contact edges).
    """
    other, z_o = _neighbour(fr.rendered, fr.depth, ys, xs, c)
    z_c = fr.depth[ys, xs]
    rel = (z_o - z_c) / np.maximum(z_c, 1e-9)
    fg = (other != 0) & (z_c > 0) & (z_o > 0)
    front = fg & (rel > _DEPTH_ORDER_REL)
    behind = fg & (rel < -_DEPTH_ORDER_REL)
    keep = (other == 0) | front | behind
    name = fr.names[c - 1]
    kinds = [
        f"{name}|none" if o == 0 else f"{name}{'>' if f else '<'}{fr.names[o - 1]}"
        for o, f in zip(other[keep], front[keep], strict=True)
    ]
    return keep, kinds


def contours_of(frames: Iterable[RenderedFrame]) -> Contours | None:
    """Collect boundary pixels and distance maps of the frames of ONE camera (None if empty)."""
    pts: dict[str, list[np.ndarray]] = {k: [] for k in ("u", "v", "z", "crop", "ch", "frame")}
    maps: list[tuple[np.ndarray, np.ndarray, np.ndarray, int, int]] = []
    labels: list[str] = []
    index: dict[str, int] = {}
    involves: list[tuple[str, ...]] = []
    camera = None
    n_frames = 0
    for f_i, fr in enumerate(frames):
        camera = fr.camera
        n_frames = f_i + 1
        H, W = fr.recorded.shape
        margin = max(8, int(round(0.06 * W)))
        for c, name in enumerate(fr.names, start=1):
            rec = fr.recorded == c
            ren = fr.rendered == c
            if rec.sum() < _MIN_PIXELS or ren.sum() < _MIN_PIXELS:
                continue
            edge = ren & ~cv2.erode(ren.astype(np.uint8), _CROSS).astype(bool)
            edge[:1] = edge[-1:] = False
            edge[:, :1] = edge[:, -1:] = False
            ys, xs = np.nonzero(edge)
            if xs.size == 0:
                continue
            keep, pair = _edge_kinds(fr, c, ys, xs)
            ys, xs = ys[keep], xs[keep]
            if xs.size == 0:
                continue
            both = rec | ren
            rows, cols = np.flatnonzero(both.any(1)), np.flatnonzero(both.any(0))
            r0, r1 = max(rows[0] - margin, 0), min(rows[-1] + margin + 1, H)
            c0, c1 = max(cols[0] - margin, 0), min(cols[-1] + margin + 1, W)
            sdf = _signed_distance(rec[r0:r1, c0:c1])
            gy, gx = np.gradient(sdf)
            maps.append((sdf, gx.astype(np.float32), gy.astype(np.float32), c0, r0))
            z = fr.depth[ys, xs]
            pts["u"].append(xs + 0.5)
            pts["v"].append(ys + 0.5)
            pts["z"].append(z)
            pts["crop"].append(np.full(xs.size, len(maps) - 1))
            for nm in dict.fromkeys(pair):
                if nm not in index:
                    index[nm] = len(labels)
                    labels.append(nm)
                    across = nm[len(name) + 1 :]
                    involves.append((name,) if across == "none" else (name, across))
            pts["ch"].append(np.array([index[nm] for nm in pair], np.int64))
            pts["frame"].append(np.full(xs.size, f_i))
    if not maps or camera is None:
        return None
    sizes = np.array([m[0].size for m in maps])
    z = np.concatenate(pts["z"]).astype(np.float64)
    z = np.where(z > 0, z, np.median(z[z > 0]) if (z > 0).any() else 1.0)
    return Contours(
        camera=camera,
        labels=labels,
        involves=involves,
        u=np.concatenate(pts["u"]).astype(np.float64),
        v=np.concatenate(pts["v"]).astype(np.float64),
        z=z,
        crop=np.concatenate(pts["crop"]),
        ch=np.concatenate(pts["ch"]),
        frame=np.concatenate(pts["frame"]),
        sdf=np.concatenate([m[0].ravel() for m in maps]).astype(np.float64),
        gx=np.concatenate([m[1].ravel() for m in maps]).astype(np.float64),
        gy=np.concatenate([m[2].ravel() for m in maps]).astype(np.float64),
        off=np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64),
        w=np.array([m[0].shape[1] for m in maps], np.int64),
        h=np.array([m[0].shape[0] for m in maps], np.int64),
        x0=np.array([m[3] for m in maps], np.int64),
        y0=np.array([m[4] for m in maps], np.int64),
        n_frames=n_frames,
    )


# ----------------------------------------------------------------------------- warp fit


@dataclass
class WarpFit:
    """A warp fit: ``a`` = (ax, ay, bx, by) with ``u' = cx + (1 + ax)(u - cx) + bx``, label
    offsets ``g`` [px], residuals at every point [px] (NaN where the warped point left its map)."""

    a: np.ndarray
    g: np.ndarray
    r: np.ndarray

    def reported(self) -> np.ndarray:
        """(dfx, dfy, dcx, dcy) of this warp."""
        ax, ay, bx, by = self.a
        return np.array([1.0 / (1.0 + ax) - 1.0, 1.0 / (1.0 + ay) - 1.0, -bx, -by])


def _residuals(ct: Contours, a: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, ...]:
    cam = ct.camera
    du, dv = ct.u - cam.cx, ct.v - cam.cy
    uu = cam.cx + (1 + a[0]) * du + a[2]
    vv = cam.cy + (1 + a[1]) * dv + a[3]
    s, gx, gy, ok = ct.sample(uu, vv)
    r = np.where(ok, s - g[ct.ch], np.nan)
    J = np.stack([gx * du, gy * dv, gx, gy], 1)
    return r, J, ok


def _normal_equations(
    ct: Contours, a: np.ndarray, g: np.ndarray, fcols: np.ndarray, sel: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Huber-weighted normal equations of the warp columns ``fcols`` (in px of boundary motion
    at the image edge) and the offsets at (a, g); also the weighted residual variance [px^2]."""
    n_ch, k = len(ct.labels), len(fcols)
    r, J, ok = _residuals(ct, a, g)
    use = sel & ok
    if use.sum() < 10:
        return None
    rr, ch = r[use], ct.ch[use]
    sigma = 1.4826 * float(np.median(np.abs(rr - np.median(rr))))
    wts = np.minimum(1.0, max(_HUBER * sigma, _HUBER_MIN_PX) / np.maximum(np.abs(rr), 1e-12))
    Jf = J[use][:, fcols] / _edge_scale(ct)[fcols]
    # normal equations of [Jf, -onehot(ch)]: the offset block is diagonal (bincount)
    N = np.zeros((k + n_ch, k + n_ch))
    N[:k, :k] = (Jf * wts[:, None]).T @ Jf
    for j in range(k):
        N[:k, k:][j] = -np.bincount(ch, wts * Jf[:, j], n_ch)
    N[k:, :k] = N[:k, k:].T
    N[k:, k:] = np.diag(np.bincount(ch, wts, n_ch))
    rhs = np.concatenate([(Jf * wts[:, None]).T @ rr, -np.bincount(ch, wts * rr, n_ch)])
    N += np.eye(k + n_ch) * 1e-9 * max(np.trace(N), 1.0)
    var = float(np.sum(wts * rr**2) / max(float(wts.sum()) - k - n_ch, 1.0))
    return N, rhs, var


def _edge_scale(ct: Contours) -> np.ndarray:
    """[4] px of boundary motion at the image edge per unit of (ax, ay, bx, by)."""
    return np.array([ct.camera.width / 2, ct.camera.height / 2, 1.0, 1.0])


def fit_warp(
    ct: Contours, free: np.ndarray, sel: np.ndarray | None = None, *, iters: int = 25
) -> WarpFit:
    """Huber-weighted Gauss-Newton fit of the warp parameters marked ``free`` and the offsets.

    The Huber threshold is at least ``_HUBER_MIN_PX`` (see there: the residuals of pixel-sampled
    boundaries are two-valued, and only their mean is unbiased).

    Args:
        ct: contour data.
        free: [4] bool, which of (ax, ay, bx, by) are fitted (the others stay 0).
        sel: [P] bool, points used (default all); residuals are returned for every point.
    """
    sel = np.ones(ct.u.size, bool) if sel is None else sel
    a = np.zeros(4)
    g = np.zeros(len(ct.labels))
    fcols = np.flatnonzero(free)
    k = len(fcols)
    scale = _edge_scale(ct)[fcols]
    lim = np.array([0.05, 0.05, 4.0, 4.0])[fcols]
    for _ in range(iters):
        ne = _normal_equations(ct, a, g, fcols, sel)
        if ne is None:
            break
        try:
            step = -np.linalg.solve(ne[0], ne[1])
        except np.linalg.LinAlgError:
            break
        # keep each step within a few px at the image edge (the distance maps are local)
        da = np.clip(step[:k] / scale, -lim, lim)
        a[fcols] += da
        a[:2] = np.clip(a[:2], -_BOUND_F, _BOUND_F)
        g += step[k:]
        if np.all(np.abs(da * scale) < 1e-3) and np.all(np.abs(step[k:]) < 1e-3):
            break
    r, _, _ = _residuals(ct, a, g)
    return WarpFit(a.copy(), g.copy(), r)


def _naive_variance(ct: Contours, fit: WarpFit, free: np.ndarray) -> np.ndarray:
    """[4] variance of the reported (dfx, dfy, dcx, dcy) if every boundary pixel were an
    independent sample (inf for fixed parameters)."""
    fcols = np.flatnonzero(free)
    out = np.full(4, np.inf)
    ne = _normal_equations(ct, fit.a, fit.g, fcols, np.ones(ct.u.size, bool))
    if ne is None or fcols.size == 0:
        return out
    try:
        cov = np.linalg.inv(ne[0])[: fcols.size, : fcols.size] * ne[2]
    except np.linalg.LinAlgError:
        return out
    var_a = np.diag(cov) / _edge_scale(ct)[fcols] ** 2
    # d(dfx)/d(ax) = -1 / (1 + ax)^2; d(dcx)/d(bx) = -1
    d = np.where(fcols < 2, 1.0 / (1.0 + fit.a[np.minimum(fcols, 1)]) ** 2, 1.0)
    out[fcols] = var_a * d**2
    return out


def _winsor(r: np.ndarray, c: float) -> np.ndarray:
    return np.where(np.isfinite(r), np.clip(r, -c, c), c)


@dataclass
class IntrinsicsFit:
    """The intrinsics diagnosis of one camera.

    Attributes:
        camera: the declared camera model.
        row: the diagnosis row (``robogs diagnose``).
        values: fitted (dfx, dfy, dcx, dcy) with unidentifiable ones at 0.
        identifiable: [4] bool.
        boundary_px_before / after: mean |residual| of the boundary pixels (declared intrinsics
            / corrected), px, offsets removed.
        sigma_px: boundary noise estimated from the data, px.
    """

    camera: CameraModel
    row: EffectRow
    values: np.ndarray
    identifiable: np.ndarray
    boundary_px_before: float
    boundary_px_after: float
    sigma_px: float
    extra: dict[str, Any] = field(default_factory=dict)


def corrected_camera(fit: IntrinsicsFit) -> CameraModel:
    """The camera with the identifiable intrinsics corrected."""
    cam = fit.camera
    dfx, dfy, dcx, dcy = np.where(fit.identifiable, fit.values, 0.0)
    return replace(
        cam,
        fx=float(cam.fx / (1 + dfx)),
        fy=float(cam.fy / (1 + dfy)),
        cx=float(cam.cx - dcx),
        cy=float(cam.cy - dcy),
    )


def _cosine_to_span(d: np.ndarray, cols: np.ndarray) -> float:
    """Cosine between ``d`` and its least-squares projection on the columns of ``cols``."""
    nd = float(np.linalg.norm(d))
    if nd == 0 or cols.size == 0:
        return 0.0
    coef, *_ = np.linalg.lstsq(cols, d, rcond=None)
    p = cols @ coef
    return float(p @ d / (nd * max(float(np.linalg.norm(p)), 1e-300)))


def _jackknife_sd(jack: list[np.ndarray]) -> np.ndarray:
    """Delete-a-group jackknife standard deviation [4] of the reported parameters."""
    jk = np.array(jack)
    m = len(jack)
    return np.sqrt((m - 1) / m * np.sum((jk - jk.mean(0)) ** 2, 0))


def _held_out(
    ct: Contours, free: np.ndarray, clip: float, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Held-out residuals [P] of the base and effect models over ``k`` contiguous time blocks of
    frames (each block fitted on the others, winsorised at ``clip``), and the delete-a-block
    jackknife standard deviation [4] of (dfx, dfy, dcx, dcy) from the same fits (Kuensch 1989;
    inf with fewer than 2 blocks)."""
    held_b = np.zeros(ct.u.size)
    held_e = np.zeros(ct.u.size)
    if k < 2:
        return held_b, held_e, np.full(4, np.inf)
    jack = []
    for blk in np.array_split(np.arange(ct.n_frames), k):
        test = np.isin(ct.frame, blk)
        fb = fit_warp(ct, np.zeros(4, bool), ~test)
        fe = fit_warp(ct, free, ~test)
        held_b[test] = _winsor(fb.r, clip)[test]
        held_e[test] = _winsor(fe.r, clip)[test]
        jack.append(fe.reported())
    return held_b, held_e, _jackknife_sd(jack)


def _label_jackknife(ct: Contours, free: np.ndarray) -> tuple[np.ndarray, int]:
    """Delete-a-label jackknife standard deviation [4] of (dfx, dfy, dcx, dcy), and the number
    of labels (0 with fewer than 2: no spread can be measured).

    The offsets model each kind of edge by one constant; what they miss (silhouette growth that
    varies along a label's edge with the splats' density and footprint, the fixed quantisation
    of a static label's edges) belongs to a label and stays the same in every frame, so the
    time blocks cannot see it. Deleting one label at a time (every edge kind it takes part in)
    measures how much the warp rests on any one label's edges: labels are the clusters of a
    second, crossed jackknife (two-way clustering, Cameron, Gelbach & Miller 2011).
    """
    names = sorted({n for inv in ct.involves for n in inv})
    if len(names) < 2:
        return np.zeros(4), 0
    jack = []
    kinds = np.arange(len(ct.labels))
    for name in names:
        drop = np.array([name in inv for inv in ct.involves])
        sel = ~np.isin(ct.ch, kinds[drop])
        if sel.sum() < _MIN_PIXELS:
            continue
        jack.append(fit_warp(ct, free, sel).reported())
    if len(jack) < 2:
        return np.zeros(4), 0
    return _jackknife_sd(jack), len(jack)


def _half_width(sd_t: np.ndarray, k: int, sd_l: np.ndarray, n_lab: int) -> np.ndarray:
    """95 % half-widths [4] from the time-block (``k`` blocks) and label (``n_lab`` labels)
    jackknives, added in quadrature (inf with fewer than 2 time blocks)."""
    from scipy.stats import t as student_t

    if k < 2:
        return np.full(4, np.inf)
    ht = float(student_t.ppf(0.975, k - 1)) * sd_t
    hl = float(student_t.ppf(0.975, n_lab - 1)) * sd_l if n_lab >= 2 else np.zeros(4)
    return np.sqrt(ht**2 + hl**2)


def analyse_contours(ct: Contours) -> IntrinsicsFit:
    """Fit and judge the warp of one camera's contours (the module docstring says how)."""
    cam = ct.camera
    n_pts = ct.u.size
    base = fit_warp(ct, np.zeros(4, bool))
    # identifiability: sensitivity at the bounds, then the block jackknife below
    _, J, _ = _residuals(ct, np.zeros(4), base.g)
    bound = np.array([_BOUND_F, _BOUND_F, _BOUND_C * cam.width, _BOUND_C * cam.height])
    sens = np.sqrt(np.mean(J**2, 0)) * bound
    free = sens >= _MIN_SENS_PX
    eff = fit_warp(ct, free)
    # boundary noise: robust scatter of the residuals of the better model (the base model's
    # would count an intrinsics error as noise)
    re = eff.r[np.isfinite(eff.r)]
    sigma = max(1.4826 * float(np.median(np.abs(re - np.median(re)))), 1e-3)
    clip = _WINSOR * sigma
    k = min(_N_FOLDS, ct.n_frames)
    held_b, held_e, sd_t = _held_out(ct, free, clip, k)
    sd_l, n_lab = _label_jackknife(ct, free)
    half = _half_width(sd_t, k, sd_l, n_lab)
    ident = free & np.isfinite(half) & (half < bound)
    if not np.array_equal(ident, free):
        eff = fit_warp(ct, ident)
        held_b, held_e, sd_t = _held_out(ct, ident, clip, k)
        sd_l, n_lab = _label_jackknife(ct, ident)
        half = _half_width(sd_t, k, sd_l, n_lab)
    values = np.where(ident, eff.reported(), 0.0)
    chi_b = float(np.sum(_winsor(base.r, clip) ** 2))
    chi_e = float(np.sum(_winsor(eff.r, clip) ** 2))
    k_extra = int(ident.sum())
    # effective number of independent boundary pixels: n over the design effect (Kish 1965),
    # the jackknife variance of the warp over the variance it would have if every pixel were
    # an independent sample (neighbouring pixels of an edge share its quantisation and growth,
    # and frames repeat the static labels)
    var_naive = _naive_variance(ct, eff, ident)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (sd_t**2 + sd_l**2) / var_naive
    ratio = ratio[ident & np.isfinite(ratio)]
    deff = max(float(np.median(ratio)), 1.0) if ratio.size else 1.0
    n = max(n_pts / deff, float(k_extra + 1))
    dbic = float(n * np.log(max(chi_e, 1e-300) / max(chi_b, 1e-300)) + k_extra * np.log(n))
    hb, he = float(np.sum(held_b**2)), float(np.sum(held_e**2))
    gain = 1.0 - he / hb if k >= 2 and hb > 0 else 0.0
    # the effect's change of the predicted boundaries: the warp's displacement along the
    # recorded edge normals, less the change of the edge offsets (linear in the warp)
    _, Jg, ok_e = _residuals(ct, eff.a, eff.g)
    gx, gy = Jg[:, 2], Jg[:, 3]
    disp_u = eff.a[0] * (ct.u - cam.cx) + eff.a[2]
    disp_v = eff.a[1] * (ct.v - cam.cy) + eff.a[3]
    delta = np.where(ok_e, gx * disp_u + gy * disp_v - (eff.g - base.g)[ct.ch], np.nan)
    per_frame = [
        float(np.sqrt(np.nanmean(delta[ct.frame == f] ** 2)))
        for f in range(ct.n_frames)
        if np.isfinite(delta[ct.frame == f]).any()
    ]
    size = max(per_frame, default=0.0) / sigma
    size_total = float(np.sqrt(np.nanmean(delta**2))) / sigma
    # rivals: a camera rotation (pan/tilt) or translation reproducing the boundary change
    x, y = (ct.u - cam.cx) / cam.fx, (ct.v - cam.cy) / cam.fy
    onehot = np.zeros((n_pts, len(ct.labels)))
    onehot[np.arange(n_pts), ct.ch] = 1.0
    rival_cols = {
        "camera pan/tilt": [
            gx * cam.fx * (1 + x * x) + gy * cam.fy * x * y,
            gx * cam.fx * x * y + gy * cam.fy * (1 + y * y),
        ],
        "camera translation": [gx * cam.fx / ct.z, gy * cam.fy / ct.z],
    }
    # per part of the warp: the focal part (scaling about the principal point) and the
    # principal-point part (a shift) have different look-alikes
    parts = {
        "focal (dfx, dfy)": gx * eff.a[0] * (ct.u - cam.cx) + gy * eff.a[1] * (ct.v - cam.cy),
        "principal point (dcx, dcy)": gx * eff.a[2] + gy * eff.a[3],
    }
    rivals: list[str] = []
    cosines: dict[str, dict[str, float]] = {}
    look_alike: dict[str, list[str]] = {}
    for part, d in parts.items():
        fin = ok_e & np.isfinite(d)
        cosines[part] = {}
        moves = float(np.sqrt(np.mean(d[fin] ** 2))) >= 0.5 * EFFECT_SIZE_MIN * sigma
        for rival, cols in rival_cols.items():
            cos = _cosine_to_span(d[fin], np.column_stack([*cols, onehot])[fin])
            cosines[part][rival] = cos
            if moves and cos > RIVAL_COSINE:
                look_alike.setdefault(part, []).append(rival)
                if rival not in rivals:
                    rivals.append(rival)
    names = ("dfx", "dfy", "dcx", "dcy")
    units = ("-", "-", "px", "px")
    params = [
        ParamEstimate(
            f"{cam.name}.{nm}",
            float(values[j]),
            float(values[j] - half[j]) if ident[j] else float("-inf"),
            float(values[j] + half[j]) if ident[j] else float("inf"),
            units[j],
        )
        for j, nm in enumerate(names)
    ]
    gate = dbic <= DBIC_MAX and gain > HELDOUT_MIN_GAIN and size >= EFFECT_SIZE_MIN and ident.any()
    if not ident.any():
        verdict = "unidentifiable"
    elif gate:
        verdict = "add"
    elif dbic <= -6 and size >= 0.5 * EFFECT_SIZE_MIN:
        verdict = "likely"
    else:
        verdict = "not supported"
    notes = [f"camera {cam.name}; errors in px of mask boundary (noise {sigma:.3g} px)"]
    bad = [names[j] for j in range(4) if not ident[j]]
    if bad:
        notes.append(f"unidentifiable: {', '.join(bad)}; to identify: {_SEPARATE_BY}")
    for part, who in look_alike.items():
        notes.append(f"{part} hard to tell from {' or '.join(who)} with this data")
    if look_alike:
        notes.append(f"to separate them: {_SEPARATE_BY}")
    rms = lambda r: float(np.sqrt(np.mean(r**2)))  # noqa: E731
    row = EffectRow(
        name=NAME,
        family="sensor",
        reported=bool(gate),
        verdict=verdict,
        delta_bic=dbic,
        heldout_rms_before=rms(held_b) if k >= 2 else float("nan"),
        heldout_rms_after=rms(held_e) if k >= 2 else float("nan"),
        heldout_gain=float(gain),
        heldout_dchi2=float((hb - he) / sigma**2),
        effect_size=float(size),
        effect_size_total=float(size_total),
        explained=float(np.clip(1.0 - chi_e / chi_b, 0.0, 1.0)) if chi_b > 0 else 0.0,
        rms_after=rms(_winsor(eff.r, clip)),
        params=params,
        rivals=rivals,
        separate_by=_SEPARATE_BY,
        note="; ".join(notes),
        unit="px",
    )
    mean_abs = lambda r: float(np.mean(np.abs(_winsor(r, clip))))  # noqa: E731
    return IntrinsicsFit(
        camera=cam,
        row=row,
        values=values,
        identifiable=ident,
        boundary_px_before=mean_abs(base.r),
        boundary_px_after=mean_abs(eff.r),
        sigma_px=sigma,
        extra={
            "rival_cosines": cosines,
            "n_points": n_pts,
            "n_effective": n,
            "frames": ct.n_frames,
            "sd_time_blocks": sd_t.tolist(),
            "sd_labels": sd_l.tolist(),
        },
    )


def fit_intrinsics(ds: Any, *, max_frames: int = MAX_FRAMES) -> list[IntrinsicsFit]:
    """Render every labelled camera once per compared frame and fit its intrinsics error.

    Raises:
        InputError: the dataset has no usable masks (the message says why).
    """
    from robogs.format.errors import InputError
    from robogs.physics.masks import rendered_frames

    why = mask_absent_reason(ds)
    if why is not None:
        raise InputError(f"{NAME} needs camera masks: {why}", path=getattr(ds, "root", None))
    by_cam: dict[str, list[RenderedFrame]] = {}
    for fr in rendered_frames(ds, max_frames=max_frames):
        by_cam.setdefault(fr.camera.name, []).append(fr)
    out = []
    for frames in by_cam.values():
        ct = contours_of(frames)
        if ct is not None:
            out.append(analyse_contours(ct))
    if not out:
        raise InputError(
            f"{NAME}: no frame has a label seen both in the masks and in the re-render",
            path=getattr(ds, "root", None),
        )
    return out


def diagnose_intrinsics(
    ds: Any, *, max_frames: int = MAX_FRAMES
) -> tuple[list[IntrinsicsFit], str | None]:
    """The ``camera_intrinsics`` rows of ``robogs diagnose``, or ``([], reason)`` when skipped."""
    from robogs.format.errors import RobogsError

    why = mask_absent_reason(ds)
    if why is not None:
        return [], f"needs camera masks and a binding ({why})"
    try:
        return fit_intrinsics(ds, max_frames=max_frames), None
    except RobogsError as exc:
        return [], exc.message
