"""Fused projection for the ``triton`` backend: one Triton program per block of Gaussians,
forward and a hand-derived backward (CUDA; the CPU interpreter in tests).

The pure-torch :func:`~.projection.project` launches a few hundred small kernels per render and
as many again in its autograd backward; on a GPU the training step is then bound by the CPU
issuing them (issue 23, ``bench/RESULTS.md``). Here every per-Gaussian quantity that the
compositor and ``finish_output`` read is computed by one kernel, elementwise over Gaussians.
3DGS:

- ``p = R_cw m + t``, ``means2d = (fx p0 / z + cx, fy p1 / z + cy)`` (z = 1 outside near/far);
- EWA splatting (Zwicker et al. 2001, as in Kerbl et al. 2023): ``Sigma2 = J R_c S S R_c^T J^T``
  with the Jacobian's tx/tz, ty/tz clamped to the widened field of view (gsplat's asymmetric
  form), plus the 0.3 px^2 low-pass scaled by ``lowpass_scale``; the conic is its inverse
  (A, B, C); ``antialiased`` adds Mip-Splatting's opacity compensation
  ``0.5 ln(det(Sigma2 - lowpass) / det(Sigma2))`` (Yu et al. 2024);
- ``ln o = logsigmoid(logit)``, ``exp_min``, the support box and the culling of ``project``;
- normals (shortest axis of the Gaussian in the camera frame, facing the camera);
- colour from real SH up to degree 3 with the 3DGS signs (``sh.py``), direction from the camera
  centre to the mean.

2DGS (Huang et al. 2024): the ray-transform rows ``Px = Tv x Tw, Py = Tw x Tu, Pa = Tu x Tv, Tw``
of ``Tm = K [R_c s_u t_u, R_c s_v t_v, p]``, the surfel box from the dual conic joined with the
low-pass circle (unbounded disks get the screen), normals = third axis facing the camera; means2d,
depth, ln o, exp_min, culling and colour as for 3DGS.

The backward kernel recomputes these and applies the chain rule by hand: conic -> 2D
covariance -> (J, R_c S) -> (camera-frame mean, quaternion, log-scales), or for 2DGS the ray rows -> (cross products)
Tm -> (K^T) the scaled axes and the camera-frame mean; means2d and depth -> camera-frame mean;
SH colour -> coefficients and (through the view direction) the mean; normals -> quaternion.
Gradients with respect to the camera pose are not computed: a caller
needing them (``T_world_cam.requires_grad``) must use :func:`~.projection.project`, which
``render_triton`` does.

Arithmetic is float32, as in the compositor. Constants are the shared ones of ``constants.py``
and ``sh.py``, passed to the kernels as compile-time values (Triton reads no other globals).
"""

from __future__ import annotations

import math

import torch
import triton
import triton.language as tl

from . import sh as _sh
from .camera import Camera
from .config import RenderConfig
from .constants import (
    ALPHA_THRESHOLD,
    FOV_CLAMP_MARGIN,
    LOG_ALPHA_THRESHOLD,
    LOWPASS_3DGS_PX2,
    MAX_EXPONENT,
)
from .gaussians import Gaussians
from .projection import Projected, lowpass_inv_sq
from .sh import sh_degree_of

__all__ = ["project_fused", "fused_projection_supports"]

#: Gaussians per program and warps (8 x 32 threads: one Gaussian per thread; ptxas -v for sm_90:
#: forward 40-48 registers, backward 64-128, no spills, 3DGS and 2DGS)
_BLOCK = 256
_WARPS = 8
#: compile-time copies of the shared constants (kernels may read only constexpr globals)
_LOG_ALPHA_T = tl.constexpr(LOG_ALPHA_THRESHOLD)
_MAX_EXP = tl.constexpr(MAX_EXPONENT)
_VIS_LOG_O = tl.constexpr(math.log(ALPHA_THRESHOLD))
_C0 = tl.constexpr(_sh.SH_C0)
_C1 = tl.constexpr(_sh._C1)
_C20 = tl.constexpr(_sh._C2[0])
_C21 = tl.constexpr(_sh._C2[1])
_C22 = tl.constexpr(_sh._C2[2])
_C23 = tl.constexpr(_sh._C2[3])
_C24 = tl.constexpr(_sh._C2[4])
_C30 = tl.constexpr(_sh._C3[0])
_C31 = tl.constexpr(_sh._C3[1])
_C32 = tl.constexpr(_sh._C3[2])
_C33 = tl.constexpr(_sh._C3[3])
_C34 = tl.constexpr(_sh._C3[4])
_C35 = tl.constexpr(_sh._C3[5])
_C36 = tl.constexpr(_sh._C3[6])
_NORM_FLOOR = tl.constexpr(1e-12)
_DET_FLOOR = tl.constexpr(1e-30)


def fused_projection_supports(gaussians: Gaussians, camera: Camera, config: RenderConfig) -> bool:
    """Whether :func:`project_fused` covers this render (3DGS or 2DGS, no camera-pose gradient)."""
    if (config.kind, gaussians.log_scales.shape[1]) not in (("3dgs", 3), ("2dgs", 2)):
        return False
    if camera.T_world_cam.requires_grad and torch.is_grad_enabled():
        return False
    return sh_degree_of(gaussians.sh.shape[1]) is not None


@triton.jit
def _sh_basis(x, y, z, DEG: tl.constexpr):
    """The 16 real SH basis values (3DGS signs); bands above ``DEG`` are 0."""
    zero = 0.0 * x
    b0 = zero + _C0
    b1 = zero
    b2 = zero
    b3 = zero
    b4 = zero
    b5 = zero
    b6 = zero
    b7 = zero
    b8 = zero
    b9 = zero
    b10 = zero
    b11 = zero
    b12 = zero
    b13 = zero
    b14 = zero
    b15 = zero
    if DEG >= 1:
        b1 = -_C1 * y
        b2 = _C1 * z
        b3 = -_C1 * x
    if DEG >= 2:
        xx = x * x
        yy = y * y
        zz = z * z
        b4 = _C20 * x * y
        b5 = _C21 * y * z
        b6 = _C22 * (2.0 * zz - xx - yy)
        b7 = _C23 * x * z
        b8 = _C24 * (xx - yy)
        if DEG >= 3:
            b9 = _C30 * y * (3.0 * xx - yy)
            b10 = _C31 * x * y * z
            b11 = _C32 * y * (4.0 * zz - xx - yy)
            b12 = _C33 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy)
            b13 = _C34 * x * (4.0 * zz - xx - yy)
            b14 = _C35 * z * (xx - yy)
            b15 = _C36 * x * (xx - 3.0 * yy)
    return b0, b1, b2, b3, b4, b5, b6, b7, b8, b9, b10, b11, b12, b13, b14, b15


