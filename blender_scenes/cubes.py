"""cubes: five textured cubes translating and spinning around the centre."""
import math

import numpy as np

from blender_scenes import common as C
from blender_scenes import textures as T


def build(cfg) -> None:
    rng = np.random.default_rng(cfg.seed)
    m = cfg.motion_strength
    looks = [
        T.checker(128, 8, (0.9, 0.9, 0.85), (0.15, 0.2, 0.5)),
        T.bricks(rng, 128),
        T.wood(rng, 128),
        T.tiles(rng, 128, 6, (0.95, 0.8, 0.3), (0.2, 0.2, 0.2)),
        T.stripes(128, 10, (0.85, 0.2, 0.2), (0.95, 0.95, 0.9)),
    ]
    for i, tex in enumerate(looks):
        mat = C.material(f"cube{i}", tex)
        size = 0.45 + 0.1 * (i % 3)
        a0 = 2 * math.pi * i / len(looks)
        r0, r1 = 0.75, 0.75 + 0.35 * m * (1 if i % 2 else -1)
        z0 = 0.35 + 0.25 * (i % 2)
        obj = C.box(f"cube{i}", (size, size, size), mat=mat, tex_scale=size)
        taus = np.linspace(0, 1, 5)
        for tau in taus:
            a = a0 + m * 0.9 * tau * (1 if i % 2 else -1)
            r = r0 + (r1 - r0) * math.sin(math.pi * tau)
            z = z0 + 0.3 * m * math.sin(2 * math.pi * tau + i)
            C.key(obj, "location", (r * math.cos(a), r * math.sin(a), z), tau)
            C.key(obj, "rotation_euler", (m * 1.5 * tau * (i % 3 - 1), m * 1.2 * tau, m * 2.5 * tau * (1 if i % 2 else -1)), tau)
    C.sun_and_world()
