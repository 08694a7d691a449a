"""Numba kernels of the EWA projection, forward and hand-written backward (see project_ref.py).

Written with scalars only: no per-Gaussian arrays or small matrix products (numba would allocate
them and call BLAS), so one Gaussian costs a few hundred flops.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from recon.raster.project_ref import QUAT_EPS
from recon.raster.types import LOWPASS, NEAR_PLANE

_opts = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


@numba.njit(**_opts)
def _rotation(q0, q1, q2, q3):
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    d = max(n, QUAT_EPS)
    w, x, y, z = q0 / d, q1 / d, q2 / d, q3 / d
    return (1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y), w, x, y, z, n)


@numba.njit(**_opts)
def jacobian_limits(fx, fy, cx, cy, width, height):
    """(x_neg, x_pos, y_neg, y_pos): the range of t_x / t_z and t_y / t_z the projection's Jacobian is
    evaluated in (project_ref.jacobian_limits; numba's copy)."""
    gx, gy = 0.3 * (0.5 * width / fx), 0.3 * (0.5 * height / fy)
    return cx / fx + gx, (width - cx) / fx + gx, cy / fy + gy, (height - cy) / fy + gy


@numba.njit(**_opts)
def _setup(i, means, quats, scales, W, fx, fy, lim):
    """Everything the forward and the backward share for Gaussian i (all scalars); `lim`: jacobian_limits."""
    tx = W[0, 0] * means[i, 0] + W[0, 1] * means[i, 1] + W[0, 2] * means[i, 2] + W[0, 3]
    ty = W[1, 0] * means[i, 0] + W[1, 1] * means[i, 1] + W[1, 2] * means[i, 2] + W[1, 3]
    tz = W[2, 0] * means[i, 0] + W[2, 1] * means[i, 1] + W[2, 2] * means[i, 2] + W[2, 3]
    rx, ry = tx / tz, ty / tz
    ux = min(max(rx, -lim[0]), lim[1])
    uy = min(max(ry, -lim[2]), lim[3])
    r00, r01, r02, r10, r11, r12, r20, r21, r22, w, x, y, z, qn = _rotation(quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3])
    s0, s1, s2 = scales[i, 0], scales[i, 1], scales[i, 2]
    # A = Wr R S (3x3): camera-space axes of the Gaussian; V = A A^T
    m00, m01, m02 = r00 * s0, r01 * s1, r02 * s2
    m10, m11, m12 = r10 * s0, r11 * s1, r12 * s2
    m20, m21, m22 = r20 * s0, r21 * s1, r22 * s2
    a00 = W[0, 0] * m00 + W[0, 1] * m10 + W[0, 2] * m20
    a01 = W[0, 0] * m01 + W[0, 1] * m11 + W[0, 2] * m21
    a02 = W[0, 0] * m02 + W[0, 1] * m12 + W[0, 2] * m22
    a10 = W[1, 0] * m00 + W[1, 1] * m10 + W[1, 2] * m20
    a11 = W[1, 0] * m01 + W[1, 1] * m11 + W[1, 2] * m21
    a12 = W[1, 0] * m02 + W[1, 1] * m12 + W[1, 2] * m22
    a20 = W[2, 0] * m00 + W[2, 1] * m10 + W[2, 2] * m20
    a21 = W[2, 0] * m01 + W[2, 1] * m11 + W[2, 2] * m21
    a22 = W[2, 0] * m02 + W[2, 1] * m12 + W[2, 2] * m22
    # B = J A (2x3), J = [[fx/tz, 0, -fx ux/tz], [0, fy/tz, -fy uy/tz]]
    j00, j02, j11, j12 = fx / tz, -fx * ux / tz, fy / tz, -fy * uy / tz
    b00, b01, b02 = j00 * a00 + j02 * a20, j00 * a01 + j02 * a21, j00 * a02 + j02 * a22
    b10, b11, b12 = j11 * a10 + j12 * a20, j11 * a11 + j12 * a21, j11 * a12 + j12 * a22
    sa = b00 * b00 + b01 * b01 + b02 * b02 + LOWPASS
    sb = b00 * b10 + b01 * b11 + b02 * b12
    sc = b10 * b10 + b11 * b11 + b12 * b12 + LOWPASS
    return (tx, ty, tz, rx, ry, ux, uy, j00, j02, j11, j12,
            (r00, r01, r02, r10, r11, r12, r20, r21, r22), (w, x, y, z, qn), (s0, s1, s2),
            (a00, a01, a02, a10, a11, a12, a20, a21, a22), (b00, b01, b02, b10, b11, b12), sa, sb, sc)


