"""Numba kernels of the tile-binned rasterizer: set-up and forward (the backward: `cpu_raster_backward`).

Same semantics as `rasterize_ref.py` (per-pixel footprint square, alpha skip and cap, stop before T < 1e-4),
organised for speed:
- one global depth sort; tile lists are filled in that order (no per-tile sort);
- each Gaussian's pixel box is the footprint square cut to the bounding box of the ellipse where
  its alpha can reach 1/255 (`footprints`, once per render): tiles and rows outside it are never
  visited (for a haze of opacity 0.1 that box is 2.55 sigma wide instead of 3 sigma);
- within a tile, Gaussians are visited front to back, and for each only the pixels of each row
  where its alpha can reach 1/255 (the roots of a quadratic, widened by a pixel and then tested
  exactly per pixel, so the result is the same as testing every pixel); rows whose pixels have all
  stopped (transmittance below T_MIN) are skipped without computing their span;
- exp(power) along a row by recurrence (two multiplications per pixel), and the start of each row
  from the previous row's by a cursor moved with constant factors (`_cursor_start`): about one
  exp per (tile, Gaussian) instead of two per row, the factors in float64 whatever the inputs;
- the forward keeps each row's columns and start values (the row store, ~24 bytes a row), so the
  backward sets up no row and sees bit for bit the alphas the forward saw;
- the per-row loops are specialised for one channel (`C` a literal at each call site);
- per-thread buffers for max_weight and gradients, reduced at the end (no atomics);
- one to three colour channels (colours and gradients as scalars in registers, no channel loop).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from recon.raster.types import ALPHA_MAX, ALPHA_MIN, T_MIN

# Tiles of this backend (its results do not depend on them): wide, so a small Gaussian straddles fewer
# tiles (each straddle repeats its row set-up), and short enough to give 2 threads ~190 tiles to share.
TILE_W, TILE_H = 32, 16
# A row's start follows from the previous row's by moving the cursor at most this many columns;
# further (or after a skipped row) it is computed afresh with exps.
MAX_SHIFT = 3

_opts = dict(cache=True, nogil=True, fastmath={"contract"}, error_model="numpy")


@numba.njit(**_opts)
def _gaussian_setup(a, b, c, k):
    """Per-Gaussian constants of the row scan: the quadratic's coefficients.

    Alpha can reach 1/255 where d^T Q d <= k = 2 log(255 opacity); for a row at offset dy that is
    a dx^2 + 2 b dy dx + (c dy^2 - k) <= 0, with discriminant k1 dy^2 + k2 (k1 = b^2 - a c, k2 = a k).
    """
    return b * b - a * c, a * k, 1.0 / a


@numba.njit(parallel=True, **_opts)
def footprints(means2d, conics, radii, opacities, width, height):
    """Pixel boxes [N, 4] (u0, u1, v0, v1; empty when u0 > u1) of the pixels each Gaussian can touch:
    the footprint square |d| <= radius cut to the bounding box of the ellipse d^T Q d <= 2 log(o / (1/255))
    (Q the conic) outside which alpha = o exp(-d^T Q d / 2) < 1/255. The ellipse's half-widths are
    sqrt(k (Q^-1)_xx) and sqrt(k (Q^-1)_yy), widened by 1e-3 px against rounding.

    Also returns the row scan's constants [N, 8] (k1, k2, 1/a, exp(-a): see `_gaussian_setup`; the
    cursor's exp(a), exp(-b), exp(b), exp(-c): see `_cursor_start`), so the tiles do not recompute
    a log and exps per Gaussian each; k serves both.
    """
    n = means2d.shape[0]
    boxes = np.empty((n, 4), np.int64)
    consts = np.zeros((n, 8), np.float64)
    for g in numba.prange(n):
        boxes[g, 0], boxes[g, 1], boxes[g, 2], boxes[g, 3] = 1, 0, 1, 0
        # in float64 whatever the inputs' dtype: the row and cursor recurrences multiply these factors
        op, a, b, c = (np.float64(opacities[g]), np.float64(conics[g, 0]), np.float64(conics[g, 1]),
                       np.float64(conics[g, 2]))
        r = float(radii[g])
        if radii[g] <= 0 or not (op >= ALPHA_MIN and a > 0.0):
            continue
        k = 2.0 * math.log(op / ALPHA_MIN)
        consts[g, 0], consts[g, 1], consts[g, 2] = _gaussian_setup(a, b, c, k)
        consts[g, 3] = math.exp(-a)
        consts[g, 4], consts[g, 5], consts[g, 6], consts[g, 7] = math.exp(a), math.exp(-b), math.exp(b), math.exp(-c)
        hx = hy = r
        det = a * c - b * b
        if det > 0.0:
            hx = min(r, math.sqrt(k * c / det) + 1e-3)
            hy = min(r, math.sqrt(k * a / det) + 1e-3)
        mx, my = means2d[g, 0], means2d[g, 1]
        u0 = max(int(math.ceil(mx - hx - 0.5)), 0)
        u1 = min(int(math.floor(mx + hx - 0.5)), width - 1)
        v0 = max(int(math.ceil(my - hy - 0.5)), 0)
        v1 = min(int(math.floor(my + hy - 0.5)), height - 1)
        if u0 <= u1 and v0 <= v1:
            boxes[g, 0], boxes[g, 1], boxes[g, 2], boxes[g, 3] = u0, u1, v0, v1
    return boxes, consts


@numba.njit(**_opts)
def _tile_range(g, boxes):
    """Tiles [tx0, tx1] x [ty0, ty1] touched by Gaussian g's pixel box (empty when tx0 > tx1)."""
    if boxes[g, 0] > boxes[g, 1]:
        return 1, 0, 1, 0
    return boxes[g, 0] // TILE_W, boxes[g, 1] // TILE_W, boxes[g, 2] // TILE_H, boxes[g, 3] // TILE_H


