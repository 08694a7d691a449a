"""Voxel grids as E2VID builds them: a window's events spread over B temporal bins with bilinear
weights in time. An event at t* = (B - 1) (t - t_first) / (t_last - t_first) adds p (1 - (t* - floor t*))
to bin floor(t*) and p (t* - floor t*) to the next (E2VID's `events_to_voxel_grid`).

    >>> import numpy as np
    >>> t, x, y, p = np.array([0, 50, 100]), np.array([0, 0, 1]), np.array([0, 0, 0]), np.array([1, 1, -1])
    >>> voxel_grid(t, x, y, p, 3, 2, 1)[:, 0].tolist()      # bins at t 0, 50, 100 us
    [[1.0, 0.0], [1.0, 0.0], [0.0, -1.0]]

    voxel_grid_ref      readable: one event at a time
    voxel_grid          two bincounts; same signature
    voxel_grid_events   voxel_grid of an EVENT_DTYPE array
"""
from __future__ import annotations

import numpy as np


def voxel_grid_ref(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray,
                   n_bins: int, width: int, height: int) -> np.ndarray:
    """Readable reference: one event at a time. Arrays [N] -> grid [n_bins, height, width] float32."""
    grid = np.zeros((n_bins, height, width), np.float64)
    if len(t_us) == 0:
        return grid.astype(np.float32)
    t0, t1 = int(t_us[0]), int(t_us[-1])
    span = float(t1 - t0) if t1 > t0 else 1.0
    for ti, xi, yi, pi in zip(t_us, x, y, p):
        ts = (n_bins - 1) * (int(ti) - t0) / span
        b = int(np.floor(ts))
        frac = ts - b
        grid[b, yi, xi] += pi * (1.0 - frac)
        if b + 1 < n_bins:
            grid[b + 1, yi, xi] += pi * frac
    return grid.astype(np.float32)


def voxel_grid(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray,
               n_bins: int, width: int, height: int) -> np.ndarray:
    """Same as `voxel_grid_ref`, vectorised (two bincounts). Events must be sorted by time."""
    n_cells = n_bins * height * width
    if len(t_us) == 0:
        return np.zeros((n_bins, height, width), np.float32)
    t = np.asarray(t_us, np.int64)
    t0, t1 = int(t[0]), int(t[-1])
    span = float(t1 - t0) if t1 > t0 else 1.0
    ts = (n_bins - 1) * (t - t0).astype(np.float64) / span
    b = np.floor(ts).astype(np.int64)
    frac = ts - b
    pol = np.asarray(p, np.float64)
    pix = np.asarray(y, np.int64) * width + np.asarray(x, np.int64)
    grid = np.bincount(b * height * width + pix, weights=pol * (1.0 - frac), minlength=n_cells)
    nxt = b + 1 < n_bins
    grid += np.bincount((b[nxt] + 1) * height * width + pix[nxt], weights=(pol * frac)[nxt], minlength=n_cells)
    return grid.reshape(n_bins, height, width).astype(np.float32)


def voxel_grid_events(events: np.ndarray, n_bins: int, width: int, height: int) -> np.ndarray:
    """`voxel_grid` of an EVENT_DTYPE array."""
    return voxel_grid(events["t"], events["x"], events["y"], events["p"], n_bins, width, height)
