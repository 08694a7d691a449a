"""Event-based initial points (`init.kind: events`): carve the initial volume with the events.

At `carve_times` instants spread over the clip, each camera's events within `carve_window` (a
fraction of the clip) around the instant mark the pixels where the scene changed as the camera moved
(recon.event_supervision.activity_mask). A uniform backdrop and empty space cause no events, so a candidate point
that some camera sees on an event-free pixel is not part of the scene at that instant
(recon.initial_points.carve). The union over the instants is the volume any part of the scene swept; the
initial points are drawn from it. Candidates come from the auto volume (the cube for objects, the
dense-to-sparse sphere for rooms), so a scene where every pixel fires (a textured room) keeps
nearly all of them and the result is close to the paper's initialisation.
"""
from __future__ import annotations

import numpy as np

from scene_format.reader import SceneDataset
from recon import event_supervision as ev
from recon import point_clouds as initial
from recon.event_windows import EventSource


def activity_views(dataset: SceneDataset, t_us: int, window_us: int, min_events: int, dilate_px: int):
    """(K, world_to_cam, active [H, W]) of every camera around time t_us."""
    intr = dataset.intrinsics
    lo = max(0, t_us - window_us // 2)
    hi = min(dataset.duration_us, lo + window_us)
    views = []
    for k in range(dataset.n_cameras):
        src = EventSource(dataset.event_file(k))
        try:
            w = src.window_between(k, lo, hi)
        finally:
            src.close()
        counts = np.bincount(np.asarray(w.y, np.int64) * intr.width + np.asarray(w.x, np.int64),
                             minlength=intr.width * intr.height).reshape(intr.height, intr.width)
        active = ev.activity_mask(counts, min_events, dilate_px)
        views.append((intr.K, np.linalg.inv(dataset.pose(k, (lo + hi) // 2)), active))
    return views


class NoCarvedPointsError(ValueError):
    """The event carving kept no candidate point: no camera's events agree with any other's."""


def carved_points(dataset: SceneDataset, candidates: np.ndarray, n: int, times: int, window: float,
                  min_events: int, dilate_px: int, seed: int = 0) -> tuple[np.ndarray, float]:
    """n initial points [n, 3] drawn from the candidates [M, 3] that the event carving keeps at any of
    `times` instants, and the kept fraction of the candidates."""
    window_us = max(1, int(round(window * dataset.duration_us)))
    keep = np.zeros(len(candidates), bool)
    for t in np.linspace(0, dataset.duration_us, times):
        keep |= initial.carve(candidates, activity_views(dataset, int(round(t)), window_us, min_events, dilate_px))
    if not keep.any():
        raise NoCarvedPointsError(f"{dataset.dir}: the event carving kept no initial point (no camera's events agree "
                                  "with any other's)")
    spacing = (np.ptp(candidates, axis=0).prod() / len(candidates)) ** (1 / 3)
    return initial.sample_kept(candidates, keep, n, 0.5 * spacing, seed), float(keep.mean())
