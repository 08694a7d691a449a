"""capsule: a capsule-hotel room; pill-shaped capsules roll and orbit in the middle, a pod hatch swings."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T
from blender_scenes.rooms import shell


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    floor = C.material("carpet", T.checker(256, 16, (0.35, 0.3, 0.28), (0.25, 0.22, 0.2)) * T.mottled(rng, 256, (1, 1, 1), 0.15))
    wall = C.material("wall", T.stripes(256, 24, (0.85, 0.82, 0.75), (0.75, 0.72, 0.66)))
    wall2 = C.material("wall2", T.tiles(rng, 256, 8, (0.7, 0.78, 0.85), (0.3, 0.32, 0.35)))
    shell(6.0, 6.0, 4.5, floor, [wall, wall2, wall, wall2], floor_tex=3.0, wall_tex=3.0)
    pod = C.material("pod", T.labelled(rng, 128, (0.92, 0.92, 0.9), ink=(0.2, 0.5, 0.8), n_marks=12))
    hole = C.material("hole", T.checker(64, 4, (0.08, 0.08, 0.1), (0.15, 0.12, 0.1)))
    hatch_mat = C.material("hatch", T.stripes(64, 8, (0.2, 0.5, 0.8), (0.85, 0.88, 0.9)))
    hatches = []
    for row in range(2):  # two stacked rows of pods along the north and west walls
        for i in range(4):
            for wall_name, (x, y, rot) in (("n", (-3.0 + 2.0 * i, 5.0, 0.0)), ("w", (-5.0, -3.0 + 2.0 * i, math.pi / 2))):
                z = 0.6 + 1.3 * row
                p = C.pivot(f"pod_{wall_name}{row}{i}", (x, y, z), rotation=(0, 0, rot))
                C.box(f"pod_shell_{wall_name}{row}{i}", (1.9, 1.8, 1.2), (0, 0, 0), pod, p, tex_scale=1.0)
                C.box(f"pod_hole_{wall_name}{row}{i}", (1.1, 0.02, 0.8), (0, -0.91, 0), hole, p, tex_scale=0.5)
                if row == 0 and i in (1, 2):
                    h = C.pivot(f"hatch_{wall_name}{i}", (-0.55, -0.93, 0), p)
                    C.box(f"hatch_panel_{wall_name}{i}", (1.1, 0.04, 0.8), (0.55, 0, 0), hatch_mat, h, tex_scale=0.5)
                    hatches.append(h)
    for n, h in enumerate(hatches):
        a = math.radians(80) * m
        C.keyframes(h, "rotation_euler", [(0, 0, 0), (0, 0, -a), (0, 0, -0.3 * a)], [0.0, 0.4 + 0.1 * n, 1.0])
    # the capsules in the middle: pills orbiting and rolling around a central table
    table = C.material("table", T.wood(rng, 128, (0.6, 0.42, 0.25)))
    C.cylinder("table_top", 0.6, 0.08, (0, 0, 0.7), table)
    C.cylinder("table_leg", 0.08, 0.7, (0, 0, 0.35), table)
    colours = [((0.9, 0.2, 0.2), (0.95, 0.95, 0.9)), ((0.2, 0.5, 0.9), (0.95, 0.85, 0.2)), ((0.2, 0.7, 0.3), (0.9, 0.9, 0.9))]
    for n, (c1, c2) in enumerate(colours):
        mat = C.material(f"pill{n}", T.stripes(128, 2, c1, c2))
        orbit = C.pivot(f"orbit{n}", (0, 0, 0))
        pill = C.capsule(f"pill{n}", 0.22, 0.5, (1.4, 0, 0.35 + 0.5 * n), mat, orbit, rotation=(math.pi / 2, 0, 0))
        turn = (0.9 + 0.4 * n) * m * (1 if n % 2 else -1)
        C.keyframes(orbit, "rotation_euler", [(0, 0, 2.1 * n), (0, 0, 2.1 * n + turn)], [0.0, 1.0], "LINEAR")
        C.keyframes(pill, "rotation_euler", [(math.pi / 2, 0, 0), (math.pi / 2 + 3.0 * m, 0, 0.5 * m)], [0.0, 1.0], "LINEAR")
    C.sun_and_world()