@triton.jit
def _sh_channel(sh_ptr, i, mask, c: tl.constexpr, basis, KS: tl.constexpr, NB: tl.constexpr):
    """sum_k basis_k sh[i, k, c] over the first NB coefficients."""
    acc = 0.0 * basis[0]
    for k in tl.static_range(NB):
        acc += basis[k] * tl.load(sh_ptr + i * (KS * 3) + k * 3 + c, mask=mask, other=0.0)
    return acc


@triton.jit
def _core(
    m_ptr, q_ptr, s_ptr, cam_ptr, i, mask,
    fx, fy, near, far, xn, xp, yn, yp, lowpass, NS: tl.constexpr,
):  # fmt: skip
    """Geometry shared by the kernels: camera-frame mean, rotation, scales (NS of them; the
    third is 1 for surfels) and the EWA covariance (unused, and compiled away, for surfels)."""
    mx = tl.load(m_ptr + i * 3 + 0, mask=mask, other=0.0)
    my = tl.load(m_ptr + i * 3 + 1, mask=mask, other=0.0)
    mz = tl.load(m_ptr + i * 3 + 2, mask=mask, other=1.0)
    w00 = tl.load(cam_ptr + 0)
    w01 = tl.load(cam_ptr + 1)
    w02 = tl.load(cam_ptr + 2)
    w10 = tl.load(cam_ptr + 3)
    w11 = tl.load(cam_ptr + 4)
    w12 = tl.load(cam_ptr + 5)
    w20 = tl.load(cam_ptr + 6)
    w21 = tl.load(cam_ptr + 7)
    w22 = tl.load(cam_ptr + 8)
    p0 = w00 * mx + w01 * my + w02 * mz + tl.load(cam_ptr + 9)
    p1 = w10 * mx + w11 * my + w12 * mz + tl.load(cam_ptr + 10)
    p2 = w20 * mx + w21 * my + w22 * mz + tl.load(cam_ptr + 11)
    in_depth = (p2 > near) & (p2 < far)
    zs = tl.where(in_depth, p2, 1.0)
    # quaternion (w, x, y, z), normalised with the norm floored as in frames.quat_to_matrix
    qw = tl.load(q_ptr + i * 4 + 0, mask=mask, other=1.0)
    qx = tl.load(q_ptr + i * 4 + 1, mask=mask, other=0.0)
    qy = tl.load(q_ptr + i * 4 + 2, mask=mask, other=0.0)
    qz = tl.load(q_ptr + i * 4 + 3, mask=mask, other=0.0)
    qn = tl.maximum(tl.sqrt(qw * qw + qx * qx + qy * qy + qz * qz), _NORM_FLOOR)
    qw = qw / qn
    qx = qx / qn
    qy = qy / qn
    qz = qz / qn
    r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
    r01 = 2.0 * (qx * qy - qw * qz)
    r02 = 2.0 * (qx * qz + qw * qy)
    r10 = 2.0 * (qx * qy + qw * qz)
    r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
    r12 = 2.0 * (qy * qz - qw * qx)
    r20 = 2.0 * (qx * qz - qw * qy)
    r21 = 2.0 * (qy * qz + qw * qx)
    r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
    # R_c = R_cw R (Gaussian axes in the camera frame)
    c00 = w00 * r00 + w01 * r10 + w02 * r20
    c01 = w00 * r01 + w01 * r11 + w02 * r21
    c02 = w00 * r02 + w01 * r12 + w02 * r22
    c10 = w10 * r00 + w11 * r10 + w12 * r20
    c11 = w10 * r01 + w11 * r11 + w12 * r21
    c12 = w10 * r02 + w11 * r12 + w12 * r22
    c20 = w20 * r00 + w21 * r10 + w22 * r20
    c21 = w20 * r01 + w21 * r11 + w22 * r21
    c22 = w20 * r02 + w21 * r12 + w22 * r22
    ls0 = tl.load(s_ptr + i * NS + 0, mask=mask, other=0.0)
    ls1 = tl.load(s_ptr + i * NS + 1, mask=mask, other=0.0)
    ls2 = 0.0 * ls0
    if NS == 3:
        ls2 = tl.load(s_ptr + i * NS + 2, mask=mask, other=0.0)
    s0 = tl.exp(ls0)
    s1 = tl.exp(ls1)
    s2 = tl.exp(ls2)
    # J with clamped tx/tz, ty/tz; T = J M with M = R_c diag(s)
    rx = p0 / zs
    ry = p1 / zs
    tx = tl.minimum(tl.maximum(rx, -xn), xp)
    ty = tl.minimum(tl.maximum(ry, -yn), yp)
    j00 = fx / zs
    j02 = -fx * tx / zs
    j11 = fy / zs
    j12 = -fy * ty / zs
    t00 = (j00 * c00 + j02 * c20) * s0
    t01 = (j00 * c01 + j02 * c21) * s1
    t02 = (j00 * c02 + j02 * c22) * s2
    t10 = (j11 * c10 + j12 * c20) * s0
    t11 = (j11 * c11 + j12 * c21) * s1
    t12 = (j11 * c12 + j12 * c22) * s2
    v00 = t00 * t00 + t01 * t01 + t02 * t02
    v01 = t00 * t10 + t01 * t11 + t02 * t12
    v11 = t10 * t10 + t11 * t11 + t12 * t12
    a = v00 + lowpass
    c = v11 + lowpass
    det = a * c - v01 * v01
    ds = tl.maximum(det, _DET_FLOOR)
    return (
        mx, my, mz, p0, p1, p2, in_depth, zs, qw, qx, qy, qz, qn,
        c00, c01, c02, c10, c11, c12, c20, c21, c22, ls0, ls1, ls2, s0, s1, s2,
        rx, ry, tx, ty, j00, j02, j11, j12, t00, t01, t02, t10, t11, t12,
        v00, v01, v11, a, c, det, ds,
    )  # fmt: skip


@triton.jit
def _normal_axis(ls0, ls1, ls2, c00, c01, c02, c10, c11, c12, c20, c21, c22, p0, p1, p2):
    """Shortest axis (first on ties, as torch.argmin), its column and the facing sign."""
    k1 = ls1 < ls0
    k2 = ls2 < tl.minimum(ls0, ls1)
    n0 = tl.where(k2, c02, tl.where(k1, c01, c00))
    n1 = tl.where(k2, c12, tl.where(k1, c11, c10))
    n2 = tl.where(k2, c22, tl.where(k1, c21, c20))
    facing = tl.where(n0 * p0 + n1 * p1 + n2 * p2 > 0, -1.0, 1.0)
    return k1, k2, n0, n1, n2, facing


@triton.jit
def _view_dir(mx, my, mz, cam_ptr):
    dx = mx - tl.load(cam_ptr + 12)
    dy = my - tl.load(cam_ptr + 13)
    dz = mz - tl.load(cam_ptr + 14)
    dn = tl.maximum(tl.sqrt(dx * dx + dy * dy + dz * dz), _NORM_FLOOR)
    return dx / dn, dy / dn, dz / dn, dn


