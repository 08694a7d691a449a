"""Initial point clouds without SfM (shared by D3DGS and E-4DGS; see DESIGN.md).

- objects: points uniform in an axis-aligned cube;
- rooms: a dense-to-sparse ball: radius uniform in [0, R] (not in volume), so the point density
  falls off as 1 / r^2 from the centre, where the scene's subject is;
- or a given point cloud.
"""
from __future__ import annotations

import numpy as np


def random_cube(n: int, half_size: float, center=(0.0, 0.0, 0.0), seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (rng.uniform(-half_size, half_size, size=(n, 3)) + np.asarray(center, np.float64)).astype(np.float32)


def dense_to_sparse_sphere(n: int, radius: float = 10.0, center=(0.0, 0.0, 0.0), seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = radius * rng.random(n)
    return (d * r[:, None] + np.asarray(center, np.float64)).astype(np.float32)


def from_point_cloud(points, n_max: int | None = None, seed: int = 0) -> np.ndarray:
    pts = np.asarray(points, np.float32)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise ValueError(f"point cloud must be a non-empty [N, 3] array, got shape {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("point cloud has non-finite coordinates")
    if n_max is not None and len(pts) > n_max:
        pts = pts[np.random.default_rng(seed).choice(len(pts), n_max, replace=False)]
    return pts
