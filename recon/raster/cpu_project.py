"""Numba kernels of the EWA projection, forward and hand-written backward (see projection.py)."""
from __future__ import annotations

import math

import numba
import numpy as np

from recon.raster.projection import QUAT_EPS
from recon.raster.types import LOWPASS, NEAR_PLANE

_opts = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


@numba.njit(**_opts)
def _rotation(q0, q1, q2, q3):
    n = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    d = max(n, QUAT_EPS)
    w, x, y, z = q0 / d, q1 / d, q2 / d, q3 / d
    R = np.empty((3, 3))
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - w * z)
    R[0, 2] = 2 * (x * z + w * y)
    R[1, 0] = 2 * (x * y + w * z)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - w * x)
    R[2, 0] = 2 * (x * z - w * y)
    R[2, 1] = 2 * (y * z + w * x)
    R[2, 2] = 1 - 2 * (x * x + y * y)
    return R, w, x, y, z, n


@numba.njit(**_opts)
def _camera_cov(Wr, R, s):
    """V = Wr R S S^T R^T Wr^T and M = R S."""
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            M[i, j] = R[i, j] * s[j]
    cov = M @ M.T
    return Wr @ cov @ Wr.T, M


@numba.njit(parallel=True, **_opts)
def project_forward(means, quats, scales, W, fx, fy, cx, cy, width, height, means2d, conics, depths, radii):
    Wr = W[:3, :3].astype(np.float64)
    lim_x = 1.3 * (0.5 * width / fx)
    lim_y = 1.3 * (0.5 * height / fy)
    for i in numba.prange(means.shape[0]):
        t = np.empty(3)
        for r in range(3):
            t[r] = W[r, 0] * means[i, 0] + W[r, 1] * means[i, 1] + W[r, 2] * means[i, 2] + W[r, 3]
        tz = t[2]
        depths[i] = tz
        if not tz >= NEAR_PLANE:
            radii[i] = 0
            means2d[i, 0] = means2d[i, 1] = 0.0
            conics[i, 0] = conics[i, 1] = conics[i, 2] = 0.0
            continue
        ux = min(max(t[0] / tz, -lim_x), lim_x)
        uy = min(max(t[1] / tz, -lim_y), lim_y)
        J = np.zeros((2, 3))
        J[0, 0] = fx / tz
        J[0, 2] = -fx * ux / tz
        J[1, 1] = fy / tz
        J[1, 2] = -fy * uy / tz
        R, _, _, _, _, _ = _rotation(quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3])
        s = np.empty(3)
        s[0], s[1], s[2] = scales[i, 0], scales[i, 1], scales[i, 2]
        V, _ = _camera_cov(Wr, R, s)
        cov2 = J @ V @ J.T
        sa = cov2[0, 0] + LOWPASS
        sb = cov2[0, 1]
        sc = cov2[1, 1] + LOWPASS
        det = sa * sc - sb * sb
        conics[i, 0] = sc / det
        conics[i, 1] = -sb / det
        conics[i, 2] = sa / det
        means2d[i, 0] = fx * t[0] / tz + cx
        means2d[i, 1] = fy * t[1] / tz + cy
        mid = 0.5 * (sa + sc)
        lam = mid + math.sqrt(max(mid * mid - det, 0.1))
        r = math.ceil(3.0 * math.sqrt(lam))
        radii[i] = np.int32(r) if math.isfinite(r) and r < 2.0e9 else 0


