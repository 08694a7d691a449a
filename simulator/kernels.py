"""Compiled (numba) event generator with the same signature and output as `kernel_ref.emit_events_ref`.

Only the way the work is done differs from the reference; the arithmetic is the same, operation for
operation (no fastmath), so the events are bit-identical:

- pixels are split into contiguous chunks that run in parallel (numba threads; one chunk per
  thread; with one thread the serial twins run, without numba's parallel launch cost), each writing
  events into its own reusable buffer as packed 64-bit keys
  (time offset << 32 | y << 17 | x << 1 | polarity bit: sorting keys by their high half orders
  events by time, and equal times keep row-major pixel order);
- a chunk that would overflow its buffer stops at a pixel boundary (an upper bound on a pixel's
  events is checked before it is processed) and is resumed after the buffer has grown, so no
  pixel state is ever half-updated;
- without refractory period and noise a lean kernel runs (`_emit_clean`); otherwise the general
  one (`_emit_general`), which follows the reference step for step;
- time ordering is a counting sort over the interval's microseconds (at 3000 FPS an interval spans
  only 333 of them): per-chunk histograms, one prefix sum over (time, chunk), a scatter of the
  8-byte keys, then a sequential decode into the EVENT_DTYPE output. Chunks hold increasing pixel ranges, so equal times
  keep pixel order exactly as the reference's stable sort does. Long intervals with few events fall
  back to a stable merge sort of the keys.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from eventio.events import EVENT_DTYPE
from simulator.kernel_ref import CROSS_TOL

# error_model="numpy": float division without Python's zero check (we never divide by zero;
# the check only blocks vectorisation). No fastmath: results must match the reference bit for bit.
_opts = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")
_jit = numba.njit(**_opts)
_pjit = numba.njit(parallel=True, **_opts)

_MAX_OFFSET = (1 << 31) - 1  # time offsets within one frame interval must fit the key's high half


@_jit
def _room_for(n, cap, a_minus_level, inv_c):
    """Whether a pixel whose level is |a_minus_level| from its input fits in the buffer (cheap test first)."""
    if n + 64 <= cap and abs(a_minus_level) * inv_c < 60.0:
        return True
    return n + int((abs(a_minus_level) + CROSS_TOL) * inv_c) + 2 <= cap


@_jit
def _thresholds(c_pos, c_neg, i):
    """(C+, C-, 1 / min(C+, C-)) of pixel i; arrays of length 1 hold one value for all pixels."""
    j = 0 if c_pos.shape[0] == 1 else i
    return c_pos[j], c_neg[j], 1.0 / min(c_pos[j], c_neg[j])


@_jit
def _emit_clean(L0, L1, base, c_pos, c_neg, t0_us, t1_us, width, i_begin, i_end, keys, n):
    """Threshold crossings only (no refractory period, no noise) for pixels [i_begin, i_end).

    Appends keys from index n. Returns (n, i_stop); i_stop < i_end means the buffer is too small
    for pixel i_stop, which is left untouched.
    """
    Df = float(t1_us - t0_us)
    cap = keys.shape[0]
    uniform = c_pos.shape[0] == 1
    cp, cn, inv_c = _thresholds(c_pos, c_neg, 0)
    y = i_begin // width
    x = i_begin - y * width
    for i in range(i_begin, i_end):
        if not uniform:
            cp, cn, inv_c = _thresholds(c_pos, c_neg, i)
        a = float(L0[i])
        b = float(L1[i])
        level = base[i]
        if not _room_for(n, cap, b - level, inv_c):
            return n, i
        yx = (y << 17) | (x << 1)
        x += 1
        if x == width:
            x = 0
            y += 1
        slope = b - a
        if slope > 0.0:
            target = level + cp
            if target <= b + CROSS_TOL:
                scale = Df / slope
                s_now = 0.0
                while target <= b + CROSS_TOL:
                    s = min(max((target - a) * scale, s_now), Df)
                    o = max(int(math.floor(s + 0.5)), 1)
                    keys[n] = (o << 32) | yx | 1
                    n += 1
                    level = target
                    s_now = s
                    target = level + cp
                base[i] = level
        elif slope < 0.0:
            target = level - cn
            if target >= b - CROSS_TOL:
                scale = Df / slope
                s_now = 0.0
                while target >= b - CROSS_TOL:
                    s = min(max((target - a) * scale, s_now), Df)
                    o = max(int(math.floor(s + 0.5)), 1)
                    keys[n] = (o << 32) | yx
                    n += 1
                    level = target
                    s_now = s
                    target = level - cn
                base[i] = level
    return n, i_end


@_jit
def _emit_general(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
                  width, i_begin, i_end, keys, n):
    """Crossings with refractory period and noise events, for pixels [i_begin, i_end).

    Same contract as `_emit_clean`; the logic is the reference's, step for step.
    """
    D = t1_us - t0_us
    Df = float(D)
    cap = keys.shape[0]
    uniform = c_pos.shape[0] == 1
    cp, cn, inv_c = _thresholds(c_pos, c_neg, 0)
    max_refractory_events = (D - 1) // R + 1 if R > 0 else 0
    M = noise_pix.shape[0]
    k_end = np.searchsorted(noise_pix, i_begin)  # cursor into the (pixel, time)-sorted noise events
    y = i_begin // width
    x = i_begin - y * width
    for i in range(i_begin, i_end):
        yx = (y << 17) | (x << 1)
        x += 1
        if x == width:
            x = 0
            y += 1
        if not uniform:
            cp, cn, inv_c = _thresholds(c_pos, c_neg, i)
        a = float(L0[i])
        b = float(L1[i])
        level = base[i]
        k = k_end
        while k_end < M and noise_pix[k_end] == i:
            k_end += 1
        # upper bound on this pixel's events, so the buffer never overflows mid-pixel
        if R > 0:
            if n + max_refractory_events > cap:
                return n, i
        elif n + (k_end - k) > cap or not _room_for(n + (k_end - k), cap, b - level, inv_c):
            return n, i  # (pixel i is resumed from scratch: its noise cursor is found again)
        slope = b - a
        scale = Df / slope if slope != 0.0 else 0.0
        refractory_end = t_ready[i] - t0_us if R > 0 else 0
        blind = refractory_end > 0
        s_now = 0.0
        while True:
            if blind:
                while k < k_end and noise_t[k] - t0_us < refractory_end:
                    k += 1
                if refractory_end > D:
                    level = b
                    break
                level = a + slope * (refractory_end / Df)
                s_now = float(refractory_end)
                blind = False
            s_cross = math.inf
            p_cross = 0
            target = level
            if slope > 0.0:
                target = level + cp
                if target <= b + CROSS_TOL:
                    s_cross = min(max((target - a) * scale, s_now), Df)
                    p_cross = 1
            elif slope < 0.0:
                target = level - cn
                if target >= b - CROSS_TOL:
                    s_cross = min(max((target - a) * scale, s_now), Df)
                    p_cross = -1
            s_noise = float(noise_t[k] - t0_us) if k < k_end else math.inf
            if s_cross == math.inf and s_noise == math.inf:
                break
            if s_noise < s_cross:
                o = noise_t[k] - t0_us
                on = noise_p[k] > 0
                k += 1
            else:
                o = max(int(math.floor(s_cross + 0.5)), 1)
                on = p_cross > 0
                level = target
                s_now = s_cross
            keys[n] = (o << 32) | yx | (1 if on else 0)
            n += 1
            if R > 0:
                t_ready[i] = t0_us + o + R
                refractory_end = o + R
                blind = True
        base[i] = level
    return n, i_end


@_jit
def _emit_chunk(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
                clean, width, starts, stops, keys, counts, c):
    """Continue chunk c from starts[c] to stops[c]; counts[c] and starts[c] advance."""
    if starts[c] < stops[c]:
        if clean:
            n, i_stop = _emit_clean(L0, L1, base, c_pos, c_neg, t0_us, t1_us, width, starts[c], stops[c],
                                    keys[c], counts[c])
        else:
            n, i_stop = _emit_general(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix,
                                      noise_t, noise_p, width, starts[c], stops[c], keys[c], counts[c])
        counts[c] = n
        starts[c] = i_stop


@_jit
def _emit_serial(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
                 clean, width, starts, stops, keys, counts):
    for c in range(starts.shape[0]):
        _emit_chunk(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
                    clean, width, starts, stops, keys, counts, c)


@_pjit
def _emit_parallel(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
                   clean, width, starts, stops, keys, counts):
    for cu in numba.prange(starts.shape[0]):
        _emit_chunk(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
                    clean, width, starts, stops, keys, counts, np.int64(cu))  # prange index is unsigned


@_jit
def _decode(keys, j0, j1, t0_us, out):
    """Packed keys [j0, j1) -> EVENT_DTYPE records at the same positions."""
    for j in range(j0, j1):
        key = keys[j]
        r = out[j]
        r.t = t0_us + (key >> 32)
        r.x = (key >> 1) & 0xFFFF
        r.y = (key >> 17) & 0x7FFF
        r.p = 1 if key & 1 else -1


@_jit
def _histogram(keys, n, hist):
    for j in range(n):
        hist[keys[j] >> 32] += 1


@_jit
def _prefix_over_time_then_chunk(hists):
    """Exclusive prefix sum in (time bin, chunk) order: where each chunk's events of a bin start."""
    acc = 0
    for v in range(hists.shape[1]):
        for c in range(hists.shape[0]):
            h = hists[c, v]
            hists[c, v] = acc
            acc += h


