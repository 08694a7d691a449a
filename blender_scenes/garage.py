"""garage: a brick garage with shelves; a car drives in and out while the roller door rises and a lamp swings."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T
from blender_scenes.rooms import shell


def car(root, rng) -> None:
    paint = C.material("paint", T.stripes(128, 2, (0.75, 0.1, 0.08), (0.85, 0.85, 0.85), horizontal=True)[:, :] * 0 +
                       T.mottled(rng, 128, (0.75, 0.1, 0.08), 0.05))
    glass = C.material("car_glass", T.checker(64, 2, (0.15, 0.2, 0.28), (0.1, 0.13, 0.18)))
    tyre = C.material("tyre", T.stripes(64, 16, (0.05, 0.05, 0.05), (0.2, 0.2, 0.2)))
    chrome = C.material("chrome", T.mottled(rng, 64, (0.75, 0.75, 0.78), 0.1))
    lights = C.material("lights", T.checker(32, 4, (0.95, 0.9, 0.6), (0.8, 0.7, 0.3)))
    C.box("car_body", (2.4, 1.1, 0.45), (0, 0, 0.45), paint, root, tex_scale=1.0)
    C.box("car_cabin", (1.3, 1.0, 0.42), (-0.15, 0, 0.88), paint, root, tex_scale=1.0)
    for side in (-1, 1):
        C.box(f"car_window{side}", (1.1, 0.02, 0.3), (-0.15, side * 0.505, 0.9), glass, root, tex_scale=0.5)
        for x in (-0.8, 0.8):
            C.cylinder(f"car_wheel{side}{x}", 0.28, 0.2, (x, side * 0.5, 0.28), tyre, root, rotation=(math.pi / 2, 0, 0))
            C.cylinder(f"car_hub{side}{x}", 0.12, 0.22, (x, side * 0.5, 0.28), chrome, root, rotation=(math.pi / 2, 0, 0))
    C.box("car_windscreen", (0.02, 0.9, 0.32), (0.51, 0, 0.88), glass, root, tex_scale=0.5)
    C.box("car_bumper", (0.1, 1.12, 0.12), (1.22, 0, 0.32), chrome, root, tex_scale=0.5)
    C.box("car_headlights", (0.02, 0.9, 0.1), (1.205, 0, 0.55), lights, root, tex_scale=0.5)


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    concrete = C.material("concrete", T.labelled(rng, 256, (0.55, 0.55, 0.52), ink=(0.3, 0.3, 0.28), n_marks=60))
    brick = C.material("brick", T.bricks(rng, 256, rows=10, cols=4))
    brick2 = C.material("brick2", T.bricks(rng, 256, rows=10, cols=4, brick=(0.5, 0.3, 0.2)))
    shell(6.0, 6.0, 4.0, concrete, [brick, brick2, brick, brick2], floor_tex=3.0, wall_tex=2.5)
    wood = C.material("shelf", T.wood(rng, 128, (0.5, 0.35, 0.2)))
    for i, y in enumerate((-3.0, -1.0, 1.0, 3.0)):  # shelves with boxes along the west wall
        for z in (0.6, 1.3, 2.0):
            C.box(f"shelf{i}{z}", (0.6, 1.6, 0.05), (-5.5, y, z), wood, tex_scale=1.0)
            for b in range(3):
                look = T.labelled(rng, 64, rng.uniform(0.3, 0.9, 3), n_marks=8)
                C.box(f"box{i}{z}{b}", (0.45, 0.4, 0.35), (-5.5, y - 0.5 + 0.5 * b, z + 0.2), C.material(f"box{i}{z}{b}", look), tex_scale=0.4)
    C.box("workbench", (0.8, 2.5, 0.9), (0.0, 5.4, 0.45), wood, tex_scale=1.0)
    # roller door in the east wall
    door_mat = C.material("roller", T.stripes(128, 16, (0.7, 0.72, 0.75), (0.45, 0.47, 0.5), horizontal=True))
    door = C.box("roller_door", (0.1, 3.2, 2.6), (5.85, 0.0, 1.3), door_mat, tex_scale=1.6)
    C.keyframes(door, "location", [(5.85, 0, 1.3), (5.85, 0, 1.3 + 2.0 * m)], [0.0, 1.0])
    # the car drives towards the door and back
    root = C.pivot("car", (0, 0, 0))
    car(root, rng)
    C.keyframes(root, "location", [(-1.2 * m, 0.3, 0), (1.2 * m, 0.3, 0), (0.2 * m, 0.3, 0)], [0.0, 0.6, 1.0])
    C.keyframes(root, "rotation_euler", [(0, 0, 0.0), (0, 0, 0.25 * m), (0, 0, 0.1 * m)], [0.0, 0.6, 1.0])
    # a hanging lamp swinging
    lamp_mat = C.material("lamp", T.stripes(64, 6, (0.95, 0.85, 0.3), (0.3, 0.3, 0.3)))
    lamp = C.pivot("lamp", (0.0, -2.0, 3.9))
    C.cylinder("lamp_cord", 0.02, 1.2, (0, 0, -0.6), C.material("cord", T.mottled(rng, 16, (0.1, 0.1, 0.1))), lamp)
    C.cylinder("lamp_shade", 0.3, 0.3, (0, 0, -1.3), lamp_mat, lamp)
    C.keyframes(lamp, "rotation_euler", [(0.5 * m, 0, 0), (-0.5 * m, 0, 0), (0.5 * m, 0, 0)], [0.0, 0.5, 1.0])
    C.sun_and_world()
