"""Building blocks for the procedural scenes: textured boxes and primitives, pivots, keyframes.

Boxes get UVs in world units (a texture tile spans `tex_scale` metres on every face), so texel
density does not depend on a part's shape. Images are generated in NumPy (`textures.py`) and
packed into the .blend; nothing is loaded from disk.
"""
from __future__ import annotations

import json
import math

import bpy
import bmesh
import numpy as np

ANIM_FRAMES = 1000  # scene animation spans Blender frames 1 .. 1 + ANIM_FRAMES over normalised time [0, 1]


def frame_of(tau: float) -> float:
    """Blender frame number of normalised clip time tau in [0, 1] (scene builders keyframe with it)."""
    return 1.0 + ANIM_FRAMES * tau

_image_cache: dict[str, bpy.types.Image] = {}


def image(name: str, rgb: np.ndarray, nearest: bool = False) -> bpy.types.Image:
    """A packed sRGB image from an array [H, W, 3] in [0, 1] (row 0 = top)."""
    h, w = rgb.shape[:2]
    img = bpy.data.images.new(name, w, h, alpha=False, float_buffer=False)
    rgba = np.ones((h, w, 4), np.float32)
    rgba[..., :3] = np.clip(rgb[::-1], 0, 1)  # Blender stores the bottom row first
    img.pixels.foreach_set(rgba.ravel())
    img.pack()
    img["nearest"] = nearest
    return img


def material(name: str, rgb: np.ndarray, nearest: bool = False, roughness: float = 0.6) -> bpy.types.Material:
    """Material whose base colour is the texture (Workbench shows it in TEXTURE mode)."""
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    tex = nt.nodes.new("ShaderNodeTexImage")
    tex.image = image(name, rgb, nearest)
    tex.interpolation = "Closest" if nearest else "Linear"
    bsdf = nt.nodes.get("Principled BSDF")
    nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    bsdf.inputs["Roughness"].default_value = roughness
    nt.nodes.active = tex
    mean = np.clip(rgb.reshape(-1, 3).mean(0), 0, 1)
    mat.diffuse_color = (*mean, 1.0)
    return mat


def _link(obj, parent=None, collection=None):
    (collection or bpy.context.scene.collection).objects.link(obj)
    if parent is not None:
        obj.parent = parent
    return obj


