"""Random event sources (shot noise, hot pixels) drawn per frame interval as per-pixel lists.

Both are Poisson processes in continuous time, drawn in O(events) rather than O(pixels): candidates
are drawn at the largest per-pixel rate and thinned to each pixel's rate (Lewis-Shedler), which is
exact for any rate map. Timestamps are uniform integer microseconds in (t0, t1].
The result is CSR: events of pixel i are t[ptr[i]:ptr[i+1]] (sorted), p likewise.
"""
from __future__ import annotations

import numpy as np


def draw_thinned(rng: np.random.Generator, rates_hz: np.ndarray, dt_s: float) -> np.ndarray:
    """Pixel indices of events of independent Poisson processes with rates [P] over dt_s seconds.

    Each pixel i gets Poisson(rates_hz[i] * dt_s) events (returned as repeated indices, unsorted).
    """
    P = rates_hz.shape[0]
    r_max = float(rates_hz.max()) if P else 0.0
    if r_max <= 0.0 or dt_s <= 0.0:
        return np.empty(0, np.int64)
    n = rng.poisson(r_max * dt_s * P)
    cand = rng.integers(0, P, size=n)
    keep = rng.random(n) * r_max < rates_hz[cand]
    return cand[keep]


def to_csr(pixels: np.ndarray, t_us: np.ndarray, p: np.ndarray, n_pixels: int):
    """Group events by pixel, time-sorted within each pixel: (ptr [P+1], t [M], p [M])."""
    order = np.lexsort((t_us, pixels))
    ptr = np.zeros(n_pixels + 1, np.int64)
    np.cumsum(np.bincount(pixels, minlength=n_pixels), out=ptr[1:])
    return ptr, np.ascontiguousarray(t_us[order], np.int64), np.ascontiguousarray(p[order], np.int8)


def draw_noise_events(rng: np.random.Generator, t0_us: int, t1_us: int,
                      shot_rate_on_hz: np.ndarray | None, shot_rate_off_hz: np.ndarray | None,
                      hot_pixels: np.ndarray | None, hot_rate_hz: float, n_pixels: int):
    """Noise events of one interval as CSR (ptr [P+1], t [M], p [M]).

    shot_rate_on_hz / shot_rate_off_hz [P]: per-pixel shot-noise rates per polarity (None: off).
    hot_pixels [H] pixel indices firing ON events at hot_rate_hz (None: off).
    """
    dt_s = (t1_us - t0_us) * 1e-6
    pix_parts, pol_parts = [], []
    if shot_rate_on_hz is not None:
        on = draw_thinned(rng, shot_rate_on_hz, dt_s)
        off = draw_thinned(rng, shot_rate_off_hz, dt_s)
        pix_parts += [on, off]
        pol_parts += [np.ones(on.size, np.int8), np.full(off.size, -1, np.int8)]
    if hot_pixels is not None and hot_pixels.size:
        counts = rng.poisson(hot_rate_hz * dt_s, size=hot_pixels.size)
        hot = np.repeat(hot_pixels, counts)
        pix_parts.append(hot)
        pol_parts.append(np.ones(hot.size, np.int8))
    pixels = np.concatenate(pix_parts) if pix_parts else np.empty(0, np.int64)
    pols = np.concatenate(pol_parts) if pol_parts else np.empty(0, np.int8)
    t_us = rng.integers(t0_us + 1, t1_us + 1, size=pixels.size, dtype=np.int64)
    return to_csr(pixels, t_us, pols, n_pixels)
