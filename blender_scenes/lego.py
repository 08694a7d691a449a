"""lego: a Lego-style bulldozer (studded yellow bricks on tracks) raising and lowering its blade arm."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T

YELLOW, DARK, GREY = (0.95, 0.72, 0.08), (0.12, 0.12, 0.13), (0.55, 0.56, 0.58)


def studs(parent, name, x0, x1, y0, y1, z, mat, pitch=0.16):
    for ix, x in enumerate(np.arange(x0, x1 + 1e-6, pitch)):
        for iy, y in enumerate(np.arange(y0, y1 + 1e-6, pitch)):
            C.cylinder(f"{name}.stud{ix}_{iy}", 0.048, 0.06, (x, y, z + 0.03), mat, parent, vertices=16)


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    yellow = C.material("yellow", T.stripes(128, 8, YELLOW, np.array(YELLOW) * 0.88, horizontal=True))
    yellow_dots = C.material("yellow_plain", T.mottled(rng, 64, YELLOW, 0.06))
    dark = C.material("tread", T.stripes(128, 16, DARK, (0.3, 0.3, 0.32)))
    grey = C.material("grey", T.mottled(rng, 64, GREY, 0.1))
    glass = C.material("glass", T.checker(64, 4, (0.2, 0.3, 0.4), (0.1, 0.15, 0.22)))
    root = C.pivot("bulldozer", (0.0, 0.0, 0.0))
    for side in (-1, 1):  # tracks with wheels
        C.box(f"track{side}", (1.5, 0.28, 0.3), (0.0, side * 0.42, 0.15), dark, root, tex_scale=0.4)
        for ix, x in enumerate((-0.6, -0.2, 0.2, 0.6)):
            C.cylinder(f"wheel{side}_{ix}", 0.12, 0.04, (x, side * 0.57, 0.15), grey, root, rotation=(math.pi / 2, 0, 0))
    C.box("chassis", (1.3, 0.74, 0.24), (0.0, 0.0, 0.42), yellow, root, tex_scale=0.5)
    studs(root, "chassis", -0.56, 0.56, -0.29, 0.29, 0.54, yellow_dots)
    C.box("cabin", (0.5, 0.62, 0.5), (-0.35, 0.0, 0.79), yellow, root, tex_scale=0.5)
    for side in (-1, 1):
        C.box(f"window{side}", (0.36, 0.02, 0.26), (-0.35, side * 0.315, 0.86), glass, root, tex_scale=0.3)
    C.box("windscreen", (0.02, 0.5, 0.26), (-0.095, 0.0, 0.86), glass, root, tex_scale=0.3)
    studs(root, "cabin", -0.51, -0.19, -0.24, 0.24, 1.04, yellow_dots)
    C.cylinder("exhaust", 0.04, 0.35, (0.2, 0.22, 0.72), grey, root, vertices=16)
    # blade arm: pivots at the chassis front, blade at the tip
    arm = C.pivot("arm", (0.35, 0.0, 0.5), root)
    for side in (-1, 1):
        C.box(f"arm{side}", (0.75, 0.08, 0.1), (0.35, side * 0.4, -0.05), yellow, arm, rotation=(0, 0.35, 0), tex_scale=0.3)
    blade = C.box("blade", (0.1, 1.2, 0.38), (0.78, 0.0, -0.22), yellow, arm, tex_scale=0.4)
    C.box("blade_edge", (0.12, 1.22, 0.05), (0.8, 0.0, -0.42), grey, arm, tex_scale=0.3)
    studs(arm, "blade", 0.78, 0.78, -0.5, 0.5, -0.03, yellow_dots, pitch=0.2)
    del blade
    lift = math.radians(32.0) * m
    C.keyframes(arm, "rotation_euler", [(0, 0, 0), (0, -lift, 0), (0, -0.3 * lift, 0), (0, -lift, 0), (0, 0, 0)],
                [0.0, 0.3, 0.5, 0.75, 1.0])
    # the whole machine creeps forward and turns a little
    C.keyframes(root, "location", [(-0.15 * m, 0, 0), (0.15 * m, 0, 0)], [0.0, 1.0])
    C.keyframes(root, "rotation_euler", [(0, 0, -0.15 * m), (0, 0, 0.15 * m)], [0.0, 1.0])
    C.sun_and_world()