@triton.jit
def _store_support(lo_ptr, emin_ptr, bbox_ptr, vis_ptr, i, mask, lo, emin, b0, b1, b2, b3, vis):
    """Store ln o, the smallest admissible exponent, the support box and the visibility."""
    tl.store(lo_ptr + i, lo, mask=mask)
    tl.store(emin_ptr + i, emin, mask=mask)
    tl.store(bbox_ptr + i * 4 + 0, b0, mask=mask)
    tl.store(bbox_ptr + i * 4 + 1, b1, mask=mask)
    tl.store(bbox_ptr + i * 4 + 2, b2, mask=mask)
    tl.store(bbox_ptr + i * 4 + 3, b3, mask=mask)
    tl.store(vis_ptr + i, vis.to(tl.int8), mask=mask)


@triton.jit
def _store_rgb(sh_ptr, rgb_ptr, i, mask, basis, KS: tl.constexpr, NB: tl.constexpr):
    """Store max(SH . basis + 0.5, 0) for the three colour channels."""
    for ch in tl.static_range(3):
        col = _sh_channel(sh_ptr, i, mask, ch, basis, KS, NB) + 0.5
        tl.store(rgb_ptr + i * 3 + ch, tl.maximum(col, 0.0), mask=mask)


@triton.jit
def _project_fwd_kernel(
    m_ptr, q_ptr, s_ptr, o_ptr, sh_ptr, cam_ptr,
    m2_ptr, z_ptr, conic_ptr, lo_ptr, emin_ptr, bbox_ptr, vis_ptr, rgb_ptr, nrm_ptr,
    n, fx, fy, cx, cy, near, far, xn, xp, yn, yp, lowpass, width, height,
    KS: tl.constexpr, DEG: tl.constexpr, NB: tl.constexpr, AA: tl.constexpr,
    BLOCK: tl.constexpr,
):  # fmt: skip
    i = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    mask = i < n
    (
        mx, my, mz, p0, p1, p2, in_depth, zs, qw, qx, qy, qz, qn,
        c00, c01, c02, c10, c11, c12, c20, c21, c22, ls0, ls1, ls2, s0, s1, s2,
        rx, ry, tx, ty, j00, j02, j11, j12, t00, t01, t02, t10, t11, t12,
        v00, v01, v11, a, c, det, ds,
    ) = _core(m_ptr, q_ptr, s_ptr, cam_ptr, i, mask, fx, fy, near, far, xn, xp, yn, yp, lowpass, 3)  # fmt: skip
    u = fx * rx + cx
    v = fy * ry + cy
    logit = tl.load(o_ptr + i, mask=mask, other=0.0)
    lo = tl.minimum(logit, 0.0) - tl.log(1.0 + tl.exp(-tl.abs(logit)))
    if AA:
        ratio = tl.maximum(v00 * v11 - v01 * v01, 0.0) / ds
        lo += 0.5 * tl.log(tl.maximum(ratio, _DET_FLOOR))
    emin = tl.maximum(lo - _MAX_EXP, _LOG_ALPHA_T)
    smax = tl.minimum(tl.maximum(lo - _LOG_ALPHA_T, 0.0), _MAX_EXP)
    hx = tl.sqrt(2.0 * smax * tl.maximum(a, 0.0))
    hy = tl.sqrt(2.0 * smax * tl.maximum(c, 0.0))
    b0 = u - hx
    b1 = u + hx
    b2 = v - hy
    b3 = v + hy
    fin = ((b0 - b0) == 0.0) & ((b1 - b1) == 0.0) & ((b2 - b2) == 0.0) & ((b3 - b3) == 0.0)
    on = (b1 > 0) & (b0 < width) & (b3 > 0) & (b2 < height)
    vis = in_depth & (det > 0) & (lo >= _VIS_LOG_O) & on & fin
    k1, k2, n0, n1, n2, facing = _normal_axis(
        ls0, ls1, ls2, c00, c01, c02, c10, c11, c12, c20, c21, c22, p0, p1, p2
    )
    ux, uy, uz, dn = _view_dir(mx, my, mz, cam_ptr)
    basis = _sh_basis(ux, uy, uz, DEG)
    tl.store(m2_ptr + i * 2 + 0, u, mask=mask)
    tl.store(m2_ptr + i * 2 + 1, v, mask=mask)
    tl.store(z_ptr + i, p2, mask=mask)
    tl.store(conic_ptr + i * 3 + 0, c / ds, mask=mask)
    tl.store(conic_ptr + i * 3 + 1, -v01 / ds, mask=mask)
    tl.store(conic_ptr + i * 3 + 2, a / ds, mask=mask)
    _store_support(lo_ptr, emin_ptr, bbox_ptr, vis_ptr, i, mask, lo, emin, b0, b1, b2, b3, vis)
    tl.store(nrm_ptr + i * 3 + 0, n0 * facing, mask=mask)
    tl.store(nrm_ptr + i * 3 + 1, n1 * facing, mask=mask)
    tl.store(nrm_ptr + i * 3 + 2, n2 * facing, mask=mask)
    _store_rgb(sh_ptr, rgb_ptr, i, mask, basis, KS, NB)


