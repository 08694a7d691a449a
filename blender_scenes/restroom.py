"""restroom: a tiled public restroom; two stall doors swing, a bin rolls across the floor, a dryer flap moves."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T
from blender_scenes.rooms import shell


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    floor = C.material("floor_tiles", T.checker(256, 16, (0.85, 0.85, 0.82), (0.2, 0.22, 0.25)))
    wall = C.material("wall_tiles", T.tiles(rng, 256, 12, (0.88, 0.92, 0.95), (0.45, 0.5, 0.55)))
    wall2 = C.material("wall_tiles2", T.tiles(rng, 256, 12, (0.55, 0.75, 0.7), (0.3, 0.35, 0.35)))
    shell(5.5, 5.5, 4.0, floor, [wall, wall2, wall2, wall], floor_tex=2.0, wall_tex=2.0)
    partition = C.material("partition", T.labelled(rng, 128, (0.35, 0.45, 0.6), ink=(0.9, 0.9, 0.9), n_marks=10))
    door_mat = C.material("stall_door", T.labelled(rng, 128, (0.6, 0.3, 0.25), ink=(0.95, 0.9, 0.8), n_marks=6))
    ceramic = C.material("ceramic", T.mottled(rng, 64, (0.95, 0.95, 0.93), 0.04))
    steel = C.material("steel", T.stripes(64, 10, (0.7, 0.72, 0.75), (0.55, 0.57, 0.6)))
    mirror = C.material("mirror", T.stripes(128, 5, (0.6, 0.68, 0.72), (0.5, 0.58, 0.62)))
    doors = []
    for i, x in enumerate((-3.5, -1.7)):  # stalls along the north wall
        C.box(f"partition{i}", (0.05, 1.6, 2.0), (x - 0.9, 4.6, 1.1), partition, tex_scale=1.0)
        C.box(f"toilet{i}", (0.45, 0.6, 0.45), (x, 5.05, 0.23), ceramic, tex_scale=0.5)
        C.box(f"tank{i}", (0.5, 0.2, 0.4), (x, 5.35, 0.65), ceramic, tex_scale=0.5)
        hinge = C.pivot(f"door_hinge{i}", (x - 0.88, 3.8, 0.0))
        C.box(f"door{i}", (1.75, 0.05, 1.9), (0.88, 0, 1.1), door_mat, hinge, tex_scale=1.0)
        C.box(f"handle{i}", (0.12, 0.08, 0.04), (1.55, -0.05, 1.1), steel, hinge, tex_scale=0.2)
        doors.append(hinge)
    C.box("partition_end", (0.05, 1.6, 2.0), (-0.8, 4.6, 1.1), partition, tex_scale=1.0)
    for i, y in enumerate((-2.0, 0.0, 2.0)):  # sinks and mirrors along the east wall
        C.box(f"sink{i}", (0.6, 0.8, 0.25), (5.05, y, 0.9), ceramic, tex_scale=0.5)
        C.cylinder(f"tap{i}", 0.03, 0.25, (5.25, y, 1.12), steel)
        C.box(f"mirror{i}", (0.03, 0.9, 1.0), (5.38, y, 1.75), mirror, tex_scale=0.5)
    for n, hinge in enumerate(doors):  # stall doors swing inwards
        a = math.radians(55) * m
        C.keyframes(hinge, "rotation_euler", [(0, 0, 0), (0, 0, a), (0, 0, 0.2 * a), (0, 0, a)],
                    [0.0, 0.35 + 0.1 * n, 0.7, 1.0])
    # a double-sided vanity island in the middle of the room
    counter = C.material("counter", T.labelled(rng, 128, (0.25, 0.25, 0.28), ink=(0.75, 0.75, 0.7), n_marks=25))
    C.box("island", (0.8, 2.2, 0.9), (0.0, 0.6, 0.45), counter, tex_scale=1.0)
    for side in (-1, 1):
        for j, y in enumerate((0.1, 1.1)):
            C.box(f"basin{side}{j}", (0.3, 0.45, 0.08), (side * 0.22, y, 0.94), ceramic, tex_scale=0.5)
            C.cylinder(f"island_tap{side}{j}", 0.025, 0.3, (0.0, y, 1.05), steel)
    C.box("island_mirror", (0.05, 2.0, 0.9), (0.0, 0.6, 1.6), mirror, tex_scale=0.5)
    # a bin rolling over the floor and a hand-dryer flap
    bin_mat = C.material("bin", T.stripes(64, 12, (0.3, 0.6, 0.3), (0.2, 0.4, 0.2)))
    rbin = C.cylinder("bin", 0.3, 0.7, (0, 0, 0.3), bin_mat, rotation=(math.pi / 2, 0, 0))
    C.keyframes(rbin, "location", [(-1.0 * m, -1.0, 0.3), (1.0 * m, 0.2, 0.3)], [0.0, 1.0], "LINEAR")
    C.keyframes(rbin, "rotation_euler", [(math.pi / 2, 0, 0.3), (math.pi / 2 + 5.0 * m, 0, 0.3)], [0.0, 1.0], "LINEAR")
    C.box("dryer", (0.3, 0.5, 0.6), (-5.25, 1.0, 1.4), steel, tex_scale=0.5)
    flap = C.pivot("flap", (-5.1, 1.0, 1.1))
    C.box("flap_panel", (0.02, 0.45, 0.3), (0, 0, -0.15), bin_mat, flap, tex_scale=0.3)
    C.keyframes(flap, "rotation_euler", [(0, 0, 0), (0, -0.9 * m, 0), (0, 0, 0), (0, -0.9 * m, 0)], [0, 0.3, 0.6, 0.9])
    C.sun_and_world()