def box(name, size, location=(0, 0, 0), mat=None, parent=None, rotation=(0, 0, 0), tex_scale=1.0, bevel=0.0):
    """Axis-aligned box of `size` (x, y, z) centred at `location` (in the parent's frame)."""
    sx, sy, sz = (s / 2 for s in size)
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    v = [bm.verts.new((x, y, z)) for x in (-sx, sx) for y in (-sy, sy) for z in (-sz, sz)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    for f in faces:
        bm.faces.new([v[i] for i in f])
    bm.normal_update()
    uv = bm.loops.layers.uv.new("UVMap")
    for face in bm.faces:
        n = face.normal
        axis = int(np.argmax(np.abs([n.x, n.y, n.z])))
        a, b = [(1, 2), (0, 2), (0, 1)][axis]
        for loop in face.loops:
            co = loop.vert.co
            loop[uv].uv = (co[a] / tex_scale + 0.5, co[b] / tex_scale + 0.5)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location, obj.rotation_euler = location, rotation
    if mat is not None:
        mesh.materials.append(mat)
    if bevel > 0:
        mod = obj.modifiers.new("bevel", "BEVEL")
        mod.width, mod.segments = bevel, 2
    return _link(obj, parent)


def _primitive(op, name, mat, parent, location, rotation, **kwargs):
    op(location=(0, 0, 0), **kwargs)
    obj = bpy.context.active_object
    obj.name = name
    obj.location, obj.rotation_euler = location, rotation
    if mat is not None:
        obj.data.materials.append(mat)
    if parent is not None:
        obj.parent = parent
    return obj


def cylinder(name, radius, depth, location=(0, 0, 0), mat=None, parent=None, rotation=(0, 0, 0), vertices=32):
    return _primitive(bpy.ops.mesh.primitive_cylinder_add, name, mat, parent, location, rotation,
                      radius=radius, depth=depth, vertices=vertices)


def sphere(name, radius, location=(0, 0, 0), mat=None, parent=None, rotation=(0, 0, 0), segments=32):
    obj = _primitive(bpy.ops.mesh.primitive_uv_sphere_add, name, mat, parent, location, rotation,
                     radius=radius, segments=segments, ring_count=segments // 2)
    for poly in obj.data.polygons:
        poly.use_smooth = True
    return obj


def capsule(name, radius, length, location=(0, 0, 0), mat=None, parent=None, rotation=(0, 0, 0)):
    """A pill: cylinder with hemispherical caps, along the local z axis."""
    root = pivot(name, location, parent, rotation)
    cylinder(f"{name}.body", radius, length, mat=mat, parent=root)
    for s in (-1, 1):
        sphere(f"{name}.cap{s}", radius, location=(0, 0, s * length / 2), mat=mat, parent=root)
    return root


def pivot(name, location=(0, 0, 0), parent=None, rotation=(0, 0, 0)):
    """An empty to animate a group of parts about `location`."""
    obj = bpy.data.objects.new(name, None)
    obj.location, obj.rotation_euler = location, rotation
    return _link(obj, parent)


def key(obj, path: str, value, tau: float, interpolation: str = "BEZIER") -> None:
    """Set obj.<path> = value and keyframe it at normalised clip time tau."""
    setattr(obj, path, value)
    obj.keyframe_insert(data_path=path, frame=frame_of(tau))
    if obj.animation_data and obj.animation_data.action:
        for fc in _fcurves(obj.animation_data.action):
            for kp in fc.keyframe_points:
                kp.interpolation = interpolation


def _fcurves(action):
    """F-curves of an action (Blender 4.4+ keeps them in layered channel bags)."""
    if hasattr(action, "fcurves") and len(getattr(action, "fcurves", [])):
        return list(action.fcurves)
    curves = []
    for layer in getattr(action, "layers", []):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", []):
                curves.extend(bag.fcurves)
    return curves


def keyframes(obj, path: str, values, taus, interpolation: str = "BEZIER") -> None:
    for value, tau in zip(values, taus):
        key(obj, path, value, tau, interpolation)


def sun_and_world(strength: float = 3.0, direction=(0.4, -0.3, 0.85)) -> None:
    """A sun lamp for path-traced engines (Workbench uses its studio light instead)."""
    data = bpy.data.lights.new("sun", "SUN")
    data.energy = strength
    obj = bpy.data.objects.new("sun", data)
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    obj.rotation_euler = (math.acos(d[2]), 0.0, math.atan2(d[1], d[0]) + math.pi / 2)
    _link(obj)


def _is_animated(obj) -> bool:
    return bool(obj.animation_data and obj.animation_data.action)


JOINED_PARTS = "e4dgs_joined_parts"     # custom property: JSON list of the parts an object was joined from


def consolidate() -> int:
    """Join the non-animated mesh parts that share a parent into one object per parent.

    Workbench draws (and casts shadows from) each object separately, so a bulldozer of 70 studs and
    plates renders several times slower than the same geometry as a few objects. Materials and UVs
    are kept per face; animated objects and their pivots are untouched. Returns the objects removed.
    """
    groups: dict = {}
    for obj in bpy.context.scene.objects:
        if obj.type == "MESH" and not _is_animated(obj) and not obj.children and not obj.modifiers:
            groups.setdefault(obj.parent, []).append(obj)
    removed = 0
    for parent, parts in groups.items():
        if len(parts) < 2:
            continue
        target = parts[0]
        # The joined object keeps its first part's name; what it holds is recorded for the ground
        # truth's object table (a room's "floor" is its whole static shell and fixtures).
        target[JOINED_PARTS] = json.dumps([p.name for p in parts])
        with bpy.context.temp_override(active_object=target, object=target,
                                       selected_objects=parts, selected_editable_objects=parts):
            bpy.ops.object.join()
        removed += len(parts) - 1
    return removed
