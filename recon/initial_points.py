"""A run's initial Gaussian centres, chosen by the training config (`train.init`): a random cube
(objects) or sphere shell (rooms) around the rig's target as the paper does, the points of a file,
or the cube / sphere carved by the events (recon.event_init). The generators themselves are pure
functions in recon.point_clouds. Where the carving keeps no point (too few events agree between the
cameras, as with a realistic sensor at high speed) and `init.carve_fallback` is `auto`, the auto
volume is used instead and an InitFallbackWarning says so (the trainer records it in run.json)."""
from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from scene_format.reader import SceneDataset
from recon import point_clouds as initial
from recon.config import TrainConfig
from recon.event_init import NoCarvedPointsError, carved_points


class InitFallbackWarning(UserWarning):
    """The requested initialisation could not be made; another was used (the message says which and why)."""


def initial_points(dataset: SceneDataset, cfg: TrainConfig) -> np.ndarray:
    ic = cfg.init
    scene = dataset.scene
    auto = "cube" if scene.kind == "object" else "sphere"
    kind = ic.kind if ic.kind != "auto" else auto
    if kind == "events":
        n = ic.n_points_object if auto == "cube" else ic.n_points_room
        candidates = initial_points(dataset, replace(cfg, init=replace(ic, kind=auto, n_points_object=ic.carve_candidates,
                                                                        n_points_room=ic.carve_candidates)))
        try:
            pts, _ = carved_points(dataset, candidates, n, ic.carve_times, ic.carve_window, ic.carve_min_events,
                                   ic.carve_dilate_px, ic.seed)
        except NoCarvedPointsError as exc:
            if ic.carve_fallback == "error":
                raise NoCarvedPointsError(f"{exc}; use init.kind: auto, or init.carve_fallback: auto") from None
            warnings.warn(InitFallbackWarning(f"init.kind events -> {auto}: {exc} (init.carve_fallback: auto)"),
                          stacklevel=2)
            return initial_points(dataset, replace(cfg, init=replace(ic, kind=auto)))
        return pts
    if kind == "cube":
        half = ic.cube_half_size if ic.cube_half_size is not None else 0.35 * scene.rig_radius_m
        return initial.random_cube(ic.n_points_object, half, scene.rig_target, ic.seed)
    if kind == "sphere":
        radius = ic.sphere_radius if ic.sphere_radius is not None else 10.0
        return initial.dense_to_sparse_sphere(ic.n_points_room, radius, scene.rig_target, ic.seed)
    path = Path(ic.points_file)
    if not path.exists():
        raise FileNotFoundError(f"init.points_file: {path} does not exist")
    return initial.from_point_cloud(np.load(path), seed=ic.seed)


def initial_points_noting_fallback(dataset: SceneDataset, cfg: TrainConfig) -> tuple[np.ndarray, str | None]:
    """initial_points and, where it fell back from the configured initialisation, the
    InitFallbackWarning's message (else None); any other warning passes on as it came."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InitFallbackWarning)
        pts = initial_points(dataset, cfg)
    note = None
    for w in caught:
        if issubclass(w.category, InitFallbackWarning):
            note = note or str(w.message)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return pts, note
