"""hinge: a panel on a two-knuckle hinge swinging open and shut against a fixed wooden block."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    wood = C.material("wood", T.wood(rng, 128))
    steel = C.material("steel", T.stripes(64, 12, (0.62, 0.63, 0.66), (0.45, 0.46, 0.5), horizontal=True))
    panel = C.material("panel", T.labelled(rng, 128, (0.2, 0.45, 0.75), ink=(0.95, 0.92, 0.8), n_marks=30))
    screw = C.material("screw", T.checker(32, 2, (0.3, 0.3, 0.32), (0.7, 0.7, 0.72)))
    C.box("base", (0.5, 1.2, 1.0), (-0.3, 0.0, 0.5), wood, tex_scale=0.6)
    C.box("foot", (1.6, 1.5, 0.08), (0.25, 0.0, 0.04), wood, tex_scale=0.6)
    axis_x, axis_y = -0.03, 0.6
    for z in (0.3, 0.75):  # knuckles and leaves of the hinge
        C.cylinder(f"knuckle{z}", 0.045, 0.22, (axis_x, axis_y, z), steel)
        C.box(f"leaf_fixed{z}", (0.012, 0.16, 0.2), (-0.05, axis_y - 0.08, z), steel, tex_scale=0.2)
        for dz in (-0.05, 0.05):
            C.cylinder(f"screw{z}{dz}", 0.018, 0.01, (-0.045, axis_y - 0.1, z + dz), screw, rotation=(0, math.pi / 2, 0))
    door = C.pivot("door", (axis_x, axis_y, 0.0))
    C.box("panel", (0.06, 1.15, 0.95), (0.05, -0.6, 0.52), panel, door, tex_scale=0.5)
    C.box("handle", (0.06, 0.06, 0.25), (0.11, -1.05, 0.55), steel, door, tex_scale=0.2)
    for z in (0.3, 0.75):
        C.box(f"leaf_moving{z}", (0.012, 0.16, 0.2), (0.03, -0.08, z), steel, door, tex_scale=0.2)
    swing = math.radians(75.0) * m
    C.keyframes(door, "rotation_euler", [(0, 0, 0), (0, 0, swing), (0, 0, 0.2 * swing), (0, 0, swing), (0, 0, 0)],
                [0.0, 0.3, 0.55, 0.8, 1.0])
    C.sun_and_world()