@numba.njit(**_opts)
def _rows_in_tile(g, boxes, y0, y1):
    """Rows [vlo, vhi] of Gaussian g's pixel box within a tile's rows [y0, y1]: the rows the row
    store holds for the pair (the offsets of `bin_tiles` and both kernels' indices agree on it)."""
    return max(y0, boxes[g, 2]), min(y1, boxes[g, 3])


@numba.njit(**_opts)
def bin_tiles(boxes, order, width, height):
    """CSR tile lists: Gaussians whose pixel box overlaps each tile, in `order` (front to back), and
    for each list entry k the first of its rows in the row store (row_offsets [len(lists) + 1]):
    one row per pixel row of the Gaussian's box within the tile."""
    tiles_x = (width + TILE_W - 1) // TILE_W
    tiles_y = (height + TILE_H - 1) // TILE_H
    counts = np.zeros(tiles_x * tiles_y + 1, np.int64)
    for g in order:
        tx0, tx1, ty0, ty1 = _tile_range(g, boxes)
        for ty in range(ty0, ty1 + 1):
            for tx in range(tx0, tx1 + 1):
                counts[ty * tiles_x + tx + 1] += 1
    for k in range(1, counts.shape[0]):
        counts[k] += counts[k - 1]
    fill = counts[:-1].copy()
    lists = np.empty(counts[-1], np.int64)
    for g in order:
        tx0, tx1, ty0, ty1 = _tile_range(g, boxes)
        for ty in range(ty0, ty1 + 1):
            for tx in range(tx0, tx1 + 1):
                t = ty * tiles_x + tx
                lists[fill[t]] = g
                fill[t] += 1
    # rows of each (tile, Gaussian) pair in the row store the forward fills and the backward reads
    row_offsets = np.empty(counts[-1] + 1, np.int64)
    row_offsets[0] = 0
    for t in range(tiles_x * tiles_y):
        y0 = (t // tiles_x) * TILE_H
        y1 = min(y0 + TILE_H, height) - 1
        for k in range(counts[t], counts[t + 1]):
            vlo, vhi = _rows_in_tile(lists[k], boxes, y0, y1)
            row_offsets[k + 1] = row_offsets[k] + vhi - vlo + 1
    return counts, lists, row_offsets


@numba.njit(inline="always", **_opts)
def _row_spans(i0, i1, dy0, mx, b, k1, k2, inv_a, u_lo, u_hi, x0, x1, span_lo, span_hi):
    """Columns [lo, hi] of the rows i0..i1 of a tile (dy0: row 0's offset from the centre) where alpha
    may reach 1/255, into span_lo / span_hi: the roots of the quadratic widened by a pixel (every
    pixel is then tested exactly), within the pixel box's columns and the tile; lo > hi for an
    empty row. Branch-free, so that the loop vectorises."""
    for i in range(i0, i1 + 1):
        dy = dy0 + i
        disc = k1 * dy * dy + k2
        sq = math.sqrt(max(disc, 0.0))
        lo = max(int(math.floor(mx + (-b * dy - sq) * inv_a - 0.5)) - 1, u_lo, x0)
        hi = min(int(math.ceil(mx + (-b * dy + sq) * inv_a - 0.5)) + 1, u_hi, x1)
        span_lo[i] = lo
        span_hi[i] = hi if disc >= 0.0 else lo - 1


@numba.njit(**_opts)
def _row_start(lo, mx, dy, a, b, c):
    """exp(power) at column lo of a row and its ratio to the next column.

    power(dx) = -0.5 (a dx^2 + c dy^2) - b dx dy, so G(dx + 1) / G(dx) = exp(-a dx - a / 2 - b dy),
    and that ratio itself changes by exp(-a) per column: two multiplications per pixel instead of
    an exp (relative drift ~1e-15 over a row in float64).
    """
    dx = lo + 0.5 - mx
    G = math.exp(-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy)
    return G, math.exp(-a * dx - 0.5 * a - b * dy)


@numba.njit(**_opts)
def _cursor_start(lo, mx, dy, a, b, c):
    """exp(power) at column lo of a row, its ratio to the next column and to the same column of the
    next row: G(dx, dy + 1) / G(dx, dy) = exp(-c dy - c / 2 - b dx).

    Moving the cursor a row down multiplies G by that ratio, the ratio by exp(-c) and the column
    ratio by exp(-b); a column right multiplies G by the column ratio, that by exp(-a) and the row
    ratio by exp(-b) (left: the inverses). Each ratio stays within exp(+-|Q d| - 3.4) of one near
    the ellipse (|Q| <= 1 / LOWPASS), so nothing underflows on the cursor's short moves, and the
    drift is ~1e-16 relative per multiplication.
    """
    dx = lo + 0.5 - mx
    G, step = _row_start(lo, mx, dy, a, b, c)
    return G, step, math.exp(-c * dy - 0.5 * c - b * dx)


@numba.njit(**_opts)
def _colour3(colors, g, C):
    """Gaussian g's colour as three scalars (channels >= C are zero): the kernels handle 1-3 channels."""
    return colors[g, 0], colors[g, 1] if C > 1 else 0.0, colors[g, 2] if C > 2 else 0.0


@numba.njit(**_opts)
def _tile_box(tile, tiles_x, width, height):
    """Pixel box [x0, x1] x [y0, y1] of a tile, its width and pixel count."""
    x0 = (tile % tiles_x) * TILE_W
    y0 = (tile // tiles_x) * TILE_H
    x1 = min(x0 + TILE_W, width) - 1
    y1 = min(y0 + TILE_H, height) - 1
    return x0, x1, y0, y1, x1 - x0 + 1, (x1 - x0 + 1) * (y1 - y0 + 1)


@numba.njit(**_opts)
def _gaussian_in_tile(g, means2d, conics, boxes, consts, opacities, y0, y1):
    """Everything the row scan of Gaussian g over a tile's rows [y0, y1] needs (binned Gaussians
    only: their alpha can reach 1/255 somewhere)."""
    vlo, vhi = _rows_in_tile(g, boxes, y0, y1)
    return (means2d[g, 0], means2d[g, 1], conics[g, 0], conics[g, 1], conics[g, 2], opacities[g],
            boxes[g, 0], boxes[g, 1], consts[g, 0], consts[g, 1], consts[g, 2], consts[g, 3], vlo, vhi)


@numba.njit(inline="always", **_opts)
def _blend_row(C, lo, hi, base, G, step, q, op, cg0, cg1, cg2, dg, idx, T, acc, dep, last, done, wmax):
    """Composite one Gaussian over the pixels [lo, hi] of a row (flat index base + u). C is a literal
    at each call site (1, or 3 for two and three channels: a missing colour is zero), so the one-
    channel models skip two colour planes. Returns the largest weight and the
    number of pixels that stopped."""
    n_stopped = 0
    for u in range(lo, hi + 1):
        p = base + u
        g_here = G
        G *= step        # exp(power) along the row by recurrence: no exp per pixel
        step *= q
        if done[p]:
            continue
        al = min(ALPHA_MAX, op * g_here)
        if al < ALPHA_MIN:
            continue
        test_t = T[p] * (1.0 - al)
        if test_t < T_MIN:
            done[p] = True
            n_stopped += 1
            continue
        w = al * T[p]
        acc[0, p] += w * cg0
        if C > 1:
            acc[1, p] += w * cg1
        if C > 2:
            acc[2, p] += w * cg2
        dep[p] += w * dg
        T[p] = test_t
        last[p] = idx
        wmax = max(wmax, w)      # branch-free: the comparison is unpredictable
    return wmax, n_stopped


@numba.njit(parallel=True, **_opts)
def raster_forward(means2d, conics, depths, boxes, consts, opacities, colors, background, width, height,
                   counts, lists, row_offsets, image, alpha_img, depth_img, final_t, n_contrib, max_w_thread,
                   row_span, row_start):
    """Also fills the row store for the backward: for each row it scans, the columns [lo, hi]
    (row_span [R, 2]) and exp(power) at lo with its ratio to the next column (row_start [R, 2])."""
    tiles_x = (width + TILE_W - 1) // TILE_W
    n_tiles = counts.shape[0] - 1
    C = colors.shape[1]
    for tile in numba.prange(n_tiles):
        tid = numba.get_thread_id()
        x0, x1, y0, y1, tw, npx = _tile_box(tile, tiles_x, width, height)
        T = np.ones(npx)
        acc = np.zeros((3, npx))       # colour planes (channels >= C stay zero)
        dep = np.zeros(npx)
        last = np.zeros(npx, np.int64)
        done = np.zeros(npx, np.bool_)
        row_live = np.full(y1 - y0 + 1, tw)   # pixels of each row still compositing
        span_lo = np.empty(TILE_H, np.int64)  # the current Gaussian's row spans in this tile
        span_hi = np.empty(TILE_H, np.int64)
        n_done = 0
        start, stop = counts[tile], counts[tile + 1]
        for k in range(start, stop):
            if n_done == npx:
                break
            g = lists[k]
            mx, my, a, b, c, op, u_lo, u_hi, k1, k2, inv_a, q, vlo, vhi = _gaussian_in_tile(
                g, means2d, conics, boxes, consts, opacities, y0, y1)
            inv_q, eb, inv_eb, ec = consts[g, 4], consts[g, 5], consts[g, 6], consts[g, 7]
            cg0, cg1, cg2 = _colour3(colors, g, C)
            dg = depths[g]
            wmax = 0.0
            r0 = row_offsets[k] - vlo
            # exp(power) at the start of each row follows from the previous row's: a cursor at (cu, cv)
            # carries G, its ratio to the next column (step) and to the next row (down), each updated by
            # constant factors as it moves (see `_cursor_start`); fresh exps only where rows do not follow
            cv = -2
            cu = 0
            G = step = down = 0.0
            _row_spans(vlo - y0, vhi - y0, y0 + 0.5 - my, mx, b, k1, k2, inv_a, u_lo, u_hi, x0, x1, span_lo, span_hi)
            for v in range(vlo, vhi + 1):
                if row_live[v - y0] == 0:
                    continue
                dy = v + 0.5 - my
                lo, hi = span_lo[v - y0], span_hi[v - y0]
                row_span[r0 + v, 0], row_span[r0 + v, 1] = lo, hi
                if lo > hi:
                    continue
                if cv == v - 1 and abs(lo - cu) <= MAX_SHIFT:
                    G *= down
                    down *= ec
                    step *= eb
                    while cu < lo:
                        G *= step
                        step *= q
                        down *= eb
                        cu += 1
                    while cu > lo:
                        step *= inv_q
                        G /= step
                        down *= inv_eb
                        cu -= 1
                else:
                    G, step, down = _cursor_start(lo, mx, dy, a, b, c)
                    cu = lo
                cv = v
                row_start[r0 + v, 0], row_start[r0 + v, 1] = G, step
                base = (v - y0) * tw - x0
                if C == 1:
                    wmax, n_stopped = _blend_row(1, lo, hi, base, G, step, q, op, cg0, cg1, cg2, dg, k - start + 1,
                                                 T, acc, dep, last, done, wmax)
                else:
                    wmax, n_stopped = _blend_row(3, lo, hi, base, G, step, q, op, cg0, cg1, cg2, dg, k - start + 1,
                                                 T, acc, dep, last, done, wmax)
                n_done += n_stopped
                row_live[v - y0] -= n_stopped
            if wmax > max_w_thread[tid, g]:
                max_w_thread[tid, g] = wmax
        for v in range(y0, y1 + 1):
            for u in range(x0, x1 + 1):
                p = (v - y0) * tw + (u - x0)
                for ch in range(C):
                    image[v, u, ch] = acc[ch, p] + T[p] * background[ch]
                alpha_img[v, u] = 1.0 - T[p]
                depth_img[v, u] = dep[p]
                final_t[v, u] = T[p]
                n_contrib[v, u] = last[p]