@numba.njit(parallel=True, **_opts)
def project_forward(means, quats, scales, W, fx, fy, cx, cy, width, height, means2d, conics, depths, radii):
    lim = jacobian_limits(fx, fy, cx, cy, width, height)
    for i in numba.prange(means.shape[0]):
        tz = W[2, 0] * means[i, 0] + W[2, 1] * means[i, 1] + W[2, 2] * means[i, 2] + W[2, 3]
        depths[i] = tz
        if not tz >= NEAR_PLANE:
            radii[i] = 0
            means2d[i, 0] = means2d[i, 1] = 0.0
            conics[i, 0] = conics[i, 1] = conics[i, 2] = 0.0
            continue
        tx, ty, tz, rx, ry, ux, uy, j00, j02, j11, j12, R, Q, S, A, B, sa, sb, sc = _setup(
            i, means, quats, scales, W, fx, fy, lim)
        det = sa * sc - sb * sb
        conics[i, 0] = sc / det
        conics[i, 1] = -sb / det
        conics[i, 2] = sa / det
        means2d[i, 0] = fx * tx / tz + cx
        means2d[i, 1] = fy * ty / tz + cy
        mid = 0.5 * (sa + sc)
        lam = mid + math.sqrt(max(mid * mid - det, 0.1))
        r = math.ceil(3.0 * math.sqrt(lam))
        radii[i] = np.int32(r) if math.isfinite(r) and r < 2.0e9 else 0


