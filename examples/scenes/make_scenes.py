"""Make the two example scenes of docs/guides/your_scene.md with
Blender's Python API, as a user would in Blender: nothing is downloaded.

    .venv/bin/python examples/scenes/make_scenes.py examples/scenes/out

- walker.blend: an armature-rigged figure, one mesh bent by three bones (its skin deforms), walking
  forward across a ground tile while its arms swing; 2 s at 24 fps.
- spinner.glb: a rigid asset exported to glTF binary: a chequered crate turning and bobbing beside a
  spinning drum; 1 s at 24 fps.

Only `bpy` and `numpy` are used, not the toolkit.
"""
import math
import sys
from pathlib import Path

import bpy
import numpy as np


def checker(name: str, a, b, n: int = 8, size: int = 64):
    """A material with an image texture of n x n squares (Workbench shows image textures)."""
    img = bpy.data.images.new(name, size, size)
    cell = (np.indices((size, size)).sum(0) // (size // n)) % 2
    rgba = np.where(cell[..., None] == 0, np.array([*a, 1.0]), np.array([*b, 1.0]))
    img.pixels.foreach_set(rgba.astype(np.float32).ravel())
    img.pack()
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex.interpolation = "Closest"
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def cube(name, size, location, mat, cuts: int = 0):
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=location)
    obj = bpy.context.active_object
    obj.name = name
    obj.scale = size
    bpy.ops.object.transform_apply(scale=True)
    if cuts:
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.subdivide(number_cuts=cuts)
        bpy.ops.object.mode_set(mode="OBJECT")
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.cube_project(cube_size=0.5)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.data.materials.append(mat)
    return obj


def key(obj, path, value, frame, index=-1):
    setattr(obj, path, value) if index < 0 else getattr(obj, path).__setitem__(index, value)
    obj.keyframe_insert(data_path=path, frame=frame, index=index)


def walker(out: Path) -> Path:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.fps, sc.frame_start, sc.frame_end = 24, 1, 49
    cube("ground", (3.0, 1.6, 0.05), (0.0, 0.0, -0.025), checker("ground", (0.35, 0.3, 0.25), (0.6, 0.55, 0.45)))
    body = cube("figure", (0.3, 0.2, 1.2), (0.0, 0.0, 0.6), checker("cloth", (0.8, 0.2, 0.1), (0.95, 0.8, 0.2)), cuts=8)
    arms = cube("arms", (0.1, 0.9, 0.1), (0.0, 0.0, 0.95), checker("arms", (0.1, 0.3, 0.8), (0.8, 0.9, 1.0)), cuts=6)
    bpy.ops.object.select_all(action="DESELECT")
    body.select_set(True)
    arms.select_set(True)
    bpy.context.view_layer.objects.active = body
    bpy.ops.object.join()                          # one skin for the whole figure
    # armature: a spine of two bones (hips -> chest) and one bone across the shoulders
    arm_data = bpy.data.armatures.new("rig")
    rig = bpy.data.objects.new("rig", arm_data)
    sc.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    bones = {}
    for name, head, tail, parent in (("hips", (0, 0, 0.0), (0, 0, 0.6), None), ("chest", (0, 0, 0.6), (0, 0, 1.2), "hips"),
                                     ("shoulders", (0, 0, 0.95), (0, 0.45, 0.95), "chest")):
        b = arm_data.edit_bones.new(name)
        b.head, b.tail = head, tail
        if parent:
            b.parent = bones[parent]
        bones[name] = b
    bpy.ops.object.mode_set(mode="OBJECT")
    # weights by height (hips below 0.5 m, chest above, blended in between; the arms follow the shoulders)
    co = np.array([v.co[:] for v in body.data.vertices]) @ np.array(body.matrix_world)[:3, :3].T + np.array(body.matrix_world)[:3, 3]
    groups = {n: body.vertex_groups.new(name=n) for n in bones}
    for i, (x, y, z) in enumerate(co):
        if abs(y) > 0.16:
            groups["shoulders"].add([i], 1.0, "REPLACE")
            continue
        w = float(np.clip((z - 0.45) / 0.3, 0.0, 1.0))
        groups["hips"].add([i], 1.0 - w, "REPLACE")
        groups["chest"].add([i], w, "REPLACE")
    mod = body.modifiers.new("rig", "ARMATURE")
    mod.object = rig
    body.parent = rig                              # the skin goes where the rig goes; the bones bend it
    # the walk: the rig moves forward while the chest sways and the shoulders swing
    for f in range(1, 50, 4):
        phase = 2 * math.pi * (f - 1) / 24
        key(rig, "location", -1.0 + 2.0 * (f - 1) / 48, f, index=0)
        pb = rig.pose.bones
        pb["chest"].rotation_mode = pb["shoulders"].rotation_mode = "XYZ"
        pb["chest"].rotation_euler = (0.25 * math.sin(phase), 0.0, 0.0)
        pb["chest"].keyframe_insert("rotation_euler", frame=f)
        pb["shoulders"].rotation_euler = (0.0, 0.0, 0.6 * math.sin(phase))
        pb["shoulders"].keyframe_insert("rotation_euler", frame=f)
    path = out / "walker.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=False)
    return path


def spinner(out: Path) -> Path:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.fps, sc.frame_start, sc.frame_end = 24, 1, 25
    cube("base", (1.6, 1.6, 0.05), (0.0, 0.0, -0.025), checker("base", (0.3, 0.3, 0.3), (0.7, 0.7, 0.7)))
    crate = cube("crate", (0.5, 0.5, 0.5), (-0.35, 0.0, 0.3), checker("crate", (0.6, 0.35, 0.1), (0.9, 0.75, 0.4)))
    bpy.ops.mesh.primitive_cylinder_add(radius=0.22, depth=0.5, location=(0.4, 0.0, 0.3), vertices=24)
    drum = bpy.context.active_object
    drum.name = "drum"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.cylinder_project()
    bpy.ops.object.mode_set(mode="OBJECT")
    drum.data.materials.append(checker("drum", (0.1, 0.5, 0.2), (0.85, 0.95, 0.85), n=6))
    for f in (1, 13, 25):
        u = (f - 1) / 24
        key(crate, "rotation_euler", 2 * math.pi * u, f, index=2)
        key(crate, "location", 0.3 + 0.15 * math.sin(2 * math.pi * u), f, index=2)
        key(drum, "rotation_euler", -4 * math.pi * u, f, index=2)
    path = out / "spinner.glb"
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", export_animations=True)
    return path


def main() -> int:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "examples/scenes/out")
    out.mkdir(parents=True, exist_ok=True)
    for path in (walker(out), spinner(out)):
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
