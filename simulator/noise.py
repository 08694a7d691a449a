"""Random event sources (shot noise, hot pixels), drawn per frame interval in O(events).

Both are Poisson processes in continuous time. Shot noise has a per-pixel rate that depends on
the pixel's intensity; it is drawn by thinning (Lewis-Shedler): candidates at an upper bound of
the rate, each kept with probability rate / bound, which is exact for any rate map and needs the
intensity only at the candidates. Timestamps are uniform integer microseconds in (t0, t1].
Result: (pix [M], t [M], p [M]) sorted by (pixel, time), the kernels' noise input.
"""
from __future__ import annotations

import numpy as np

from simulator.pixel import SHOT_NOISE_WHITE_FACTOR, intensity01, shot_noise_rates_hz

NO_NOISE = (np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0, np.int8))


def draw_thinned(rng: np.random.Generator, n_pixels: int, rate_bound_hz: float, dt_s: float, rate_at) -> np.ndarray:
    """Pixel indices of Poisson events with per-pixel rates `rate_at(pix)` <= rate_bound_hz over dt_s.

    Each pixel i gets Poisson(rate_at(i) * dt_s) events (repeated indices, unsorted).
    """
    if rate_bound_hz <= 0.0 or dt_s <= 0.0 or n_pixels == 0:
        return np.empty(0, np.int64)
    n = rng.poisson(rate_bound_hz * dt_s * n_pixels)
    cand = rng.integers(0, n_pixels, size=n)
    keep = rng.random(n) * rate_bound_hz < rate_at(cand)
    return cand[keep]


def sort_by_pixel_then_time(pix: np.ndarray, t_us: np.ndarray, p: np.ndarray):
    order = np.lexsort((t_us, pix))
    return (np.ascontiguousarray(pix[order], np.int64), np.ascontiguousarray(t_us[order], np.int64),
            np.ascontiguousarray(p[order], np.int8))


def draw_noise_events(rng: np.random.Generator, t0_us: int, t1_us: int, n_pixels: int,
                      intensity: np.ndarray | None, shot_rate_hz: float, c_nominal: tuple[float, float],
                      c_pos: np.ndarray, c_neg: np.ndarray,
                      hot_pixels: np.ndarray | None, hot_rate_hz: float, on_share: float = 0.5,
                      white_factor: float = SHOT_NOISE_WHITE_FACTOR, gain: np.ndarray | None = None):
    """Noise events of one interval, sorted by (pixel, time).

    Shot noise (when shot_rate_hz > 0): v2e's per-polarity rate from `shot_noise_rates_hz` at the
    pixel's linear intensity [P] and thresholds c_pos / c_neg ([P] or [1]); c_nominal = (C+, C-);
    `on_share` of it ON (v2e: half), `white_factor` its scale at white (v2e: 0.25), times a per-pixel
    `gain` [P] (fixed pattern; None: 1).
    Hot pixels (when hot_pixels is given): ON events at hot_rate_hz at those pixel indices.
    """
    dt_s = (t1_us - t0_us) * 1e-6
    pix_parts, pol_parts = [], []
    if shot_rate_hz > 0:
        g_max = float(gain.max()) if gain is not None else 1.0
        for pol, c_nom, c_pix, share in ((1, c_nominal[0], c_pos, on_share), (-1, c_nominal[1], c_neg, 1.0 - on_share)):
            c_at = (lambda i, c=c_pix: c[0]) if c_pix.shape[0] == 1 else (lambda i, c=c_pix: c[i])
            g_at = (lambda i: 1.0) if gain is None else (lambda i: gain[i])
            # rate is largest in the dark (factor 1, or white_factor if above 1), at the smallest threshold and gain
            bound = shot_noise_rates_hz(np.zeros(1), shot_rate_hz, c_nom, np.array([c_pix.min()]), share,
                                        white_factor)[0] * max(1.0, white_factor) * g_max
            rate_at = lambda i, c_nom=c_nom, c_at=c_at, share=share: shot_noise_rates_hz(  # noqa: E731
                intensity01(intensity[i]), shot_rate_hz, c_nom, c_at(i), share, white_factor) * g_at(i)
            drawn = draw_thinned(rng, n_pixels, bound, dt_s, rate_at)
            pix_parts.append(drawn)
            pol_parts.append(np.full(drawn.size, pol, np.int8))
    if hot_pixels is not None and hot_pixels.size and hot_rate_hz > 0:
        counts = rng.poisson(hot_rate_hz * dt_s, size=hot_pixels.size)
        hot = np.repeat(hot_pixels, counts)
        pix_parts.append(hot)
        pol_parts.append(np.ones(hot.size, np.int8))
    if not pix_parts:
        return NO_NOISE
    pix = np.concatenate(pix_parts)
    pol = np.concatenate(pol_parts)
    t_us = rng.integers(t0_us + 1, t1_us + 1, size=pix.size, dtype=np.int64)
    return sort_by_pixel_then_time(pix, t_us, pol)
