"""Intensity frames from an event stream: a trained network, or the non-learned high-pass filter.

Windows: frame k is reconstructed from the events in (t_{k-1}, t_k] (the first from the stream's
start), split into sub-windows of at most `events_per_window` events so the network sees event
densities like those it was trained on; the recurrent state carries across all windows.

The high-pass filter (Scheerlinck et al., ACCV 2018, without the frame input) integrates events as
log-intensity steps and forgets with cutoff alpha (rad/s): L(t) = exp(-alpha (t - t0)) L(t0) +
sum_i C p_i exp(-alpha (t - t_i)). It is linear, so a window is one bincount. Its image is only
defined up to an offset and scale; `hpf_display` maps it to [0, 1] by robust min/max.
"""
from __future__ import annotations

import math
from typing import Iterator

import numpy as np
import torch

from e2vid.networks import Reconstructor
from e2vid.voxel import normalize_voxel, voxel_grid_events


def frame_times_us(t0_us: int, t1_us: int, step_us: float | None = None, n_frames: int = 30) -> np.ndarray:
    """Output times [K] int64 over a stream from t0_us to t1_us: every step_us from t0_us + step_us,
    the last at t1_us (a shorter final window, so no event is left out); without a step, n_frames
    evenly spaced, the last at t1_us."""
    if t1_us <= t0_us:
        return np.array([t1_us], np.int64)
    if step_us is None:
        return np.unique(np.round(t0_us + (t1_us - t0_us) * np.arange(1, n_frames + 1) / n_frames).astype(np.int64))
    inner = np.round(t0_us + step_us * np.arange(1, int(math.ceil((t1_us - t0_us) / step_us)))).astype(np.int64)
    return np.unique(np.concatenate([inner[inner < t1_us], [t1_us]]))


def split_windows(t_us: np.ndarray, t_out_us: np.ndarray, events_per_window: int | None) -> Iterator[tuple[int, int, int]]:
    """Yield (i0, i1, k): events [i0, i1) form a window, k >= 0 when frame k is due after it, else -1."""
    t_out_us = np.asarray(t_out_us, np.int64)
    if np.any(np.diff(t_out_us) < 0):
        raise ValueError("output timestamps must be non-decreasing")
    ends = np.searchsorted(t_us, t_out_us, side="right")
    i0 = 0
    for k, i1 in enumerate(ends):
        n = int(i1 - i0)
        parts = max(1, math.ceil(n / events_per_window)) if events_per_window else 1
        cuts = np.linspace(i0, i1, parts + 1).astype(np.int64)
        for j in range(parts):
            yield int(cuts[j]), int(cuts[j + 1]), (k if j == parts - 1 else -1)
        i0 = int(i1)


def reconstruct_frames(recon: Reconstructor, events: np.ndarray, width: int, height: int,
                       t_out_us: np.ndarray, events_per_window: int | None = None,
                       num_bins: int = 5, progress: bool = False) -> np.ndarray:
    """Frames [K, H, W] in [0, 1] at t_out_us from EVENT_DTYPE events (time-sorted); `progress`
    shows a bar over the network's windows."""
    from tqdm import tqdm

    from common.progress import report

    frames = np.zeros((len(t_out_us), height, width), np.float32)
    windows = list(split_windows(events["t"], t_out_us, events_per_window))
    for j, (i0, i1, k) in enumerate(tqdm(windows, desc="e2vid", unit="window", disable=not progress)):
        report(j + 1, len(windows), "e2vid windows")
        vox = normalize_voxel(torch.from_numpy(voxel_grid_events(events[i0:i1], num_bins, width, height)))
        img = recon(vox)
        if k >= 0:
            frames[k] = img.numpy()
    return frames


def hpf_log_frames(events: np.ndarray, width: int, height: int, t_out_us: np.ndarray,
                   cutoff_rad_s: float = 30.0, contrast: float = 0.2) -> np.ndarray:
    """High-pass-filtered log intensity [K, H, W] at t_out_us (0 where nothing happened)."""
    t_out_us = np.asarray(t_out_us, np.int64)
    state = np.zeros(height * width, np.float64)
    t_state = int(events["t"][0]) if len(events) else (int(t_out_us[0]) if len(t_out_us) else 0)
    out = np.zeros((len(t_out_us), height, width), np.float32)
    ends = np.searchsorted(events["t"], t_out_us, side="right")
    i0 = 0
    for k, (t_end, i1) in enumerate(zip(t_out_us, ends)):
        ev = events[i0:i1]
        state *= math.exp(-cutoff_rad_s * (int(t_end) - t_state) * 1e-6)
        if len(ev):
            w = contrast * ev["p"].astype(np.float64) * np.exp(-cutoff_rad_s * (int(t_end) - ev["t"]) * 1e-6)
            state += np.bincount(ev["y"].astype(np.int64) * width + ev["x"], weights=w, minlength=height * width)
        t_state, i0 = int(t_end), int(i1)
        out[k] = state.reshape(height, width)
    return out


def hpf_display(log_frame: np.ndarray) -> np.ndarray:
    """exp of a log frame, robustly stretched to [0, 1] (1st..99th percentile); constant -> 0.5."""
    img = np.exp(log_frame.astype(np.float64))
    lo, hi = np.percentile(img, 1), np.percentile(img, 99)
    if hi - lo < 1e-9:
        return np.full(log_frame.shape, 0.5, np.float32)
    return np.clip((img - lo) / (hi - lo), 0, 1).astype(np.float32)
