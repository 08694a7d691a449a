"""Scene geometry for the blur measurement (bpy): first surface hits through a pixel grid, every
part's world matrix at every rendered timestamp, and a check that parts move rigidly.

The pure part of the measurement (paths, windows, statistics) is `datagen.blur_geometry`.
"""
from __future__ import annotations

import bpy
import mathutils
import numpy as np
from mathutils.bvhtree import BVHTree

from datagen import render as R
from common.config import ConfigError


class RigidMotionError(ConfigError):
    """A scene part deforms over time: the blur measurement tracks rigidly moving parts only."""


def pixel_grid(width: int, height: int, stride: int) -> np.ndarray:
    """Pixel-centre image coordinates [N, 2] of every stride-th pixel (u, v) = (x + 0.5, y + 0.5),
    starting half a stride in so the grid is centred."""
    u = np.arange(stride // 2, width, stride) + 0.5
    v = np.arange(stride // 2, height, stride) + 0.5
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel()], -1)


class GeometrySampler:
    """The scene's mesh parts; world matrices, local vertices and ray hits at the current time."""

    def __init__(self):
        self.objects = [o for o in bpy.context.scene.objects if o.type == "MESH" and len(o.data.polygons)]

    def matrices(self) -> np.ndarray:
        """Object-to-world [O, 4, 4] of every part at the current scene time."""
        dg = bpy.context.evaluated_depsgraph_get()
        return np.array([np.array(o.evaluated_get(dg).matrix_world) for o in self.objects], np.float64)

    def _meshes(self):
        dg = bpy.context.evaluated_depsgraph_get()
        for o in self.objects:
            ev = o.evaluated_get(dg)
            me = ev.to_mesh()
            me.calc_loop_triangles()
            co = np.empty(len(me.vertices) * 3)
            me.vertices.foreach_get("co", co)
            tri = np.empty(len(me.loop_triangles) * 3, np.int32)
            me.loop_triangles.foreach_get("vertices", tri)
            yield co.reshape(-1, 3), tri.reshape(-1, 3)
            ev.to_mesh_clear()

    def local_vertices(self) -> list[np.ndarray]:
        return [co for co, _ in self._meshes()]

    def check_rigid(self, taus) -> None:
        """RigidMotionError unless every part's evaluated mesh (in its own frame) is the same at all taus."""
        R.set_time(float(taus[0]))
        ref = self.local_vertices()
        for tau in taus[1:]:
            R.set_time(float(tau))
            for o, a, b in zip(self.objects, ref, self.local_vertices()):
                if a.shape != b.shape or not np.allclose(a, b, atol=1e-6):
                    raise RigidMotionError(f"part {o.name!r} deforms between tau={taus[0]} and tau={tau}: the blur "
                                           "measurement tracks rigidly moving parts only")

    def snapshot(self):
        """The scene's triangles in world space at the current time, as (BVH, part of each triangle [F],
        part matrices [O, 4, 4]) for `cast`."""
        mats = self.matrices()
        verts, tris, owner, offset = [], [], [], 0
        for o, (co, tri) in enumerate(self._meshes()):
            verts.append(co @ mats[o, :3, :3].T + mats[o, :3, 3])
            tris.append(tri + offset)
            owner.append(np.full(len(tri), o))
            offset += len(co)
        bvh = BVHTree.FromPolygons(np.concatenate(verts).tolist(), np.concatenate(tris).tolist(), epsilon=0.0)
        return bvh, np.concatenate(owner), mats

    @staticmethod
    def cast(snapshot, c2w: np.ndarray, K: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First surface hit of the ray through each pixel [N, 2] of an OpenCV camera c2w [4, 4] in a
        snapshot: (points in their part's frame [M, 3], part index [M]) for the M rays that hit."""
        pts, idx, _hit = GeometrySampler.cast_hits(snapshot, c2w, K, pixels)
        return pts, idx

    @staticmethod
    def cast_hits(snapshot, c2w: np.ndarray, K: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`cast`, and which of the N rays hit (bool [N], in the order of the M points)."""
        bvh, owner, mats = snapshot
        rays = np.concatenate([pixels, np.ones((len(pixels), 1))], 1) @ np.linalg.inv(K).T @ c2w[:3, :3].T
        origin = mathutils.Vector(c2w[:3, 3].tolist())
        cast, Vector = bvh.ray_cast, mathutils.Vector
        pts, idx, hit = [], [], np.zeros(len(rays), bool)
        for n, d in enumerate(rays.tolist()):
            loc, _normal, face, _dist = cast(origin, Vector(d))
            if face is not None:
                pts.append(tuple(loc))
                idx.append(owner[face])
                hit[n] = True
        if not pts:
            return np.zeros((0, 3)), np.zeros(0, np.int64), hit
        pts, idx = np.array(pts, np.float64), np.array(idx, np.int64)
        inv = np.linalg.inv(mats[idx])
        return np.einsum("nij,nj->ni", inv[:, :3, :3], pts) + inv[:, :3, 3], idx, hit


def sample_scene_motion(tau: np.ndarray, centers: np.ndarray, poses: np.ndarray, K: np.ndarray, width: int,
                        height: int, stride: int):
    """Everything the blur measurement needs from Blender, for the scene currently built.

    tau [T] normalised rendered times; centers [J] rendered-frame indices of the blurred frames;
    poses [C, T, 4, 4] OpenCV c2w. Returns (part matrices [T, O, 4, 4], samples {(camera, j): (local
    points [N, 3], part index [N])}). Raises RigidMotionError if a part deforms.
    """
    sampler = GeometrySampler()
    sampler.check_rigid([tau[0], tau[len(tau) // 2], tau[-1]])
    mats = np.empty((len(tau), len(sampler.objects), 4, 4))
    for i, t in enumerate(tau):
        R.set_time(float(t))
        mats[i] = sampler.matrices()
    pixels = pixel_grid(width, height, stride)
    samples = {}
    for j, i in enumerate(centers):
        R.set_time(float(tau[i]))
        snap = sampler.snapshot()
        for k in range(poses.shape[0]):
            samples[(k, j)] = sampler.cast(snap, poses[k, i], K, pixels)
    return mats, samples


def dynamic_masks(tau: np.ndarray, views: list[tuple[int, int]], poses: np.ndarray, K: np.ndarray, width: int,
                  height: int, threshold_px: float) -> dict[tuple[int, int], np.ndarray]:
    """The dynamic mask (datagen.dynamic) of every view (camera k, rendered-time index i), for the scene
    currently built: a ray through every pixel at time tau[i], each hit tracked over the whole clip.
    poses [C, T, 4, 4] OpenCV c2w. Raises RigidMotionError if a part deforms."""
    from datagen.dynamic import mask_image, surface_motion_px

    sampler = GeometrySampler()
    sampler.check_rigid([tau[0], tau[len(tau) // 2], tau[-1]])
    mats = np.empty((len(tau), len(sampler.objects), 4, 4))
    for i, t in enumerate(tau):
        R.set_time(float(t))
        mats[i] = sampler.matrices()
    pixels = pixel_grid(width, height, 1)
    out = {}
    for i in sorted({i for _, i in views}):
        R.set_time(float(tau[i]))
        snap = sampler.snapshot()
        for k in sorted({k for k, j in views if j == i}):
            local, obj, hit = sampler.cast_hits(snap, poses[k, i], K, pixels)
            out[(k, i)] = mask_image(hit, surface_motion_px(local, obj, mats, poses[k, i], K[0, 0], i),
                                     width, height, threshold_px)
    return out