@numba.njit(parallel=True, **_opts)
def project_backward(means, quats, scales, W, fx, fy, cx, cy, width, height, radii, g_means2d, g_conics, g_depths,
                     g_means, g_quats, g_scales):
    lim = jacobian_limits(fx, fy, cx, cy, width, height)
    for i in numba.prange(means.shape[0]):
        if radii[i] <= 0:
            for k in range(3):
                g_means[i, k] = 0.0
                g_scales[i, k] = 0.0
            for k in range(4):
                g_quats[i, k] = 0.0
            continue
        tx, ty, tz, rx, ry, ux, uy, j00, j02, j11, j12, R, Q, S, A, B, sa, sb, sc = _setup(
            i, means, quats, scales, W, fx, fy, lim)
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
        w, x, y, z, qn = Q
        s0, s1, s2 = S
        a00, a01, a02, a10, a11, a12, a20, a21, a22 = A
        b00, b01, b02, b10, b11, b12 = B
        det = sa * sc - sb * sb
        d2 = det * det
        ga, gb, gc = g_conics[i, 0], g_conics[i, 1], g_conics[i, 2]
        # conic = (sc, -sb, sa) / det
        g_sa = ga * (-sc * sc / d2) + gb * (sb * sc / d2) + gc * (1.0 / det - sa * sc / d2)
        g_sc = ga * (1.0 / det - sc * sa / d2) + gb * (sb * sa / d2) + gc * (-sa * sa / d2)
        g_sb = ga * (2.0 * sb * sc / d2) + gb * (-1.0 / det - 2.0 * sb * sb / d2) + gc * (2.0 * sa * sb / d2)
        # cov2 = B B^T with B = J A; Gs = [[2 g_sa, g_sb], [g_sb, 2 g_sc]]: dL/dB = Gs B
        e00, e01, e11 = 2.0 * g_sa, g_sb, 2.0 * g_sc
        gb00, gb01, gb02 = e00 * b00 + e01 * b10, e00 * b01 + e01 * b11, e00 * b02 + e01 * b12
        gb10, gb11, gb12 = e01 * b00 + e11 * b10, e01 * b01 + e11 * b11, e01 * b02 + e11 * b12
        # B = J A: dL/dJ = dL/dB A^T (only the non-zero entries of J), dL/dA = J^T dL/dB
        gj00 = gb00 * a00 + gb01 * a01 + gb02 * a02
        gj02 = gb00 * a20 + gb01 * a21 + gb02 * a22
        gj11 = gb10 * a10 + gb11 * a11 + gb12 * a12
        gj12 = gb10 * a20 + gb11 * a21 + gb12 * a22
        ga00, ga01, ga02 = j00 * gb00, j00 * gb01, j00 * gb02
        ga10, ga11, ga12 = j11 * gb10, j11 * gb11, j11 * gb12
        ga20 = j02 * gb00 + j12 * gb10
        ga21 = j02 * gb01 + j12 * gb11
        ga22 = j02 * gb02 + j12 * gb12
        # A = Wr M: dL/dM = Wr^T dL/dA
        gm00 = W[0, 0] * ga00 + W[1, 0] * ga10 + W[2, 0] * ga20
        gm01 = W[0, 0] * ga01 + W[1, 0] * ga11 + W[2, 0] * ga21
        gm02 = W[0, 0] * ga02 + W[1, 0] * ga12 + W[2, 0] * ga22
        gm10 = W[0, 1] * ga00 + W[1, 1] * ga10 + W[2, 1] * ga20
        gm11 = W[0, 1] * ga01 + W[1, 1] * ga11 + W[2, 1] * ga21
        gm12 = W[0, 1] * ga02 + W[1, 1] * ga12 + W[2, 1] * ga22
        gm20 = W[0, 2] * ga00 + W[1, 2] * ga10 + W[2, 2] * ga20
        gm21 = W[0, 2] * ga01 + W[1, 2] * ga11 + W[2, 2] * ga21
        gm22 = W[0, 2] * ga02 + W[1, 2] * ga12 + W[2, 2] * ga22
        # M = R diag(s)
        g_scales[i, 0] = gm00 * r00 + gm10 * r10 + gm20 * r20
        g_scales[i, 1] = gm01 * r01 + gm11 * r11 + gm21 * r21
        g_scales[i, 2] = gm02 * r02 + gm12 * r12 + gm22 * r22
        G00, G01, G02 = gm00 * s0, gm01 * s1, gm02 * s2
        G10, G11, G12 = gm10 * s0, gm11 * s1, gm12 * s2
        G20, G21, G22 = gm20 * s0, gm21 * s1, gm22 * s2
        gw = 2 * (-z * G01 + y * G02 + z * G10 - x * G12 - y * G20 + x * G21)
        gx = 2 * (y * G01 + z * G02 + y * G10 - 2 * x * G11 - w * G12 + z * G20 + w * G21 - 2 * x * G22)
        gy = 2 * (-2 * y * G00 + x * G01 + w * G02 + x * G10 + z * G12 - w * G20 + z * G21 - 2 * y * G22)
        gz = 2 * (-2 * z * G00 - w * G01 + x * G02 + w * G10 - 2 * z * G11 + y * G12 + x * G20 + y * G21)
        if qn > QUAT_EPS:  # through q / |q|
            dot = w * gw + x * gx + y * gy + z * gz
            g_quats[i, 0] = (gw - w * dot) / qn
            g_quats[i, 1] = (gx - x * dot) / qn
            g_quats[i, 2] = (gy - y * dot) / qn
            g_quats[i, 3] = (gz - z * dot) / qn
        else:
            g_quats[i, 0] = gw / QUAT_EPS
            g_quats[i, 1] = gx / QUAT_EPS
            g_quats[i, 2] = gy / QUAT_EPS
            g_quats[i, 3] = gz / QUAT_EPS
        # J -> t (ux, uy clamped: gradient only inside the clamp range, as torch.clamp)
        tz2 = tz * tz
        g_tz = g_depths[i] + gj00 * (-fx / tz2) + gj02 * (fx * ux / tz2) + gj11 * (-fy / tz2) + gj12 * (fy * uy / tz2)
        g_tx = 0.0
        g_ty = 0.0
        g_ux = gj02 * (-fx / tz)
        g_uy = gj12 * (-fy / tz)
        if -lim[0] <= rx <= lim[1]:
            g_tx += g_ux / tz
            g_tz += -g_ux * tx / tz2
        if -lim[2] <= ry <= lim[3]:
            g_ty += g_uy / tz
            g_tz += -g_uy * ty / tz2
        gmx, gmy = g_means2d[i, 0], g_means2d[i, 1]
        g_tx += gmx * fx / tz
        g_ty += gmy * fy / tz
        g_tz += -gmx * fx * tx / tz2 - gmy * fy * ty / tz2
        for k in range(3):
            g_means[i, k] = W[0, k] * g_tx + W[1, k] * g_ty + W[2, k] * g_tz
