"""calibration: three small coloured balls at known world points on a dark background.

Not part of the dataset: the tests render it to check that the cameras written to cameras.json
project world points exactly where Blender draws them (lens, sensor fit, axes, image row order).
"""
from blender_scenes import common as C

MARKERS = {"red": ((0.0, 0.0, 0.5), (1.0, 0.05, 0.05)),
           "green": ((0.7, 0.3, 0.2), (0.05, 1.0, 0.05)),
           "blue": ((-0.5, -0.6, 0.9), (0.05, 0.05, 1.0))}


def build(cfg) -> None:
    import numpy as np

    for name, (pos, rgb) in MARKERS.items():
        C.sphere(name, 0.06, pos, C.material(name, np.ones((4, 4, 3)) * np.asarray(rgb)))