@triton.jit
def _rot_sh_mean_backward(
    dc00, dc01, dc02, dc10, dc11, dc12, dc20, dc21, dc22, dp0, dp1, dp2,
    qw, qx, qy, qz, qn, mx, my, mz, cam_ptr, sh_ptr, grgb_ptr, dq_ptr, dsh_ptr, dm_ptr, i, mask,
    KS: tl.constexpr, DEG: tl.constexpr, NB: tl.constexpr,
):  # fmt: skip
    """Shared tail of both backward kernels: dR_c -> quaternion, SH -> coefficients and the
    view direction, camera-frame mean -> world mean; stores d quats, d sh, d means."""
    # R_c = W R: dR = W^T dR_c
    w00 = tl.load(cam_ptr + 0)
    w01 = tl.load(cam_ptr + 1)
    w02 = tl.load(cam_ptr + 2)
    w10 = tl.load(cam_ptr + 3)
    w11 = tl.load(cam_ptr + 4)
    w12 = tl.load(cam_ptr + 5)
    w20 = tl.load(cam_ptr + 6)
    w21 = tl.load(cam_ptr + 7)
    w22 = tl.load(cam_ptr + 8)
    dr00 = w00 * dc00 + w10 * dc10 + w20 * dc20
    dr01 = w00 * dc01 + w10 * dc11 + w20 * dc21
    dr02 = w00 * dc02 + w10 * dc12 + w20 * dc22
    dr10 = w01 * dc00 + w11 * dc10 + w21 * dc20
    dr11 = w01 * dc01 + w11 * dc11 + w21 * dc21
    dr12 = w01 * dc02 + w11 * dc12 + w21 * dc22
    dr20 = w02 * dc00 + w12 * dc10 + w22 * dc20
    dr21 = w02 * dc01 + w12 * dc11 + w22 * dc21
    dr22 = w02 * dc02 + w12 * dc12 + w22 * dc22
    # R(q) of the normalised quaternion, then the normalisation q / max(|q|, floor)
    gw = 2.0 * (-qz * dr01 + qy * dr02 + qz * dr10 - qx * dr12 - qy * dr20 + qx * dr21)
    gx = 2.0 * (
        -2.0 * qx * (dr11 + dr22) + qy * dr01 + qz * dr02 + qy * dr10 - qw * dr12
        + qz * dr20 + qw * dr21
    )  # fmt: skip
    gy = 2.0 * (
        -2.0 * qy * (dr00 + dr22) + qx * dr01 + qw * dr02 + qx * dr10 + qz * dr12
        - qw * dr20 + qz * dr21
    )  # fmt: skip
    gz = 2.0 * (
        -2.0 * qz * (dr00 + dr11) - qw * dr01 + qx * dr02 + qw * dr10 + qy * dr12
        + qx * dr20 + qy * dr21
    )  # fmt: skip
    proj = tl.where(qn > _NORM_FLOOR, qw * gw + qx * gx + qy * gy + qz * gz, 0.0)
    tl.store(dq_ptr + i * 4 + 0, (gw - qw * proj) / qn, mask=mask)
    tl.store(dq_ptr + i * 4 + 1, (gx - qx * proj) / qn, mask=mask)
    tl.store(dq_ptr + i * 4 + 2, (gy - qy * proj) / qn, mask=mask)
    tl.store(dq_ptr + i * 4 + 3, (gz - qz * proj) / qn, mask=mask)
    # SH colour: d rgb / d sh = basis (where unclamped); d rgb / d dir through the basis
    ux, uy, uz, dn = _view_dir(mx, my, mz, cam_ptr)
    basis = _sh_basis(ux, uy, uz, DEG)
    gb1 = 0.0 * ux
    gb2 = 0.0 * ux
    gb3 = 0.0 * ux
    gb4 = 0.0 * ux
    gb5 = 0.0 * ux
    gb6 = 0.0 * ux
    gb7 = 0.0 * ux
    gb8 = 0.0 * ux
    gb9 = 0.0 * ux
    gb10 = 0.0 * ux
    gb11 = 0.0 * ux
    gb12 = 0.0 * ux
    gb13 = 0.0 * ux
    gb14 = 0.0 * ux
    gb15 = 0.0 * ux
    for ch in tl.static_range(3):
        col = _sh_channel(sh_ptr, i, mask, ch, basis, KS, NB) + 0.5
        gcol = tl.where(col >= 0.0, tl.load(grgb_ptr + i * 3 + ch, mask=mask, other=0.0), 0.0)
        base = sh_ptr + i * (KS * 3) + ch
        for k in tl.static_range(NB):
            tl.store(dsh_ptr + i * (KS * 3) + k * 3 + ch, basis[k] * gcol, mask=mask)
        if DEG >= 1:
            gb1 += gcol * tl.load(base + 3, mask=mask, other=0.0)
            gb2 += gcol * tl.load(base + 6, mask=mask, other=0.0)
            gb3 += gcol * tl.load(base + 9, mask=mask, other=0.0)
        if DEG >= 2:
            gb4 += gcol * tl.load(base + 12, mask=mask, other=0.0)
            gb5 += gcol * tl.load(base + 15, mask=mask, other=0.0)
            gb6 += gcol * tl.load(base + 18, mask=mask, other=0.0)
            gb7 += gcol * tl.load(base + 21, mask=mask, other=0.0)
            gb8 += gcol * tl.load(base + 24, mask=mask, other=0.0)
        if DEG >= 3:
            gb9 += gcol * tl.load(base + 27, mask=mask, other=0.0)
            gb10 += gcol * tl.load(base + 30, mask=mask, other=0.0)
            gb11 += gcol * tl.load(base + 33, mask=mask, other=0.0)
            gb12 += gcol * tl.load(base + 36, mask=mask, other=0.0)
            gb13 += gcol * tl.load(base + 39, mask=mask, other=0.0)
            gb14 += gcol * tl.load(base + 42, mask=mask, other=0.0)
            gb15 += gcol * tl.load(base + 45, mask=mask, other=0.0)
    x = ux
    y = uy
    z = uz
    xx = x * x
    yy = y * y
    zz = z * z
    gdx = -_C1 * gb3
    gdy = -_C1 * gb1
    gdz = _C1 * gb2
    if DEG >= 2:
        gdx += _C20 * y * gb4 - 2.0 * _C22 * x * gb6 + _C23 * z * gb7 + 2.0 * _C24 * x * gb8
        gdy += _C20 * x * gb4 + _C21 * z * gb5 - 2.0 * _C22 * y * gb6 - 2.0 * _C24 * y * gb8
        gdz += _C21 * y * gb5 + 4.0 * _C22 * z * gb6 + _C23 * x * gb7
    if DEG >= 3:
        gdx += (
            6.0 * _C30 * x * y * gb9 + _C31 * y * z * gb10 - 2.0 * _C32 * x * y * gb11
            - 6.0 * _C33 * x * z * gb12 + _C34 * (4.0 * zz - 3.0 * xx - yy) * gb13
            + 2.0 * _C35 * x * z * gb14 + _C36 * (3.0 * xx - 3.0 * yy) * gb15
        )  # fmt: skip
        gdy += (
            _C30 * (3.0 * xx - 3.0 * yy) * gb9 + _C31 * x * z * gb10
            + _C32 * (4.0 * zz - xx - 3.0 * yy) * gb11 - 6.0 * _C33 * y * z * gb12
            - 2.0 * _C34 * x * y * gb13 - 2.0 * _C35 * y * z * gb14 - 6.0 * _C36 * x * y * gb15
        )  # fmt: skip
        gdz += (
            _C31 * x * y * gb10 + 8.0 * _C32 * y * z * gb11
            + _C33 * (6.0 * zz - 3.0 * xx - 3.0 * yy) * gb12 + 8.0 * _C34 * x * z * gb13
            + _C35 * (xx - yy) * gb14
        )  # fmt: skip
    # dir = d / max(|d|, floor)
    dproj = tl.where(dn > _NORM_FLOOR, x * gdx + y * gdy + z * gdz, 0.0)
    # mean: view direction plus p = W m + t
    dmx = (gdx - x * dproj) / dn + w00 * dp0 + w10 * dp1 + w20 * dp2
    dmy = (gdy - y * dproj) / dn + w01 * dp0 + w11 * dp1 + w21 * dp2
    dmz = (gdz - z * dproj) / dn + w02 * dp0 + w12 * dp1 + w22 * dp2
    tl.store(dm_ptr + i * 3 + 0, dmx, mask=mask)
    tl.store(dm_ptr + i * 3 + 1, dmy, mask=mask)
    tl.store(dm_ptr + i * 3 + 2, dmz, mask=mask)


