"""mc_toy: a blocky Minecraft-style figure walking in place, swinging arms and legs and turning its head."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T

SKIN, HAIR, EYE, MOUTH = (0.85, 0.62, 0.45), (0.3, 0.18, 0.08), (0.25, 0.3, 0.8), (0.5, 0.25, 0.2)
SHIRT, SHIRT2, PANTS, SHOE = (0.1, 0.65, 0.7), (0.05, 0.5, 0.55), (0.2, 0.2, 0.55), (0.3, 0.3, 0.32)

FACE = ["HHHHHHHH",
        "HHHHHHHH",
        "HSSSSSSH",
        "SSSSSSSS",
        "SWESSEWS",
        "SSSNNSSS",
        "SSMMMMSS",
        "SSSSSSSS"]


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    pal = {"H": HAIR, "S": SKIN, "E": EYE, "W": (0.95, 0.95, 0.95), "N": np.array(SKIN) * 0.8, "M": MOUTH}
    face = C.material("face", T.pixel_art(FACE, pal, 64), nearest=True)
    head_side = C.material("head", T.pixel_art(["HHHHHHHH", "HHHHHHHH", "HHHSSHHH", "HSSSSSSH",
                                                  "SSSSSSSS", "SSSNSSSS", "SSSSSSSS", "SSSSSSSS"], pal, 64), nearest=True)
    shirt = C.material("shirt", T.random_pixels(rng, 8, {"a": SHIRT, "b": SHIRT2, "c": np.array(SHIRT) * 1.15}, 64), nearest=True)
    arm_pal = {"a": SHIRT, "b": SHIRT2, "s": SKIN, "t": np.array(SKIN) * 0.9}
    arm_mat = C.material("arm", T.pixel_art(["abab", "baba", "abab", "stst", "tsts", "stst", "tsts", "stst"], arm_pal, 64), nearest=True)
    pants_pal = {"a": PANTS, "b": np.array(PANTS) * 0.8, "c": SHOE, "d": np.array(SHOE) * 0.8}
    pants = C.material("pants", T.pixel_art(["abab", "baba", "abab", "baba", "abab", "baba", "cdcd", "dcdc"], pants_pal, 64), nearest=True)
    u = 0.12  # one "pixel" block
    figure = C.pivot("figure", (0, 0, 0))
    hips = 6 * u
    legs = []
    for side in (-1, 1):
        hip = C.pivot(f"hip{side}", (0, side * 1.02 * u, hips), figure)
        C.box(f"leg{side}", (2 * u, 1.96 * u, 6 * u), (0, 0, -3 * u), pants, hip, tex_scale=6 * u)
        legs.append(hip)
    C.box("body", (2 * u, 4 * u, 6 * u), (0, 0, hips + 3 * u), shirt, figure, tex_scale=2 * u)
    arms = []
    for side in (-1, 1):
        shoulder = C.pivot(f"shoulder{side}", (0, side * 3 * u, hips + 5.5 * u), figure)
        C.box(f"arm{side}", (2 * u, 1.96 * u, 6 * u), (0, 0, -2.5 * u), arm_mat, shoulder, tex_scale=6 * u)
        arms.append(shoulder)
    neck = C.pivot("neck", (0, 0, hips + 6 * u), figure)
    C.box("head", (8 * u * 0.999, 8 * u, 8 * u), (0, 0, 4 * u), head_side, neck, tex_scale=8 * u)
    C.box("face", (0.01, 8 * u, 8 * u), (4 * u + 0.006, 0, 4 * u), face, neck, tex_scale=8 * u)
    swing = math.radians(40.0) * m
    taus = np.linspace(0.0, 1.0, 17)
    for i, tau in enumerate(taus):
        a = swing * math.sin(2 * math.pi * 2 * tau)
        for j, (hip, shoulder) in enumerate(zip(legs, arms)):
            sign = 1 if j == 0 else -1
            C.key(hip, "rotation_euler", (0, sign * a, 0), tau)
            C.key(shoulder, "rotation_euler", (0, -sign * a, 0), tau)
        C.key(neck, "rotation_euler", (0, 0, 0.5 * m * math.sin(2 * math.pi * tau)), tau)
        C.key(figure, "location", (0, 0, 0.04 * m * abs(math.sin(2 * math.pi * 2 * tau))), tau)
    C.keyframes(figure, "rotation_euler", [(0, 0, -0.6 * m), (0, 0, 0.6 * m)], [0.0, 1.0])
    C.sun_and_world()
