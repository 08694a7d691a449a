"""A run's initial Gaussian centres, chosen by the training config (`train.init`): a random cube
(objects) or sphere shell (rooms) around the rig's target as the paper does, the points of a file,
or the cube / sphere carved by the events (recon.event_init). The generators themselves are pure
functions in recon.point_clouds."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from scene_format.reader import SceneDataset
from recon import point_clouds as initial
from recon.config import TrainConfig
from recon.event_init import carved_points


def initial_points(dataset: SceneDataset, cfg: TrainConfig) -> np.ndarray:
    ic = cfg.init
    scene = dataset.scene
    auto = "cube" if scene.kind == "object" else "sphere"
    kind = ic.kind if ic.kind != "auto" else auto
    if kind == "events":
        n = ic.n_points_object if auto == "cube" else ic.n_points_room
        candidates = initial_points(dataset, replace(cfg, init=replace(ic, kind=auto, n_points_object=ic.carve_candidates,
                                                                        n_points_room=ic.carve_candidates)))
        pts, _ = carved_points(dataset, candidates, n, ic.carve_times, ic.carve_window, ic.carve_min_events,
                               ic.carve_dilate_px, ic.seed)
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