@triton.jit
def _project_bwd_kernel(
    m_ptr, q_ptr, s_ptr, o_ptr, sh_ptr, cam_ptr,
    gm2_ptr, gz_ptr, gconic_ptr, glo_ptr, grgb_ptr, gnrm_ptr,
    dm_ptr, dq_ptr, ds_ptr, do_ptr, dsh_ptr,
    n, fx, fy, near, far, xn, xp, yn, yp, lowpass,
    KS: tl.constexpr, DEG: tl.constexpr, NB: tl.constexpr, AA: tl.constexpr,
    BLOCK: tl.constexpr,
):  # fmt: skip
    i = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    mask = i < n
    (
        mx, my, mz, p0, p1, p2, in_depth, zs, qw, qx, qy, qz, qn,
        c00, c01, c02, c10, c11, c12, c20, c21, c22, ls0, ls1, ls2, s0, s1, s2,
        rx, ry, tx, ty, j00, j02, j11, j12, t00, t01, t02, t10, t11, t12,
        v00, v01, v11, a, c, det, ds,
    ) = _core(m_ptr, q_ptr, s_ptr, cam_ptr, i, mask, fx, fy, near, far, xn, xp, yn, yp, lowpass, 3)  # fmt: skip
    gu = tl.load(gm2_ptr + i * 2 + 0, mask=mask, other=0.0)
    gv = tl.load(gm2_ptr + i * 2 + 1, mask=mask, other=0.0)
    gA = tl.load(gconic_ptr + i * 3 + 0, mask=mask, other=0.0)
    gB = tl.load(gconic_ptr + i * 3 + 1, mask=mask, other=0.0)
    gC = tl.load(gconic_ptr + i * 3 + 2, mask=mask, other=0.0)
    glo = tl.load(glo_ptr + i, mask=mask, other=0.0)
    # opacity: d logsigmoid(x) / dx = sigmoid(-x)
    logit = tl.load(o_ptr + i, mask=mask, other=0.0)
    tl.store(do_ptr + i, glo / (1.0 + tl.exp(logit)), mask=mask)
    # conic = (c, -b, a) / ds, ds = max(det, floor)
    g_ds = -(gA * c - gB * v01 + gC * a) / (ds * ds)
    da = gC / ds
    dc = gA / ds
    db = -gB / ds
    dv00 = 0.0 * a
    dv11 = 0.0 * a
    if AA:  # ln o += 0.5 ln(max(max(det0, 0) / ds, floor))
        det0 = v00 * v11 - v01 * v01
        ratio = tl.maximum(det0, 0.0) / ds
        g_ratio = tl.where(ratio >= _DET_FLOOR, 0.5 * glo / tl.maximum(ratio, _DET_FLOOR), 0.0)
        g_det0 = tl.where(det0 >= 0.0, g_ratio / ds, 0.0)
        g_ds -= g_ratio * ratio / ds
        dv00 += g_det0 * v11
        dv11 += g_det0 * v00
        db -= 2.0 * v01 * g_det0
    g_det = tl.where(det >= _DET_FLOOR, g_ds, 0.0)
    da += g_det * c
    dc += g_det * a
    db -= 2.0 * v01 * g_det
    dv00 += da
    dv11 += dc
    # cov = T T^T
    dt00 = 2.0 * dv00 * t00 + db * t10
    dt01 = 2.0 * dv00 * t01 + db * t11
    dt02 = 2.0 * dv00 * t02 + db * t12
    dt10 = 2.0 * dv11 * t10 + db * t00
    dt11 = 2.0 * dv11 * t11 + db * t01
    dt12 = 2.0 * dv11 * t12 + db * t02
    # T = J M, M = R_c diag(s): dM = J^T dT, dJ = dT M^T
    m00 = c00 * s0
    m01 = c01 * s1
    m02 = c02 * s2
    m10 = c10 * s0
    m11 = c11 * s1
    m12 = c12 * s2
    m20 = c20 * s0
    m21 = c21 * s1
    m22 = c22 * s2
    dj00 = dt00 * m00 + dt01 * m01 + dt02 * m02
    dj02 = dt00 * m20 + dt01 * m21 + dt02 * m22
    dj11 = dt10 * m10 + dt11 * m11 + dt12 * m12
    dj12 = dt10 * m20 + dt11 * m21 + dt12 * m22
    dm00 = j00 * dt00
    dm01 = j00 * dt01
    dm02 = j00 * dt02
    dm10 = j11 * dt10
    dm11 = j11 * dt11
    dm12 = j11 * dt12
    dm20 = j02 * dt00 + j12 * dt10
    dm21 = j02 * dt01 + j12 * dt11
    dm22 = j02 * dt02 + j12 * dt12
    # J(zs, tx, ty) and means2d
    izs = 1.0 / zs
    dtx = -dj02 * fx * izs
    dty = -dj12 * fy * izs
    g_zs = -(dj00 * fx + dj11 * fy - dj02 * fx * tx - dj12 * fy * ty) * izs * izs
    g_rx = gu * fx + tl.where((rx >= -xn) & (rx <= xp), dtx, 0.0)
    g_ry = gv * fy + tl.where((ry >= -yn) & (ry <= yp), dty, 0.0)
    dp0 = g_rx * izs
    dp1 = g_ry * izs
    g_zs -= (g_rx * rx + g_ry * ry) * izs
    dp2 = tl.load(gz_ptr + i, mask=mask, other=0.0) + tl.where(in_depth, g_zs, 0.0)
    # log-scales
    tl.store(ds_ptr + i * 3 + 0, (dm00 * c00 + dm10 * c10 + dm20 * c20) * s0, mask=mask)
    tl.store(ds_ptr + i * 3 + 1, (dm01 * c01 + dm11 * c11 + dm21 * c21) * s1, mask=mask)
    tl.store(ds_ptr + i * 3 + 2, (dm02 * c02 + dm12 * c12 + dm22 * c22) * s2, mask=mask)
    # dR_c: from M and from the normal (the chosen column, times the facing sign)
    dc00 = dm00 * s0
    dc01 = dm01 * s1
    dc02 = dm02 * s2
    dc10 = dm10 * s0
    dc11 = dm11 * s1
    dc12 = dm12 * s2
    dc20 = dm20 * s0
    dc21 = dm21 * s1
    dc22 = dm22 * s2
    k1, k2, n0, n1, n2, facing = _normal_axis(
        ls0, ls1, ls2, c00, c01, c02, c10, c11, c12, c20, c21, c22, p0, p1, p2
    )
    gn0 = tl.load(gnrm_ptr + i * 3 + 0, mask=mask, other=0.0) * facing
    gn1 = tl.load(gnrm_ptr + i * 3 + 1, mask=mask, other=0.0) * facing
    gn2 = tl.load(gnrm_ptr + i * 3 + 2, mask=mask, other=0.0) * facing
    sel0 = tl.where(k1 | k2, 0.0, 1.0)
    sel1 = tl.where(k1 & (k2 == 0), 1.0, 0.0)
    sel2 = tl.where(k2, 1.0, 0.0)
    dc00 += gn0 * sel0
    dc10 += gn1 * sel0
    dc20 += gn2 * sel0
    dc01 += gn0 * sel1
    dc11 += gn1 * sel1
    dc21 += gn2 * sel1
    dc02 += gn0 * sel2
    dc12 += gn1 * sel2
    dc22 += gn2 * sel2
    _rot_sh_mean_backward(
        dc00, dc01, dc02, dc10, dc11, dc12, dc20, dc21, dc22, dp0, dp1, dp2,
        qw, qx, qy, qz, qn, mx, my, mz, cam_ptr, sh_ptr, grgb_ptr, dq_ptr, dsh_ptr, dm_ptr, i, mask,
        KS, DEG, NB,
    )  # fmt: skip