@numba.njit(parallel=True, **_opts)
def project_backward(means, quats, scales, W, fx, fy, width, height, radii, g_means2d, g_conics, g_depths,
                     g_means, g_quats, g_scales):
    Wr = W[:3, :3].astype(np.float64)
    lim_x = 1.3 * (0.5 * width / fx)
    lim_y = 1.3 * (0.5 * height / fy)
    for i in numba.prange(means.shape[0]):
        for k in range(3):
            g_means[i, k] = 0.0
            g_scales[i, k] = 0.0
        for k in range(4):
            g_quats[i, k] = 0.0
        if radii[i] <= 0:
            continue
        t = np.empty(3)
        for r in range(3):
            t[r] = W[r, 0] * means[i, 0] + W[r, 1] * means[i, 1] + W[r, 2] * means[i, 2] + W[r, 3]
        tx, ty, tz = t[0], t[1], t[2]
        rx, ry = tx / tz, ty / tz
        ux = min(max(rx, -lim_x), lim_x)
        uy = min(max(ry, -lim_y), lim_y)
        J = np.zeros((2, 3))
        J[0, 0] = fx / tz
        J[0, 2] = -fx * ux / tz
        J[1, 1] = fy / tz
        J[1, 2] = -fy * uy / tz
        R, w, x, y, z, qn = _rotation(quats[i, 0], quats[i, 1], quats[i, 2], quats[i, 3])
        s = np.empty(3)
        s[0], s[1], s[2] = scales[i, 0], scales[i, 1], scales[i, 2]
        V, M = _camera_cov(Wr, R, s)
        cov2 = J @ V @ J.T
        sa = cov2[0, 0] + LOWPASS
        sb = cov2[0, 1]
        sc = cov2[1, 1] + LOWPASS
        det = sa * sc - sb * sb
        d2 = det * det
        ga, gb, gc = g_conics[i, 0], g_conics[i, 1], g_conics[i, 2]
        # conic = (sc, -sb, sa) / det
        g_sa = ga * (-sc * sc / d2) + gb * (sb * sc / d2) + gc * (1.0 / det - sa * sc / d2)
        g_sc = ga * (1.0 / det - sc * sa / d2) + gb * (sb * sa / d2) + gc * (-sa * sa / d2)
        g_sb = ga * (2.0 * sb * sc / d2) + gb * (-1.0 / det - 2.0 * sb * sb / d2) + gc * (2.0 * sa * sb / d2)
        Gs = np.empty((2, 2))
        Gs[0, 0] = 2.0 * g_sa
        Gs[0, 1] = g_sb
        Gs[1, 0] = g_sb
        Gs[1, 1] = 2.0 * g_sc
        gJ = Gs @ J @ V                                  # dL/dJ
        gM = Wr.T @ (J.T @ Gs @ J) @ Wr @ M              # dL/dM, M = R S
        for j in range(3):
            acc = 0.0
            for r in range(3):
                acc += gM[r, j] * R[r, j]
            g_scales[i, j] = acc
        G = np.empty((3, 3))
        for r in range(3):
            for j in range(3):
                G[r, j] = gM[r, j] * s[j]
        gw = 2 * (-z * G[0, 1] + y * G[0, 2] + z * G[1, 0] - x * G[1, 2] - y * G[2, 0] + x * G[2, 1])
        gx = 2 * (y * G[0, 1] + z * G[0, 2] + y * G[1, 0] - 2 * x * G[1, 1] - w * G[1, 2] + z * G[2, 0]
                  + w * G[2, 1] - 2 * x * G[2, 2])
        gy = 2 * (-2 * y * G[0, 0] + x * G[0, 1] + w * G[0, 2] + x * G[1, 0] + z * G[1, 2] - w * G[2, 0]
                  + z * G[2, 1] - 2 * y * G[2, 2])
        gz = 2 * (-2 * z * G[0, 0] - w * G[0, 1] + x * G[0, 2] + w * G[1, 0] - 2 * z * G[1, 1] + y * G[1, 2]
                  + x * G[2, 0] + y * G[2, 1])
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
        g_tz = g_depths[i]
        g_tz += gJ[0, 0] * (-fx / (tz * tz)) + gJ[0, 2] * (fx * ux / (tz * tz))
        g_tz += gJ[1, 1] * (-fy / (tz * tz)) + gJ[1, 2] * (fy * uy / (tz * tz))
        g_tx = 0.0
        g_ty = 0.0
        g_ux = gJ[0, 2] * (-fx / tz)
        g_uy = gJ[1, 2] * (-fy / tz)
        if -lim_x <= rx <= lim_x:
            g_tx += g_ux / tz
            g_tz += -g_ux * tx / (tz * tz)
        if -lim_y <= ry <= lim_y:
            g_ty += g_uy / tz
            g_tz += -g_uy * ty / (tz * tz)
        gmx, gmy = g_means2d[i, 0], g_means2d[i, 1]
        g_tx += gmx * fx / tz
        g_ty += gmy * fy / tz
        g_tz += -gmx * fx * tx / (tz * tz) - gmy * fy * ty / (tz * tz)
        for k in range(3):
            g_means[i, k] = W[0, k] * g_tx + W[1, k] * g_ty + W[2, k] * g_tz