@_jit
def _scatter(keys, n, pos, sorted_keys):
    for j in range(n):
        key = keys[j]
        o = key >> 32
        sorted_keys[pos[o]] = key
        pos[o] += 1


@_jit
def _sort_counting_serial(keys, counts, hists, sorted_keys, t0_us, out):
    for c in range(counts.shape[0]):
        _histogram(keys[c], counts[c], hists[c])
    _prefix_over_time_then_chunk(hists)
    for c in range(counts.shape[0]):
        _scatter(keys[c], counts[c], hists[c], sorted_keys)
    _decode(sorted_keys, 0, out.shape[0], t0_us, out)


@_pjit
def _sort_counting_parallel(keys, counts, hists, sorted_keys, t0_us, out):
    n_chunks = counts.shape[0]
    for cu in numba.prange(n_chunks):
        c = np.int64(cu)
        _histogram(keys[c], counts[c], hists[c])
    _prefix_over_time_then_chunk(hists)
    for cu in numba.prange(n_chunks):
        c = np.int64(cu)
        _scatter(keys[c], counts[c], hists[c], sorted_keys)
    total = out.shape[0]
    for cu in numba.prange(n_chunks):
        c = np.int64(cu)
        _decode(sorted_keys, total * c // n_chunks, total * (c + 1) // n_chunks, t0_us, out)


@_jit
def _sort_merge(keys, counts, t0_us, out):
    """Stable merge sort of the keys by time offset (long intervals with few events)."""
    total = out.shape[0]
    all_keys = np.empty(total, np.int64)
    j0 = 0
    for c in range(counts.shape[0]):
        all_keys[j0:j0 + counts[c]] = keys[c][:counts[c]]
        j0 += counts[c]
    order = np.argsort(all_keys >> 32, kind="mergesort")
    _decode(all_keys[order], 0, total, t0_us, out)


class Workspace:
    """Reusable per-chunk key buffers and histograms (grown on demand, kept between frames)."""

    def __init__(self, n_chunks: int | None = None, capacity: int = 1 << 16):
        self.n_chunks = int(n_chunks or numba.get_num_threads())
        self.keys = numba.typed.List([np.empty(int(capacity), np.int64) for _ in range(self.n_chunks)])
        self.sorted_keys = np.empty(0, np.int64)
        self.hists = np.zeros((self.n_chunks, 0), np.int64)

    @property
    def capacity(self) -> int:
        return self.keys[0].shape[0]

    def grow(self, counts: np.ndarray) -> None:
        """Double each chunk's capacity, keeping its first counts[c] keys."""
        new = numba.typed.List()
        for c, n in enumerate(counts):
            buf = np.empty(2 * self.capacity, np.int64)
            buf[:n] = self.keys[c][:n]
            new.append(buf)
        self.keys = new

    def histograms(self, n_bins: int) -> np.ndarray:
        """Zeroed [n_chunks, n_bins] counts (a view of a buffer reused between calls)."""
        if self.hists.shape[1] < n_bins:
            self.hists = np.zeros((self.n_chunks, n_bins), np.int64)
        view = self.hists[:, :n_bins]
        view[...] = 0
        return view


def emit_events(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, refractory_us,
                noise_pix, noise_t, noise_p, width, workspace: Workspace | None = None):
    """Fast twin of `simulator.kernel_ref.emit_events_ref` (same arguments, same result).

    `workspace` keeps buffers between calls (the simulator passes one; optional here).
    """
    ws = workspace or Workspace()
    t0_us, t1_us, R, width = int(t0_us), int(t1_us), int(refractory_us), int(width)
    D = t1_us - t0_us
    if D > _MAX_OFFSET:
        raise ValueError(f"frame interval of {D} us is longer than the supported {_MAX_OFFSET} us")
    if width > 0xFFFF or L0.shape[0] // max(width, 1) > 0x7FFF:
        raise ValueError("sensor too large for packed event keys: width <= 65535 and height <= 32767")
    parallel = ws.n_chunks > 1
    P = L0.shape[0]
    bounds = np.linspace(0, P, ws.n_chunks + 1).astype(np.int64)
    starts, stops = bounds[:-1].copy(), bounds[1:].copy()
    counts = np.zeros(ws.n_chunks, np.int64)
    clean = R == 0 and noise_t.shape[0] == 0
    while True:
        (_emit_parallel if parallel else _emit_serial)(
            L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, R, noise_pix, noise_t, noise_p,
            clean, width, starts, stops, ws.keys, counts)
        if np.all(starts >= stops):
            break
        ws.grow(counts)
    total = int(counts.sum())
    out = np.empty(total, EVENT_DTYPE)
    if D <= 4 * total + 65536:  # one histogram bin per microsecond of the interval
        hists = ws.histograms(D + 1)
        if ws.sorted_keys.shape[0] < total:
            ws.sorted_keys = np.empty(max(total, 2 * ws.sorted_keys.shape[0]), np.int64)
        sort = _sort_counting_parallel if parallel else _sort_counting_serial
        sort(ws.keys, counts, hists, ws.sorted_keys, t0_us, out)
    else:
        _sort_merge(ws.keys, counts, t0_us, out)
    return out