@triton.jit
def _surfel_fwd_kernel(
    m_ptr, q_ptr, s_ptr, o_ptr, sh_ptr, cam_ptr,
    m2_ptr, z_ptr, ray_ptr, lo_ptr, emin_ptr, bbox_ptr, vis_ptr, rgb_ptr, nrm_ptr,
    n, fx, fy, cx, cy, near, far, inv_sq, width, height,
    KS: tl.constexpr, DEG: tl.constexpr, NB: tl.constexpr, BLOCK: tl.constexpr,
):  # fmt: skip
    """2DGS (Huang et al. 2024): ray-transform rows Px, Py, Pa, Tw, the surfel box, normals."""
    i = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    mask = i < n
    (
        mx, my, mz, p0, p1, p2, in_depth, zs, qw, qx, qy, qz, qn,
        c00, c01, c02, c10, c11, c12, c20, c21, c22, ls0, ls1, ls2, s0, s1, s2,
        rx, ry, tx, ty, j00, j02, j11, j12, t00, t01, t02, t10, t11, t12,
        v00, v01, v11, a, c, det, ds,
    ) = _core(m_ptr, q_ptr, s_ptr, cam_ptr, i, mask, fx, fy, near, far, 1.0, 1.0, 1.0, 1.0, 0.0, 2)  # fmt: skip
    u = fx * rx + cx
    v = fy * ry + cy
    logit = tl.load(o_ptr + i, mask=mask, other=0.0)
    lo = tl.minimum(logit, 0.0) - tl.log(1.0 + tl.exp(-tl.abs(logit)))
    emin = tl.maximum(lo - _MAX_EXP, _LOG_ALPHA_T)
    rmax = 2.0 * tl.minimum(tl.maximum(lo - _LOG_ALPHA_T, 0.0), _MAX_EXP)
    # Tm = K [R_c s_u t_u, R_c s_v t_v, p]: rows Tu, Tv, Tw
    u0 = fx * c00 * s0 + cx * c20 * s0
    u1 = fx * c01 * s1 + cx * c21 * s1
    u2 = fx * p0 + cx * p2
    v0 = fy * c10 * s0 + cy * c20 * s0
    v1 = fy * c11 * s1 + cy * c21 * s1
    v2 = fy * p1 + cy * p2
    w0 = c20 * s0
    w1 = c21 * s1
    w2 = p2
    base = ray_ptr + i * 12
    tl.store(base + 0, v1 * w2 - v2 * w1, mask=mask)  # Px = Tv x Tw
    tl.store(base + 1, v2 * w0 - v0 * w2, mask=mask)
    tl.store(base + 2, v0 * w1 - v1 * w0, mask=mask)
    tl.store(base + 3, w1 * u2 - w2 * u1, mask=mask)  # Py = Tw x Tu
    tl.store(base + 4, w2 * u0 - w0 * u2, mask=mask)
    tl.store(base + 5, w0 * u1 - w1 * u0, mask=mask)
    tl.store(base + 6, u1 * v2 - u2 * v1, mask=mask)  # Pa = Tu x Tv
    tl.store(base + 7, u2 * v0 - u0 * v2, mask=mask)
    tl.store(base + 8, u0 * v1 - u1 * v0, mask=mask)
    tl.store(base + 9, w0, mask=mask)
    tl.store(base + 10, w1, mask=mask)
    tl.store(base + 11, w2, mask=mask)
    # box of the projected disk from the dual conic D = r^2 (c0 c0^T + c1 c1^T) - c2 c2^T
    # (columns c_j of Tm), joined with the low-pass circle; unbounded disks get the screen
    d00 = rmax * (u0 * u0 + u1 * u1) - u2 * u2
    d11 = rmax * (v0 * v0 + v1 * v1) - v2 * v2
    d22 = rmax * (w0 * w0 + w1 * w1) - w2 * w2
    d02 = rmax * (u0 * w0 + u1 * w1) - u2 * w2
    d12 = rmax * (v0 * w0 + v1 * w1) - v2 * w2
    bounded = d22 < 0
    d22s = tl.where(bounded, d22, -1.0)
    xc = d02 / d22s
    yc = d12 / d22s
    hx = tl.sqrt(tl.maximum(xc * xc - d00 / d22s, 0.0))
    hy = tl.sqrt(tl.maximum(yc * yc - d11 / d22s, 0.0))
    rl = tl.sqrt(rmax / inv_sq)
    b0 = tl.where(bounded, tl.minimum(xc - hx, u - rl), 0.0)
    b1 = tl.where(bounded, tl.maximum(xc + hx, u + rl), width)
    b2 = tl.where(bounded, tl.minimum(yc - hy, v - rl), 0.0)
    b3 = tl.where(bounded, tl.maximum(yc + hy, v + rl), height)
    fin = ((b0 - b0) == 0.0) & ((b1 - b1) == 0.0) & ((b2 - b2) == 0.0) & ((b3 - b3) == 0.0)
    on = (b1 > 0) & (b0 < width) & (b3 > 0) & (b2 < height)
    vis = in_depth & (lo >= _VIS_LOG_O) & on & fin
    facing = tl.where(c02 * p0 + c12 * p1 + c22 * p2 > 0, -1.0, 1.0)
    ux, uy, uz, dn = _view_dir(mx, my, mz, cam_ptr)
    basis = _sh_basis(ux, uy, uz, DEG)
    tl.store(m2_ptr + i * 2 + 0, u, mask=mask)
    tl.store(m2_ptr + i * 2 + 1, v, mask=mask)
    tl.store(z_ptr + i, p2, mask=mask)
    _store_support(lo_ptr, emin_ptr, bbox_ptr, vis_ptr, i, mask, lo, emin, b0, b1, b2, b3, vis)
    tl.store(nrm_ptr + i * 3 + 0, c02 * facing, mask=mask)
    tl.store(nrm_ptr + i * 3 + 1, c12 * facing, mask=mask)
    tl.store(nrm_ptr + i * 3 + 2, c22 * facing, mask=mask)
    _store_rgb(sh_ptr, rgb_ptr, i, mask, basis, KS, NB)


