"""Adaptive temporal sampling: render only the frames the image motion needs (as ESIM samples its
renderer by the image's motion), and let the rest of the render.fps time line be filled in.

The image motion comes from the scene geometry the generator already samples for the blur
measurement (datagen.render_geometry, datagen.blur_geometry): surface points seen through every
camera at every kept frame, tracked rigidly through the neighbouring rendered frames and projected.
`frame_steps_px` turns them into the motion between consecutive rendered frames (a high quantile over
the points, the largest over the cameras); `render_schedule` picks the frames to render so that the
motion between two rendered frames stays within a bound (px), always rendering the kept (ground-truth)
frames, the first and the last, and never skipping more than `max_stride - 1` frames in a row.

What fills the skipped frames (datagen.generate):
- the simulator gets only rendered frames: its per-pixel linear interpolation of log intensity between
  two frames (simulator.simulator) is what it does between any two frames, now over a longer step;
- a blurred frame is the mean of every render.fps frame in its exposure: a skipped frame enters it as
  the linear-light blend of the two rendered frames around it (`blend_weights`), i.e. the exposure
  integral by the trapezoid rule over the rendered frames.
The error against rendering every frame is measured by `python -m tools.bench_render_rate
--adaptive ...` (docs/design/dataset.md).
"""
from __future__ import annotations

import numpy as np

from datagen.blur_geometry import view_paths

STEP_QUANTILE = 0.99       # of the sampled points' motion between two rendered frames, per camera


def frame_steps_px(samples: dict, mats, poses: np.ndarray, K: np.ndarray, centers: np.ndarray, T: int) -> np.ndarray:
    """steps [T - 1]: image motion (px) between rendered frames i and i + 1, the STEP_QUANTILE of the
    sampled surface points' displacement, the largest over the cameras. Each interval is measured with
    the points sampled at its nearest kept frame (centers [J], rendered-frame indices), tracked through
    the frames halfway to the neighbouring kept frames. samples {(camera, j): (local [N, 3], part [N])}
    and mats as datagen.render_geometry.sample_scene_motion returns them; poses [C, T, 4, 4] c2w."""
    steps = np.zeros(max(T - 1, 0))
    if T < 2:
        return steps
    centers = np.asarray(centers, int)
    bounds = np.concatenate([[0], (centers[1:] + centers[:-1]) // 2, [T - 1]])   # kept frame j owns [b_j, b_j+1]
    for (k, j), (local, obj) in samples.items():
        if not len(local):
            continue
        c, a, b = int(centers[j]), int(bounds[j]), int(bounds[j + 1])
        n = max(c - a, b - c, 1)
        lo, cum = view_paths(local, obj, mats, poses[k], K, c, n, T)
        step = np.diff(cum, axis=0)                              # [frames - 1, N]: interval lo + r
        first, last = max(a, lo), min(max(b, a + 1), lo + step.shape[0])   # the intervals this kept frame owns
        rows = step[first - lo:last - lo]
        seen = np.isfinite(rows).any(axis=1)                     # an interval no sample saw says nothing
        if seen.any():
            q = np.nanquantile(np.where(np.isfinite(rows[seen]), rows[seen], np.nan), STEP_QUANTILE, axis=1)
            idx = np.arange(first, last)[seen]
            steps[idx] = np.maximum(steps[idx], q)
    return steps


def render_schedule(steps_px: np.ndarray, required: np.ndarray, bound_px: float, max_stride: int) -> np.ndarray:
    """Sorted indices of the frames to render, of T = len(required): every required frame, the first
    and the last, and between them as few as keep the motion between consecutive rendered frames
    (the sum of steps_px [T - 1] over the interval) within bound_px and the gap within max_stride
    frames. A single step above the bound renders both its frames."""
    T = len(required)
    if T == 0:
        return np.zeros(0, int)
    out, acc, last = [0], 0.0, 0
    for i in range(1, T):
        acc += float(steps_px[i - 1])
        nxt = float(steps_px[i]) if i < T - 1 else 0.0
        if required[i] or i == T - 1 or acc + nxt > bound_px or i + 1 - last > max_stride:
            out.append(i)
            acc, last = 0.0, i
    return np.asarray(out, int)


def plan_renders(steps_px: np.ndarray, kept: np.ndarray, bound_px: float, max_stride: int) -> tuple[np.ndarray, dict]:
    """(rendered indices, the plan's record for the manifest) of T = len(steps_px) + 1 frames, the
    kept frames [J] required."""
    T = len(steps_px) + 1
    required = np.zeros(T, bool)
    required[np.asarray(kept, int)] = True
    rendered = render_schedule(steps_px, required, bound_px, max_stride)
    gaps = np.add.reduceat(steps_px, rendered[:-1]) if len(rendered) > 1 else np.zeros(0)
    return rendered, {"adaptive_px": bound_px, "max_stride": max_stride, "rendered_frames": int(len(rendered)),
                      "timestamps": T,
                      "px_between_rendered_frames": {"median": round(float(np.median(gaps)), 4) if len(gaps) else 0.0,
                                                     "max": round(float(gaps.max()), 4) if len(gaps) else 0.0},
                      "px_per_frame_max": round(float(steps_px.max()), 4) if len(steps_px) else 0.0}


def blend_weights(a: int, b: int, m: int) -> float:
    """Weight of rendered frame b in skipped frame m's linear-light blend (1 - w) F_a + w F_b, a < m < b."""
    return (m - a) / (b - a)
