"""rubiks_cube: a 3x3x3 puzzle cube whose top and bottom layers turn while the cube tumbles."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T

FACE_COLOURS = {  # outward normal -> sticker colour
    (0, 0, 1): (0.95, 0.95, 0.95), (0, 0, -1): (0.98, 0.85, 0.1),
    (1, 0, 0): (0.8, 0.08, 0.08), (-1, 0, 0): (0.98, 0.45, 0.05),
    (0, 1, 0): (0.05, 0.3, 0.85), (0, -1, 0): (0.05, 0.6, 0.2),
}


def sticker_texture(rng, colour) -> np.ndarray:
    img = T.mottled(rng, 64, colour, 0.05)
    img[:5], img[-5:], img[:, :5], img[:, -5:] = 0.05, 0.05, 0.05, 0.05  # dark rim
    img[10:14, 10:30] = np.clip(np.asarray(colour) * 1.25 + 0.1, 0, 1)   # a highlight stroke
    return img


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    s, gap = 0.32, 0.012
    body = C.material("plastic", T.mottled(rng, 64, (0.04, 0.04, 0.045), 0.3))
    stickers = {n: C.material(f"sticker{i}", sticker_texture(rng, c)) for i, (n, c) in enumerate(FACE_COLOURS.items())}
    cube = C.pivot("cube", (0.0, 0.0, 0.55))
    layers = {z: C.pivot(f"layer{z}", (0, 0, 0), cube) for z in (-1, 0, 1)}
    for x in (-1, 0, 1):
        for y in (-1, 0, 1):
            for z in (-1, 0, 1):
                parent = layers[z]
                pos = (x * (s + gap), y * (s + gap), z * (s + gap))
                C.box(f"cubie{x}{y}{z}", (s, s, s), pos, body, parent, tex_scale=s)
                for normal, mat in stickers.items():
                    axis = int(np.argmax(np.abs(normal)))
                    if (x, y, z)[axis] != normal[axis]:
                        continue
                    size = [0.26, 0.26, 0.26]
                    size[axis] = 0.012
                    loc = list(pos)
                    loc[axis] += normal[axis] * (s / 2 + 0.004)
                    C.box(f"sticker{x}{y}{z}_{axis}{normal[axis]}", size, loc, mat, parent, tex_scale=0.26)
    quarter = math.pi / 2 * m
    C.keyframes(layers[1], "rotation_euler", [(0, 0, 0), (0, 0, quarter), (0, 0, quarter)], [0.0, 0.45, 1.0])
    C.keyframes(layers[-1], "rotation_euler", [(0, 0, 0), (0, 0, 0), (0, 0, -quarter)], [0.0, 0.5, 0.95])
    C.keyframes(cube, "rotation_euler", [(0.0, 0.0, 0.0), (0.25 * m, 0.15 * m, 0.6 * m)], [0.0, 1.0])
    C.sun_and_world()
