"""The `cpu` backend: numba kernels wrapped as autograd Functions (projection, then rasterization).

Two stages like gsplat, so `means2d` is a real intermediate tensor: call `means2d.retain_grad()`
before backward to read the screen-space gradient that densification uses.
"""
from __future__ import annotations

import numba
import numpy as np
import torch

from recon.raster import cpu_project as P
from recon.raster import cpu_raster as K
from recon.raster import cpu_raster_backward as KB


def _np(t: torch.Tensor) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy())


class _Project(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, scales, W, K_mat, width, height):
        m, q, s, w = _np(means), _np(quats), _np(scales), _np(W).astype(np.float64)
        k = _np(K_mat).astype(np.float64)
        N = m.shape[0]
        means2d = np.empty((N, 2), m.dtype)
        conics = np.empty((N, 3), m.dtype)
        depths = np.empty(N, m.dtype)
        radii = np.empty(N, np.int32)
        if N:
            P.project_forward(m, q, s, w, k[0, 0], k[1, 1], k[0, 2], k[1, 2], width, height,
                              means2d, conics, depths, radii)
        ctx.save_for_backward(means, quats, scales)
        ctx.cam = (w, k, width, height)
        ctx.radii = radii
        radii_t = torch.from_numpy(radii)
        ctx.mark_non_differentiable(radii_t)
        return torch.from_numpy(means2d), torch.from_numpy(conics), torch.from_numpy(depths), radii_t

    @staticmethod
    def backward(ctx, g_means2d, g_conics, g_depths, _g_radii):
        means, quats, scales = ctx.saved_tensors
        w, k, width, height = ctx.cam
        m, q, s = _np(means), _np(quats), _np(scales)
        N = m.shape[0]
        g_m = np.zeros((N, 3), m.dtype)
        g_q = np.zeros((N, 4), m.dtype)
        g_s = np.zeros((N, 3), m.dtype)
        if N:
            P.project_backward(m, q, s, w, k[0, 0], k[1, 1], k[0, 2], k[1, 2], width, height, ctx.radii,
                               _np(g_means2d).astype(m.dtype), _np(g_conics).astype(m.dtype),
                               _np(g_depths).astype(m.dtype), g_m, g_q, g_s)
        return torch.from_numpy(g_m), torch.from_numpy(g_q), torch.from_numpy(g_s), None, None, None, None


def project_cpu(means, quats, scales, camera):
    return _Project.apply(means, quats, scales, camera.world_to_cam, camera.K, camera.width, camera.height)


class _Rasterize(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means2d, conics, depths, opacities, colors, background, radii, width, height):
        m2d, con, dep, op, col, bg = (_np(x) for x in (means2d, conics, depths, opacities, colors, background))
        rad = _np(radii).astype(np.int32)
        dtype = m2d.dtype
        N, C = col.shape
        order = np.argsort(dep, kind="stable").astype(np.int64)
        boxes, consts = K.footprints(m2d, con, rad, op, width, height)
        counts, lists, row_offsets = K.bin_tiles(boxes, order, width, height)
        image = np.empty((height, width, C), dtype)
        alpha = np.empty((height, width), dtype)
        depth = np.empty((height, width), dtype)
        final_t = np.empty((height, width), dtype)
        n_contrib = np.empty((height, width), np.int64)
        threads = numba.get_num_threads()
        max_w = np.zeros((threads, N), dtype)
        col, bg = col.astype(dtype, copy=False), bg.astype(dtype, copy=False)
        n_rows = row_offsets[-1]
        row_span = np.empty((n_rows, 2), np.int32)     # the forward's row scans, for the backward
        row_start = np.empty((n_rows, 2), np.float64)
        K.raster_forward(m2d, con, dep, boxes, consts, op, col, bg, width, height,
                         counts, lists, row_offsets, image, alpha, depth, final_t, n_contrib, max_w,
                         row_span, row_start)
        ctx.save_for_backward(means2d, conics, depths, opacities, colors, background)
        ctx.state = (boxes, consts, counts, lists, row_offsets, row_span, row_start, final_t, n_contrib, width, height)
        max_w_t = torch.from_numpy(max_w.max(axis=0) if N else np.zeros(0, dtype))
        ctx.mark_non_differentiable(max_w_t)
        return torch.from_numpy(image), torch.from_numpy(alpha), torch.from_numpy(depth), max_w_t

    @staticmethod
    def backward(ctx, g_image, g_alpha, g_depth, _g_max_w):
        means2d, conics, depths, opacities, colors, background = ctx.saved_tensors
        boxes, consts, counts, lists, row_offsets, row_span, row_start, final_t, n_contrib, width, height = ctx.state
        m2d, con, dep, op, col, bg = (_np(x) for x in (means2d, conics, depths, opacities, colors, background))
        dtype = m2d.dtype
        N, C = col.shape
        threads = numba.get_num_threads()
        g_m2d = np.zeros((threads, N, 2), dtype)
        g_con = np.zeros((threads, N, 3), dtype)
        g_dep = np.zeros((threads, N), dtype)
        g_op = np.zeros((threads, N), dtype)
        g_col = np.zeros((threads, N, C), dtype)
        g_bg = np.zeros((threads, C), dtype)
        col, bg = col.astype(dtype, copy=False), bg.astype(dtype, copy=False)
        KB.raster_backward(m2d, con, dep, boxes, consts, op, col, bg, width, height,
                          counts, lists, row_offsets, row_span, row_start, final_t, n_contrib, _np(g_image).astype(dtype, copy=False),
                          _np(g_alpha).astype(dtype, copy=False), _np(g_depth).astype(dtype, copy=False),
                          g_m2d, g_con, g_dep, g_op, g_col, g_bg)
        out = [torch.from_numpy(x.sum(axis=0)) for x in (g_m2d, g_con, g_dep, g_op, g_col, g_bg)]
        return (*out, None, None, None)


def rasterize_cpu(means2d, conics, depths, radii, opacities, colors, background, width, height):
    if not 1 <= colors.shape[1] <= 3:
        raise ValueError(f"render: the cpu backend renders 1 to 3 colour channels, got {colors.shape[1]} "
                         "(use backend='torch' for more)")
    return _Rasterize.apply(means2d, conics, depths, opacities, colors, background, radii, width, height)