@triton.jit
def _surfel_bwd_kernel(
    m_ptr, q_ptr, s_ptr, o_ptr, sh_ptr, cam_ptr,
    gm2_ptr, gz_ptr, gray_ptr, glo_ptr, grgb_ptr, gnrm_ptr,
    dm_ptr, dq_ptr, ds_ptr, do_ptr, dsh_ptr,
    n, fx, fy, cx, cy, near, far,
    KS: tl.constexpr, DEG: tl.constexpr, NB: tl.constexpr, BLOCK: tl.constexpr,
):  # fmt: skip
    i = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    mask = i < n
    (
        mx, my, mz, p0, p1, p2, in_depth, zs, qw, qx, qy, qz, qn,
        c00, c01, c02, c10, c11, c12, c20, c21, c22, ls0, ls1, ls2, s0, s1, s2,
        rx, ry, tx, ty, j00, j02, j11, j12, t00, t01, t02, t10, t11, t12,
        v00, v01, v11, a, c, det, ds,
    ) = _core(m_ptr, q_ptr, s_ptr, cam_ptr, i, mask, fx, fy, near, far, 1.0, 1.0, 1.0, 1.0, 0.0, 2)  # fmt: skip
    logit = tl.load(o_ptr + i, mask=mask, other=0.0)
    tl.store(
        do_ptr + i, tl.load(glo_ptr + i, mask=mask, other=0.0) / (1.0 + tl.exp(logit)), mask=mask
    )
    u0 = fx * c00 * s0 + cx * c20 * s0
    u1 = fx * c01 * s1 + cx * c21 * s1
    u2 = fx * p0 + cx * p2
    v0 = fy * c10 * s0 + cy * c20 * s0
    v1 = fy * c11 * s1 + cy * c21 * s1
    v2 = fy * p1 + cy * p2
    w0 = c20 * s0
    w1 = c21 * s1
    w2 = p2
    gb = gray_ptr + i * 12
    gx0 = tl.load(gb + 0, mask=mask, other=0.0)
    gx1 = tl.load(gb + 1, mask=mask, other=0.0)
    gx2 = tl.load(gb + 2, mask=mask, other=0.0)
    gy0 = tl.load(gb + 3, mask=mask, other=0.0)
    gy1 = tl.load(gb + 4, mask=mask, other=0.0)
    gy2 = tl.load(gb + 5, mask=mask, other=0.0)
    ga0 = tl.load(gb + 6, mask=mask, other=0.0)
    ga1 = tl.load(gb + 7, mask=mask, other=0.0)
    ga2 = tl.load(gb + 8, mask=mask, other=0.0)
    # d(a x b) with upstream g: da = b x g, db = g x a
    # Px = Tv x Tw, Py = Tw x Tu, Pa = Tu x Tv
    du0 = (gy1 * w2 - gy2 * w1) + (v1 * ga2 - v2 * ga1)
    du1 = (gy2 * w0 - gy0 * w2) + (v2 * ga0 - v0 * ga2)
    du2 = (gy0 * w1 - gy1 * w0) + (v0 * ga1 - v1 * ga0)
    dv0 = (w1 * gx2 - w2 * gx1) + (ga1 * u2 - ga2 * u1)
    dv1 = (w2 * gx0 - w0 * gx2) + (ga2 * u0 - ga0 * u2)
    dv2 = (w0 * gx1 - w1 * gx0) + (ga0 * u1 - ga1 * u0)
    dw0 = tl.load(gb + 9, mask=mask, other=0.0) + (gx1 * v2 - gx2 * v1) + (u1 * gy2 - u2 * gy1)
    dw1 = tl.load(gb + 10, mask=mask, other=0.0) + (gx2 * v0 - gx0 * v2) + (u2 * gy0 - u0 * gy2)
    dw2 = tl.load(gb + 11, mask=mask, other=0.0) + (gx0 * v1 - gx1 * v0) + (u0 * gy1 - u1 * gy0)
    # column j of Tm is K col_j: d col_j = K^T d(Tm[:, j])
    da0 = fx * du0
    da1 = fy * dv0
    da2 = cx * du0 + cy * dv0 + dw0
    db0 = fx * du1
    db1 = fy * dv1
    db2 = cx * du1 + cy * dv1 + dw1
    dp0 = fx * du2
    dp1 = fy * dv2
    dp2 = cx * du2 + cy * dv2 + dw2
    # col_u = R_c[:, 0] s0, col_v = R_c[:, 1] s1
    tl.store(ds_ptr + i * 2 + 0, (da0 * c00 + da1 * c10 + da2 * c20) * s0, mask=mask)
    tl.store(ds_ptr + i * 2 + 1, (db0 * c01 + db1 * c11 + db2 * c21) * s1, mask=mask)
    facing = tl.where(c02 * p0 + c12 * p1 + c22 * p2 > 0, -1.0, 1.0)
    dc00 = da0 * s0
    dc10 = da1 * s0
    dc20 = da2 * s0
    dc01 = db0 * s1
    dc11 = db1 * s1
    dc21 = db2 * s1
    dc02 = tl.load(gnrm_ptr + i * 3 + 0, mask=mask, other=0.0) * facing
    dc12 = tl.load(gnrm_ptr + i * 3 + 1, mask=mask, other=0.0) * facing
    dc22 = tl.load(gnrm_ptr + i * 3 + 2, mask=mask, other=0.0) * facing
    # means2d and depth
    gu = tl.load(gm2_ptr + i * 2 + 0, mask=mask, other=0.0)
    gv = tl.load(gm2_ptr + i * 2 + 1, mask=mask, other=0.0)
    izs = 1.0 / zs
    dp0 += gu * fx * izs
    dp1 += gv * fy * izs
    g_zs = -(gu * fx * rx + gv * fy * ry) * izs
    dp2 += tl.load(gz_ptr + i, mask=mask, other=0.0) + tl.where(in_depth, g_zs, 0.0)
    _rot_sh_mean_backward(
        dc00, dc01, dc02, dc10, dc11, dc12, dc20, dc21, dc22, dp0, dp1, dp2,
        qw, qx, qy, qz, qn, mx, my, mz, cam_ptr, sh_ptr, grgb_ptr, dq_ptr, dsh_ptr, dm_ptr, i, mask,
        KS, DEG, NB,
    )  # fmt: skip


