"""Initial point clouds without SfM (shared by D3DGS and E-4DGS; see docs/design/recon.md).

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


def carve(points: np.ndarray, views: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
          min_views: int = 2) -> np.ndarray:
    """Space carving: which points every camera that sees them agrees on.

    points [M, 3] world; views: (K [3, 3], world_to_cam [4, 4] OpenCV axes, active [H, W] bool), all
    taken at one instant. A point is kept when it projects inside the image of at least `min_views`
    of the views (in front of the camera) and onto an active pixel in every one of them.
    Returns keep [M] bool.
    """
    pts = np.asarray(points, np.float64)
    seen = np.zeros(len(pts), np.int32)
    missed = np.zeros(len(pts), bool)
    for K, w2c, active in views:
        cam = pts @ np.asarray(w2c, np.float64)[:3, :3].T + np.asarray(w2c, np.float64)[:3, 3]   # [M, 3]
        z = cam[:, 2]
        front = z > 1e-6
        uv = cam[:, :2] / np.where(front, z, 1.0)[:, None] @ np.asarray(K, np.float64)[:2, :2].T + \
            np.asarray(K, np.float64)[:2, 2]                                                       # [M, 2] px
        h, w = active.shape
        u, v = np.floor(uv[:, 0]).astype(np.int64), np.floor(uv[:, 1]).astype(np.int64)
        inside = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        hit = np.zeros(len(pts), bool)
        hit[inside] = active[v[inside], u[inside]]
        seen += inside
        missed |= inside & ~hit
    return (seen >= min_views) & ~missed


def sample_kept(candidates: np.ndarray, keep: np.ndarray, n: int, jitter: float, seed: int = 0) -> np.ndarray:
    """n points drawn from the kept candidates [M, 3] (with replacement when fewer), each moved by a
    uniform offset in [-jitter, jitter]^3 so repeated draws do not coincide. [n, 3] float32."""
    kept = np.asarray(candidates, np.float64)[np.asarray(keep, bool)]
    if len(kept) == 0:
        raise ValueError("no candidate point is kept")
    rng = np.random.default_rng(seed)
    idx = rng.choice(len(kept), n, replace=len(kept) < n)
    return (kept[idx] + rng.uniform(-jitter, jitter, size=(n, 3))).astype(np.float32)
