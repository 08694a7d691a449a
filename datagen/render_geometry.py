"""Scene geometry for the blur measurement and the dynamic masks (bpy): first surface hits through a
pixel grid, and how every part moves at every rendered timestamp: a world matrix for a rigid part,
its evaluated mesh's world vertices for a deforming one (armature, shape keys, modifiers, cloth).

The pure part of the measurement (paths, windows, statistics) is `datagen.blur_geometry`.
"""
from __future__ import annotations

import json

import bpy
import mathutils
import numpy as np
from mathutils.bvhtree import BVHTree

from blender_scenes.common import JOINED_PARTS
from datagen import render as R
from datagen.blur_geometry import PartMotion
from common.config import ConfigError

N_DEFORM_CHECKS = 9      # times at which every part's mesh is compared to find the deforming ones


class TopologyChangeError(ConfigError):
    """A part's mesh changes its vertices or faces over the clip: its surface points cannot be tracked."""


RigidMotionError = TopologyChangeError      # the name callers knew when only rigid parts were tracked


def pixel_grid(width: int, height: int, stride: int) -> np.ndarray:
    """Pixel-centre image coordinates [N, 2] of every stride-th pixel (u, v) = (x + 0.5, y + 0.5),
    starting half a stride in so the grid is centred."""
    u = np.arange(stride // 2, width, stride) + 0.5
    v = np.arange(stride // 2, height, stride) + 0.5
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu.ravel(), vv.ravel()], -1)


def fan_triangles(loop_start: np.ndarray, loop_total: np.ndarray, loop_verts: np.ndarray) -> np.ndarray:
    """Triangles [F, 3] of polygons as fans (v0, vi, vi+1): fixed by the topology, unlike Blender's
    loop triangles, whose diagonals may flip as a mesh bends."""
    out = []
    for start, n in zip(loop_start.tolist(), loop_total.tolist()):
        v = loop_verts[start:start + n]
        out.extend((v[0], v[i], v[i + 1]) for i in range(1, n - 1))
    return np.array(out, np.int64).reshape(-1, 3)


