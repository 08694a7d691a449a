"""Numba kernel of the tile-binned rasterizer's hand-written backward (set-up and forward: `cpu_raster`).

It visits each tile's Gaussians back to front over the forward's rows (its row store: the same
columns and start values, bit for bit) and runs the standard reverse compositing recurrence per
pixel, skipping rows where every pixel stopped before the current Gaussian. Per row it sums the
moments of dL/dpower and forms the mean and conic gradients from them once per row.
"""
from __future__ import annotations

import numba
import numpy as np

from recon.raster.cpu_raster import TILE_W, _colour3, _opts, _rows_in_tile, _tile_box
from recon.raster.types import ALPHA_MAX, ALPHA_MIN


@numba.njit(inline="always", **_opts)
def _grad_row(C, lo, hi, base, G_next, step, q, idx, op, dx, cg0, cg1, cg2, dg,
              T, last, S, gimg, gdpx, gfin):
    """The reverse compositing recurrence of one Gaussian over the pixels [lo, hi] of a row (dx: the
    column offset of lo from its centre). Returns its sums over the row: colour (3), depth and
    opacity gradients, and the moments sum(d), sum(d dx), sum(d dx^2) of d = dL/dpower, from
    which the caller forms the mean and conic gradients. C is a literal at each call site (1 or 3;
    two channels take the three-channel path, the third colour and image gradient being zero)."""
    r_c0 = r_c1 = r_c2 = r_dep = r_op = s0 = s1 = s2 = 0.0
    for u in range(lo, hi + 1):
        p = base + u
        G = G_next
        G_next *= step
        step *= q
        dxu = dx
        dx += 1.0
        if idx >= last[p]:
            continue
        al = min(ALPHA_MAX, op * G)
        if al < ALPHA_MIN:
            continue
        inv_keep = 1.0 / (1.0 - al)
        Tp = T[p] * inv_keep               # transmittance in front of g
        T[p] = Tp
        wgt = al * Tp
        g0, gd = gimg[0, p], gdpx[p]
        here = cg0 * g0 + dg * gd
        r_c0 += wgt * g0
        if C > 1:
            g1 = gimg[1, p]
            here += cg1 * g1
            r_c1 += wgt * g1
        if C > 2:
            g2 = gimg[2, p]
            here += cg2 * g2
            r_c2 += wgt * g2
        behind = S[p]
        S[p] = behind + al * (here - behind)      # what lies behind the next Gaussian in front
        dl_dal = (here - behind) * Tp + gfin[p] * inv_keep
        r_dep += wgt * gd
        if op * G > ALPHA_MAX:
            continue                       # alpha is capped: no gradient to opacity or shape
        r_op += G * dl_dal
        d = op * G * dl_dal
        s0 += d
        s1 += d * dxu
        s2 += d * dxu * dxu
    return r_c0, r_c1, r_c2, r_dep, r_op, s0, s1, s2


