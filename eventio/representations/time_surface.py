"""Time surfaces: per pixel and polarity, exp(-(t_ref - t_last) / tau) of the latest event at or
before t_ref (0 where there is none), as in HOTS (Lagorce et al. 2017) and tonic's ToTimesurface.

    >>> import numpy as np
    >>> t, x, y, p = np.array([0, 1000]), np.array([0, 1]), np.array([0, 0]), np.array([1, -1])
    >>> s = time_surface(t, x, y, p, 2, 1, t_ref_us=1000, tau_us=1000)
    >>> np.round(s, 4).tolist()            # [ON, OFF]: the ON event 1 ms old, the OFF event now
    [[[0.3679, 0.0]], [[0.0, 1.0]]]

    time_surface_ref   readable: one event at a time
    time_surface       the latest time per pixel by one maximum-reduction; same signature
"""
from __future__ import annotations

import numpy as np


def time_surface_ref(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int,
                     t_ref_us: int, tau_us: float) -> np.ndarray:
    """Arrays [N] -> [2, H, W] float64 (ON, OFF); events after t_ref_us are ignored."""
    if not tau_us > 0:
        raise ValueError(f"time_surface: tau_us must be > 0, got {tau_us!r}")
    last = np.full((2, height, width), None, dtype=object)
    for ti, xi, yi, pi in zip(t_us, x, y, p):
        if int(ti) <= t_ref_us:
            c = 0 if pi > 0 else 1
            if last[c, yi, xi] is None or int(ti) > last[c, yi, xi]:
                last[c, yi, xi] = int(ti)
    out = np.zeros((2, height, width))
    for idx, t in np.ndenumerate(last):
        if t is not None:
            out[idx] = np.exp(-(t_ref_us - t) / tau_us)
    return out


def time_surface(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int,
                 t_ref_us: int, tau_us: float) -> np.ndarray:
    """Same as time_surface_ref, vectorised (events in any order)."""
    if not tau_us > 0:
        raise ValueError(f"time_surface: tau_us must be > 0, got {tau_us!r}")
    t = np.asarray(t_us, np.int64)
    keep = t <= t_ref_us
    cell = (np.where(np.asarray(p)[keep] > 0, 0, 1) * height + np.asarray(y, np.int64)[keep]) * width \
        + np.asarray(x, np.int64)[keep]
    last = np.full(2 * height * width, np.iinfo(np.int64).min, np.int64)
    np.maximum.at(last, cell, t[keep])
    seen = last > np.iinfo(np.int64).min
    out = np.zeros(2 * height * width)
    out[seen] = np.exp(-(t_ref_us - last[seen]) / tau_us)
    return out.reshape(2, height, width)
