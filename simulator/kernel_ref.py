"""Readable reference of the event generator: one pixel at a time, one event at a time.

Model, per pixel and frame interval [t0, t1] (microseconds). The (filtered, leak-shifted) log
intensity L(s) is linear between the frames: L(s) = L0 + (L1 - L0) s / D, s = t - t0, D = t1 - t0.
The pixel keeps a reference level `base`. It emits an ON event when L reaches base + C+ and an OFF
event when L reaches base - C-, each at the exact time the line crosses that level, and moves base
by one threshold. Several crossings in one interval all emit, each with its own time (no "pillars").
Crossing times are rounded to the nearest microsecond and kept inside (t0, t1].

Refractory period R > 0: after an event at t_e the pixel is blind until t_e + R; its reference then
resets to the input at that moment (L(t_e + R)), which is where a real DVS pixel's reset switch
releases. Noise events (shot noise, hot pixels; given per pixel) are emitted at their own times, do
not move the reference, and obey the refractory period like any other event.

A crossing counts when the line reaches the level to within CROSS_TOL (1e-9 log units), so that an
input stepping by exactly n thresholds gives n events despite rounding in the log.

`emit_events_ref` and the compiled `simulator.kernels.emit_events` share this signature and must
produce identical output.
"""
from __future__ import annotations

import math

import numpy as np

from eventio.events import make_events

CROSS_TOL = 1e-9


def emit_events_ref(L0, L1, base, t_ready, c_pos, c_neg, t0_us, t1_us, refractory_us,
                    noise_pix, noise_t, noise_p, width):
    """Events of one frame interval. Updates `base` [P] and `t_ready` [P] in place.

    L0, L1 [P] float64: log intensity at t0_us and t1_us. base [P] float64: reference levels.
    t_ready [P] int64: end of each pixel's refractory period. c_pos, c_neg [P] or [1] float64:
    per-pixel thresholds, or one threshold for all pixels.
    noise_pix [M] int64, noise_t [M] int64 (in (t0, t1]), noise_p [M] int8: noise events sorted by
    (pixel, time).
    Returns the events [K] (EVENT_DTYPE) sorted by t; equal t keep pixel order (row-major), then
    each pixel's own order.
    """
    D = t1_us - t0_us
    R = refractory_us
    ts, xs, ys, ps = [], [], [], []
    uniform = c_pos.shape[0] == 1
    for i in range(L0.shape[0]):
        cp, cn = (c_pos[0], c_neg[0]) if uniform else (c_pos[i], c_neg[i])
        a, b = float(L0[i]), float(L1[i])
        slope = b - a
        scale = D / slope if slope != 0.0 else 0.0
        level = float(base[i])
        k, k_end = (int(v) for v in np.searchsorted(noise_pix, [i, i + 1]))
        s_now = 0.0
        refractory_end = int(t_ready[i]) - t0_us  # offset in us; <= 0: not refractory
        blind = R > 0 and refractory_end > 0
        while True:
            if blind:
                while k < k_end and noise_t[k] - t0_us < refractory_end:
                    k += 1  # noise during the refractory period is lost
                if refractory_end > D:
                    level = b  # still blind at t1: the reference follows the input
                    break
                level = a + slope * (refractory_end / D)
                s_now = float(refractory_end)
                blind = False
            # next threshold crossing of the line from the current reference
            s_cross, pol, target = math.inf, 0, level
            if slope > 0.0:
                target = level + cp
                if target <= b + CROSS_TOL:
                    s_cross, pol = min(max((target - a) * scale, s_now), float(D)), 1
            elif slope < 0.0:
                target = level - cn
                if target >= b - CROSS_TOL:
                    s_cross, pol = min(max((target - a) * scale, s_now), float(D)), -1
            s_noise = float(noise_t[k] - t0_us) if k < k_end else math.inf
            if s_cross == math.inf and s_noise == math.inf:
                break
            if s_noise < s_cross:
                offset = int(noise_t[k] - t0_us)
                ts.append(t0_us + offset)
                ps.append(int(noise_p[k]))
                k += 1
            else:
                offset = max(int(math.floor(s_cross + 0.5)), 1)
                ts.append(t0_us + offset)
                ps.append(pol)
                level = target
                s_now = s_cross
            xs.append(i % width)
            ys.append(i // width)
            if R > 0:
                t_ready[i] = t0_us + offset + R
                refractory_end = offset + R
                blind = True
        base[i] = level
    events = make_events(np.asarray(ts, np.int64), np.asarray(xs, np.uint16), np.asarray(ys, np.uint16),
                         np.asarray(ps, np.int8))
    return events[np.argsort(events["t"], kind="stable")]