def barycentric(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(b1, b2) of points p [N, 3] in triangles (a, b, c) [N, 3]: p = (1 - b1 - b2) a + b1 b + b2 c."""
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = (v0 * v0).sum(-1), (v0 * v1).sum(-1), (v1 * v1).sum(-1)
    d20, d21 = (v2 * v0).sum(-1), (v2 * v1).sum(-1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) > 1e-300, den, 1e-300)
    return (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den


class GeometrySampler:
    """The scene's mesh parts; how they move, and ray hits at the current time. Hits on a rigid part
    are kept in its own frame; on a deforming part (`deforming`) as (triangle, b1, b2) of its fan
    triangles, carried by its world vertices at every time (blur_geometry.PartMotion)."""

    def __init__(self):
        self.objects = [o for o in bpy.context.scene.objects
                        if o.type == "MESH" and len(o.data.polygons) and not o.hide_render]
        self.deforming: dict[int, np.ndarray] = {}     # part -> its fan triangles [F, 3]

    def matrices(self) -> np.ndarray:
        """Object-to-world [O, 4, 4] of every part at the current scene time."""
        dg = bpy.context.evaluated_depsgraph_get()
        return np.array([np.array(o.evaluated_get(dg).matrix_world) for o in self.objects], np.float64)

    def _meshes(self, fan=False, only=None, normals: bool = False):
        """(local vertices [V, 3], triangles [F, 3], polygon sizes [P]) of every part (or of the parts
        `only`) at the current time; `fan`: True, or the set of part indices, triangulated as fans
        (fan_triangles) instead of Blender's loop triangles. With `normals`, a fourth item: each
        triangle's corner normals [F, 3, 3] in the part's frame (Blender's shading normals: smooth
        faces interpolate them, flat faces repeat the face normal)."""
        dg = bpy.context.evaluated_depsgraph_get()
        indices = range(len(self.objects)) if only is None else only
        for n in indices:
            ev = self.objects[n].evaluated_get(dg)
            me = ev.to_mesh()
            co = np.empty(len(me.vertices) * 3)
            me.vertices.foreach_get("co", co)
            sizes = np.empty(len(me.polygons), np.int64)
            me.polygons.foreach_get("loop_total", sizes)
            if fan is True or (fan and n in fan):
                start = np.empty(len(me.polygons), np.int64)
                me.polygons.foreach_get("loop_start", start)
                loops = np.empty(len(me.loops), np.int64)
                me.loops.foreach_get("vertex_index", loops)
                tri = fan_triangles(start, sizes, loops)
                corners = fan_triangles(start, sizes, np.arange(len(me.loops)))
            else:
                me.calc_loop_triangles()
                tri = np.empty(len(me.loop_triangles) * 3, np.int32)
                me.loop_triangles.foreach_get("vertices", tri)
                corners = np.empty(len(me.loop_triangles) * 3, np.int64)
                me.loop_triangles.foreach_get("loops", corners)
            out = (co.reshape(-1, 3), tri.reshape(-1, 3), sizes)
            if normals:
                cn = np.empty(len(me.loops) * 3)
                me.corner_normals.foreach_get("vector", cn)
                out += (cn.reshape(-1, 3)[corners.reshape(-1, 3)],)
            yield out
            ev.to_mesh_clear()

    def find_deforming(self, taus) -> None:
        """Which parts' evaluated meshes (in their own frame) change over taus (deforming parts);
        TopologyChangeError naming a part whose vertex or polygon count changes."""
        R.set_time(float(taus[0]))
        ref = list(self._meshes())
        changed = set()
        for tau in taus[1:]:
            R.set_time(float(tau))
            for o, (a, _, pa), (b, _, pb) in zip(range(len(self.objects)), ref, self._meshes()):
                if a.shape != b.shape or pa.shape != pb.shape or not np.array_equal(pa, pb):
                    raise TopologyChangeError(
                        f"part {self.objects[o].name!r} changes its mesh topology between tau={taus[0]} and "
                        f"tau={tau} ({len(a)} -> {len(b)} vertices, {len(pa)} -> {len(pb)} faces): its surface "
                        "points cannot be tracked (remesh or remove the modifier that changes it)")
                if not np.allclose(a, b, atol=1e-6):
                    changed.add(o)
        R.set_time(float(taus[0]))
        self.deforming = {o: tri for o, (_, tri, _) in enumerate(self._meshes(fan=True)) if o in changed}

    def motion(self, tau: np.ndarray) -> PartMotion:
        """Every part's motion at the rendered times tau [T] (call find_deforming first)."""
        mats = np.empty((len(tau), len(self.objects), 4, 4))
        verts = {o: [] for o in self.deforming}
        for i, t in enumerate(tau):
            R.set_time(float(t))
            mats[i] = self.matrices()
            order = sorted(self.deforming)
            for o, (co, _, _) in zip(order, self._meshes(only=order)):      # the deforming parts only
                verts[o].append(co @ mats[i, o, :3, :3].T + mats[i, o, :3, 3])
        for o in self.deforming:                     # the vertices carry the motion: identity matrices
            mats[:, o] = np.eye(4)
        return PartMotion(mats, {o: (self.deforming[o], np.stack(v)) for o, v in verts.items()})

    def snapshot(self):
        """The scene's triangles in world space at the current time, as (BVH, part of each triangle [F],
        part matrices [O, 4, 4], first triangle of each part, world vertices and triangles of each part,
        world corner normals of every triangle [F, 3, 3]) for `cast`."""
        mats = self.matrices()
        verts, tris, owner, firsts, parts, corner, offset, nf = [], [], [], [], [], [], 0, 0
        for o, (co, tri, _, cn) in enumerate(self._meshes(fan=set(self.deforming), normals=True)):
            world = co @ mats[o, :3, :3].T + mats[o, :3, 3]
            verts.append(world)
            tris.append(tri + offset)
            owner.append(np.full(len(tri), o))
            firsts.append(nf)
            parts.append((world, tri))
            corner.append(cn @ np.linalg.inv(mats[o, :3, :3]))      # normals: the inverse transpose
            offset += len(co)
            nf += len(tri)
        bvh = BVHTree.FromPolygons(np.concatenate(verts).tolist(), np.concatenate(tris).tolist(), epsilon=0.0)
        return bvh, np.concatenate(owner), mats, np.array(firsts), parts, np.concatenate(corner)

    def cast(self, snapshot, c2w: np.ndarray, K: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First surface hit of the ray through each pixel [N, 2] of an OpenCV camera c2w [4, 4] in a
        snapshot: (points in their part's frame [M, 3], part index [M]) for the M rays that hit."""
        pts, idx, _hit = self.cast_hits(snapshot, c2w, K, pixels)
        return pts, idx

    def cast_hits(self, snapshot, c2w: np.ndarray, K: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`cast`, and which of the N rays hit (bool [N], in the order of the M points). A hit on a
        deforming part is (its triangle, b1, b2) instead of a point in the part's frame."""
        s = self.surface(snapshot, c2w, K, pixels)
        return s.local, s.obj, s.hit

    def surface(self, snapshot, c2w: np.ndarray, K: np.ndarray, pixels: np.ndarray):
        """Everything the rays through pixels [N, 2] meet (datagen.ground_truth.ViewSurface): which
        hit, and per hit its point in its part's frame (or triangle and barycentric coordinates on
        a deforming part), its part, its world point and its world shading normal (the triangle's
        corner normals interpolated at the hit, as the renderer shades it; the face normal on a flat
        face)."""
        from datagen.ground_truth import ViewSurface

        bvh, owner, mats, firsts, parts, corner = snapshot
        rays = np.concatenate([pixels, np.ones((len(pixels), 1))], 1) @ np.linalg.inv(K).T @ c2w[:3, :3].T
        origin = mathutils.Vector(c2w[:3, 3].tolist())
        cast, Vector = bvh.ray_cast, mathutils.Vector
        pts, faces, hit = [], [], np.zeros(len(rays), bool)
        for n, d in enumerate(rays.tolist()):
            loc, _normal, face, _dist = cast(origin, Vector(d))
            if face is not None:
                pts.append(tuple(loc))
                faces.append(face)
                hit[n] = True
        if not pts:
            empty = np.zeros((0, 3))
            return ViewSurface(hit, empty, np.zeros(0, np.int64), empty, empty)
        pts, faces = np.array(pts, np.float64), np.array(faces, np.int64)
        idx = owner[faces]
        normal = shading_normals(pts, faces, parts, firsts, owner, corner)
        inv = np.linalg.inv(mats[idx])
        local = np.einsum("nij,nj->ni", inv[:, :3, :3], pts) + inv[:, :3, 3]
        for o in self.deforming:
            sel = idx == o
            if sel.any():
                world, tri = parts[o]
                f = faces[sel] - firsts[o]
                b1, b2 = barycentric(pts[sel], world[tri[f, 0]], world[tri[f, 1]], world[tri[f, 2]])
                local[sel] = np.stack([f.astype(np.float64), b1, b2], -1)
        return ViewSurface(hit, local, idx, pts, normal)


def shading_normals(pts: np.ndarray, faces: np.ndarray, parts: list, firsts: np.ndarray, owner: np.ndarray,
                    corner: np.ndarray) -> np.ndarray:
    """Unit world shading normals [M, 3] at hit points pts [M, 3] on triangles `faces` [M] (global
    indices; owner [F] their part, firsts the part's first triangle, parts (world vertices, triangles)
    per part, corner [F, 3, 3] world corner normals): the corner normals interpolated with the hit's
    barycentric coordinates, as the renderer shades a smooth face (a flat face's corners agree)."""
    o = owner[faces]
    tv = np.empty((len(faces), 3, 3))
    for part in np.unique(o):
        sel = o == part
        world, tri = parts[part]
        tv[sel] = world[tri[faces[sel] - firsts[part]]]
    b1, b2 = barycentric(pts, tv[:, 0], tv[:, 1], tv[:, 2])
    c = corner[faces]
    n = (1.0 - b1 - b2)[:, None] * c[:, 0] + b1[:, None] * c[:, 1] + b2[:, None] * c[:, 2]
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def deform_check_taus(tau: np.ndarray) -> np.ndarray:
    return tau[np.unique(np.linspace(0, len(tau) - 1, N_DEFORM_CHECKS).round().astype(int))]


def sample_scene_motion(tau: np.ndarray, centers: np.ndarray, poses: np.ndarray, K: np.ndarray, width: int,
                        height: int, stride: int):
    """Everything the blur measurement needs from Blender, for the scene currently built.

    tau [T] normalised rendered times; centers [J] rendered-frame indices of the blurred frames;
    poses [C, T, 4, 4] OpenCV c2w. Returns (PartMotion over tau, samples {(camera, j): (local points
    [N, 3], part index [N])}). Raises TopologyChangeError if a part's mesh topology changes.
    """
    sampler = GeometrySampler()
    sampler.find_deforming(deform_check_taus(tau))
    motion = sampler.motion(tau)
    pixels = pixel_grid(width, height, stride)
    samples = {}
    for j, i in enumerate(centers):
        R.set_time(float(tau[i]))
        snap = sampler.snapshot()
        for k in range(poses.shape[0]):
            samples[(k, j)] = sampler.cast(snap, poses[k, i], K, pixels)
    return motion, samples


def dynamic_masks(tau: np.ndarray, views: list[tuple[int, int]], poses: np.ndarray, K: np.ndarray, width: int,
                  height: int, threshold_px: float) -> dict[tuple[int, int], np.ndarray]:
    """The dynamic mask (datagen.dynamic) of every view (camera k, rendered-time index i), for the scene
    currently built: a ray through every pixel at time tau[i], each hit tracked over the whole clip
    (deforming parts included). poses [C, T, 4, 4] OpenCV c2w."""
    from datagen.dynamic import mask_image, surface_motion_px

    sampler = GeometrySampler()
    sampler.find_deforming(deform_check_taus(tau))
    motion = sampler.motion(tau)
    pixels = pixel_grid(width, height, 1)
    out = {}
    for i in sorted({i for _, i in views}):
        R.set_time(float(tau[i]))
        snap = sampler.snapshot()
        for k in sorted({k for k, j in views if j == i}):
            local, obj, hit = sampler.cast_hits(snap, poses[k, i], K, pixels)
            out[(k, i)] = mask_image(hit, surface_motion_px(local, obj, motion, poses[k, i], K[0, 0], i),
                                     width, height, threshold_px)
    return out


class SurfaceTracer:
    """The ground truth's raw material for the scene currently built (datagen.ground_truth): its parts'
    names, their motion over the rendered times tau [T] (blur_geometry.PartMotion), and what every
    pixel's ray meets in a view at one time. TopologyChangeError names a part whose mesh topology
    changes (its surface points cannot be tracked)."""

    def __init__(self, tau: np.ndarray):
        self.tau = tau
        self.sampler = GeometrySampler()
        self.sampler.find_deforming(deform_check_taus(tau))
        self.motion = self.sampler.motion(tau)
        self.names = [o.name for o in self.sampler.objects]
        # part index -> the scene's parts it was joined from (blender_scenes.common.consolidate)
        self.joined = {n: json.loads(o[JOINED_PARTS]) for n, o in enumerate(self.sampler.objects) if JOINED_PARTS in o}

    def views_at(self, i: int, c2w: dict[int, np.ndarray], K: np.ndarray, width: int, height: int) -> dict:
        """{camera k: ViewSurface} at rendered-time index i for the cameras' OpenCV poses c2w {k: [4, 4]}."""
        R.set_time(float(self.tau[i]))
        snap = self.snapshot = self.sampler.snapshot()
        pixels = pixel_grid(width, height, 1)
        return {k: self.sampler.surface(snap, pose, K, pixels) for k, pose in sorted(c2w.items())}

    def visible(self, points: np.ndarray, c2w: np.ndarray) -> np.ndarray:
        """bool [M]: whether each world point [M, 3] is seen from the centre of the camera c2w [4, 4] at
        the time of the last views_at: the ray to it (datagen.ground_truth.ray_stops) meets no surface of
        that time's geometry before it."""
        from datagen.ground_truth import ray_stops

        bvh = self.snapshot[0]
        dirs, dist = ray_stops(c2w[:3, 3], np.asarray(points, np.float64))
        origin, Vector, cast = mathutils.Vector(c2w[:3, 3].tolist()), mathutils.Vector, bvh.ray_cast
        return np.array([cast(origin, Vector(d), float(r))[2] is None for d, r in zip(dirs.tolist(), dist.tolist())],
                        bool).reshape(len(dist))
