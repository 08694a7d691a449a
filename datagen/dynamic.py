"""Dynamic-region masks: which pixels of a test view show a surface that moves in the world.

Whole-image scores of a dynamic scene are dominated by its static part (a room, a table), so the
benchmark also scores the moving pixels alone (DyCheck's masked metrics, Gao et al. 2022). Here a
pixel of a view (camera k at time t) is **dynamic** when the surface point it sees at t moves, at
some time of the clip, by at least THRESHOLD_PX pixels as seen from that view: its largest world
displacement from where it is at t, |X(t') - X(t)| over every rendered t', times fx / z(t), its
depth at t. Camera motion plays no part (the static room is static however fast the camera flies),
and a point turning about an axis it lies on is static. Pixels that see nothing (the background)
are static. The geometry comes from the scene (datagen.render_geometry, bpy); this module is the
pure part and the files:

    <scene>/dynamic/cam<k>/<index>.png   8-bit, 255 = dynamic, one per test view
    <scene>/dynamic/masks.json           the definition, threshold and each view's dynamic fraction
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from common.fileio import write_text_atomic
from common.imageio import write_png
from datagen.blur_geometry import track_world
from scene_format.reader import mask_path

THRESHOLD_PX = 2.0
DEFINITION = ("a pixel is dynamic when the surface point it sees at the view's time moves, at some time of the clip, "
              "by >= threshold_px pixels as seen from the view (largest world displacement times fx / depth); camera "
              "motion is not counted; pixels that see no surface are static")


def surface_motion_px(local: np.ndarray, obj: np.ndarray, mats: np.ndarray, c2w: np.ndarray, fx: float,
                      i: int, chunk: int = 64) -> np.ndarray:
    """Largest image-space displacement [M] (pixels, at the view's depth) of surface points over the clip.

    local [M, 3] points in their part's frame; obj [M] part index; mats [T, O, 4, 4] part-to-world at
    every rendered time; c2w [4, 4] the view's OpenCV pose; i the view's rendered-time index.
    """
    if len(local) == 0:
        return np.zeros(0)
    at_i = track_world(local, obj, mats[i:i + 1])[0]                          # [M, 3]
    w2c = np.linalg.inv(c2w)
    depth = at_i @ w2c[2, :3] + w2c[2, 3]
    largest = np.zeros(len(local))
    for t0 in range(0, mats.shape[0], chunk):                                  # [chunk, M, 3] at a time
        world = track_world(local, obj, mats[t0:t0 + chunk])
        largest = np.maximum(largest, np.sqrt(((world - at_i) ** 2).sum(-1)).max(0))
    return fx * largest / np.maximum(depth, 1e-6)


def mask_image(hit: np.ndarray, motion_px: np.ndarray, width: int, height: int,
               threshold_px: float = THRESHOLD_PX) -> np.ndarray:
    """bool [H, W]: pixels (row-major, every pixel's ray; `hit` [H*W] which rays met a surface, in
    order of `motion_px` [hits]) whose surface moves >= threshold_px."""
    out = np.zeros(height * width, bool)
    out[np.flatnonzero(hit)] = motion_px >= threshold_px
    return out.reshape(height, width)


def write_masks(scene_dir: Path, masks: dict[tuple[int, int], np.ndarray], threshold_px: float = THRESHOLD_PX) -> None:
    """dynamic/cam<k>/<index>.png for every (camera, kept-frame index) and dynamic/masks.json."""
    views = []
    for (k, j), m in sorted(masks.items()):
        write_png(mask_path(scene_dir, k, j), m.astype(np.uint8) * 255)
        views.append({"camera": k, "index": j, "dynamic_fraction": round(float(m.mean()), 6)})
    write_text_atomic(Path(scene_dir) / "dynamic" / "masks.json", json.dumps(
        {"definition": DEFINITION, "threshold_px": threshold_px, "views": views}, indent=1))