def _camera_args(camera: Camera) -> tuple[float, ...]:
    """(fx, fy, cx, cy, near, far, xn, xp, yn, yp) as in ``projection._fov_limits``."""
    tan_x = 0.5 * camera.width / camera.fx
    tan_y = 0.5 * camera.height / camera.fy
    fx, fy, cx, cy = float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy)
    return (
        fx, fy, cx, cy, float(camera.near), float(camera.far),
        cx / fx + FOV_CLAMP_MARGIN * tan_x,
        (camera.width - cx) / fx + FOV_CLAMP_MARGIN * tan_x,
        cy / fy + FOV_CLAMP_MARGIN * tan_y,
        (camera.height - cy) / fy + FOV_CLAMP_MARGIN * tan_y,
    )  # fmt: skip


class _Project(torch.autograd.Function):
    """The fused projection as one differentiable op (float32, contiguous inputs)."""

    @staticmethod
    def forward(ctx, means, quats, log_scales, logits, sh, cam, meta):  # type: ignore[override]
        fx, fy, cx, cy, near, far, xn, xp, yn, yp, lowpass, W, H, deg, aa = meta
        n = means.shape[0]
        ks = sh.shape[1]
        m2 = means.new_empty((n, 2))
        z = means.new_empty(n)
        conic = means.new_empty((n, 3))
        lo = means.new_empty(n)
        emin = means.new_empty(n)
        bbox = means.new_empty((n, 4))
        vis = torch.empty(n, dtype=torch.int8, device=means.device)
        rgb = means.new_empty((n, 3))
        nrm = means.new_empty((n, 3))
        grid = (triton.cdiv(n, _BLOCK),)
        surfel = log_scales.shape[1] == 2
        if surfel:
            conic = means.new_empty((n, 4, 3))  # the ray rows Px, Py, Pa, Tw
        if n and surfel:
            _surfel_fwd_kernel[grid](
                means, quats, log_scales, logits, sh, cam,
                m2, z, conic, lo, emin, bbox, vis, rgb, nrm,
                n, fx, fy, cx, cy, near, far, lowpass, float(W), float(H),
                KS=ks, DEG=deg, NB=(deg + 1) ** 2, BLOCK=_BLOCK, num_warps=_WARPS,
            )  # fmt: skip
        elif n:
            _project_fwd_kernel[grid](
                means, quats, log_scales, logits, sh, cam,
                m2, z, conic, lo, emin, bbox, vis, rgb, nrm,
                n, fx, fy, cx, cy, near, far, xn, xp, yn, yp, lowpass, float(W), float(H),
                KS=ks, DEG=deg, NB=(deg + 1) ** 2, AA=aa, BLOCK=_BLOCK, num_warps=_WARPS,
            )  # fmt: skip
        ctx.save_for_backward(means, quats, log_scales, logits, sh, cam)
        ctx.meta = meta
        visible = vis.view(torch.bool)
        ctx.mark_non_differentiable(emin, bbox, visible)
        return m2, z, conic, lo, rgb, nrm, emin, bbox, visible

    @staticmethod
    def backward(ctx, gm2, gz, gconic, glo, grgb, gnrm, _ge, _gb, _gv):  # type: ignore[override]
        means, quats, log_scales, logits, sh, cam = ctx.saved_tensors
        fx, fy, cx, cy, near, far, xn, xp, yn, yp, lowpass, W, H, deg, aa = ctx.meta
        n = means.shape[0]
        ks = sh.shape[1]
        dm = torch.empty_like(means)
        dq = torch.empty_like(quats)
        dls = torch.empty_like(log_scales)
        dop = torch.empty_like(logits)
        nb = (deg + 1) ** 2
        dsh = torch.empty_like(sh) if nb == ks else torch.zeros_like(sh)
        grads = [t.float().contiguous() for t in (gm2, gz, gconic, glo, grgb, gnrm)]
        if n and log_scales.shape[1] == 2:
            _surfel_bwd_kernel[(triton.cdiv(n, _BLOCK),)](
                means, quats, log_scales, logits, sh, cam, *grads, dm, dq, dls, dop, dsh,
                n, fx, fy, cx, cy, near, far,
                KS=ks, DEG=deg, NB=nb, BLOCK=_BLOCK, num_warps=_WARPS,
            )  # fmt: skip
        elif n:
            _project_bwd_kernel[(triton.cdiv(n, _BLOCK),)](
                means, quats, log_scales, logits, sh, cam, *grads, dm, dq, dls, dop, dsh,
                n, fx, fy, near, far, xn, xp, yn, yp, lowpass,
                KS=ks, DEG=deg, NB=nb, AA=aa, BLOCK=_BLOCK, num_warps=_WARPS,
            )  # fmt: skip
        return dm, dq, dls, dop, dsh, None, None


def project_fused(gaussians: Gaussians, camera: Camera, config: RenderConfig) -> Projected:
    """:func:`~.projection.project` by the fused kernels (float32; 3DGS and 2DGS).

    Args:
        gaussians: N Gaussians (3 or 2 log-scales per ``config.kind``) on a CUDA device (any device under ``TRITON_INTERPRET=1``).
        camera: pinhole camera (distortion ignored; its pose gets no gradient).
        config: render options (kind, SH degree, anti-aliasing, low-pass scale).

    Returns:
        The same fields as ``project``, float32, differentiable w.r.t. means, quats,
        log_scales, opacity_logits and sh; ``extra`` is passed through.
    """
    if not fused_projection_supports(gaussians, camera, config):
        raise ValueError(
            "project_fused covers 3DGS/2DGS Gaussians of the configured kind without camera-pose "
            "gradients only; use projection.project"
        )
    g = gaussians
    dev = g.means.device
    full = sh_degree_of(g.sh.shape[1])
    deg = full if config.sh_degree is None else min(int(config.sh_degree), full)
    with torch.no_grad():
        R_cw, t_cw, centre = camera.world_to_cam(torch.float32, dev)
        cam = torch.cat([R_cw.reshape(-1), t_cw, centre]).contiguous()
    surfel = config.kind == "2dgs"
    # 3DGS: the low-pass added to the 2D covariance; 2DGS: the screen filter coefficient
    lowpass = lowpass_inv_sq(config) if surfel else LOWPASS_3DGS_PX2 * config.lowpass_scale**2
    meta = (*_camera_args(camera), float(lowpass), camera.width, camera.height, int(deg))
    meta = (*meta, bool(config.antialiased))
    ins = [t.float().contiguous() for t in (g.means, g.quats, g.log_scales, g.opacity_logits)]
    sh = g.sh.float().contiguous()
    m2, z, conic, lo, rgb, nrm, emin, bbox, visible = _Project.apply(*ins, sh, cam, meta)
    extra = g.extra if g.extra is not None else g.means.new_zeros((len(g), 0))
    return Projected(
        kind=config.kind,
        lowpass_inv_sq=lowpass_inv_sq(config),
        means2d=m2,
        depth=z,
        log_opacity=lo,
        exp_min=emin,
        conic=None if surfel else conic,
        ray=conic if surfel else None,
        bbox=bbox,
        visible=visible,
        rgb=rgb,
        normals=nrm,
        extra=extra,
    )