@numba.njit(parallel=True, **_opts)
def raster_backward(means2d, conics, depths, boxes, consts, opacities, colors, background, width, height,
                    counts, lists, row_offsets, row_span, row_start, final_t, n_contrib, g_image, g_alpha, g_depth,
                    g_m2d, g_con, g_dep, g_op, g_col, g_bg):
    """Per-thread gradient buffers g_* [threads, N, ...] and g_bg [threads, C] are accumulated into.
    The rows are the forward's (its row store): the same columns and the same exp(power) bit for bit,
    so both passes agree on every alpha test, and no row is set up twice."""
    tiles_x = (width + TILE_W - 1) // TILE_W
    n_tiles = counts.shape[0] - 1
    C = colors.shape[1]
    for tile in numba.prange(n_tiles):
        tid = numba.get_thread_id()
        x0, x1, y0, y1, tw, npx = _tile_box(tile, tiles_x, width, height)
        T = np.empty(npx)
        last = np.empty(npx, np.int64)
        # Colour and depth composited behind the current Gaussian enter the gradient only through their
        # dot product with the pixel's (fixed) image and depth gradient, and that dot product follows the
        # same linear recurrence, updated as each contributor is passed (back to front):
        # S <- alpha H + (1 - alpha) S, with H = colour . dL/dimage + depth * dL/ddepth of that
        # contributor. So a pixel's state is a few scalars, whatever C.
        S = np.zeros(npx)
        max_last = 0
        row_last = np.zeros(y1 - y0 + 1, np.int64)   # per row: the largest last contributor + 1
        gimg = np.zeros((3, npx))      # the tile's image gradient planes (channels >= C stay zero)
        gdpx = np.empty(npx)           # depth gradient
        gfin = np.empty(npx)           # (dL/dalpha - background . dL/dimage) x final transmittance
        for v in range(y0, y1 + 1):
            for u in range(x0, x1 + 1):
                p = (v - y0) * tw + (u - x0)
                T[p] = final_t[v, u]
                last[p] = n_contrib[v, u]
                row_last[v - y0] = max(row_last[v - y0], last[p])
                max_last = max(max_last, last[p])
                bg_dot = 0.0
                for ch in range(C):
                    gimg[ch, p] = g_image[v, u, ch]
                    g_bg[tid, ch] += final_t[v, u] * g_image[v, u, ch]
                    bg_dot += background[ch] * g_image[v, u, ch]
                gdpx[p] = g_depth[v, u]
                gfin[p] = (g_alpha[v, u] - bg_dot) * final_t[v, u]
        start = counts[tile]
        for k in range(start + max_last - 1, start - 1, -1):
            g = lists[k]
            idx = k - start
            mx, my, a, b, c, op = means2d[g, 0], means2d[g, 1], conics[g, 0], conics[g, 1], conics[g, 2], opacities[g]
            q = consts[g, 3]
            vlo, vhi = _rows_in_tile(g, boxes, y0, y1)
            cg0, cg1, cg2 = _colour3(colors, g, C)
            dg = depths[g]
            # this Gaussian's gradient over the tile, summed locally and stored once
            gdep = gop = gmx = gmy = gca = gcb = gcc = gc0 = gc1 = gc2 = 0.0
            r0 = row_offsets[k] - vlo
            for v in range(vlo, vhi + 1):
                if idx >= row_last[v - y0]:
                    continue
                lo, hi = row_span[r0 + v, 0], row_span[r0 + v, 1]
                if lo > hi:
                    continue
                dy = v + 0.5 - my
                base = (v - y0) * tw - x0
                G0, step = row_start[r0 + v, 0], row_start[r0 + v, 1]
                if C == 1:
                    sums = _grad_row(1, lo, hi, base, G0, step, q, idx, op, lo + 0.5 - mx, cg0, cg1, cg2, dg,
                                     T, last, S, gimg, gdpx, gfin)
                else:
                    sums = _grad_row(3, lo, hi, base, G0, step, q, idx, op, lo + 0.5 - mx, cg0, cg1, cg2, dg,
                                     T, last, S, gimg, gdpx, gfin)
                r_c0, r_c1, r_c2, r_dep, r_op, s0, s1, s2 = sums
                gc0 += r_c0
                gc1 += r_c1
                gc2 += r_c2
                gdep += r_dep
                gop += r_op
                # the shape gradients from the row's moments of dL/dpower (dy is the row's constant)
                gmx += a * s1 + b * dy * s0
                gmy += c * dy * s0 + b * s1
                gca += -0.5 * s2
                gcb += -dy * s1
                gcc += -0.5 * dy * dy * s0
            g_col[tid, g, 0] += gc0
            if C > 1:
                g_col[tid, g, 1] += gc1
            if C > 2:
                g_col[tid, g, 2] += gc2
            g_dep[tid, g] += gdep
            g_op[tid, g] += gop
            g_m2d[tid, g, 0] += gmx
            g_m2d[tid, g, 1] += gmy
            g_con[tid, g, 0] += gca
            g_con[tid, g, 1] += gcb
            g_con[tid, g, 2] += gcc
