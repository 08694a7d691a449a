"""The held-out views a method must render to be scored, as a file any code can read.

    views = test_views(SceneDataset("data/quick/hinge"))   # {"format", "views": [...], ...}
    write_test_views(Path("data/quick"), Path("runs/quick/testviews"))   # <out>/<scene>/testviews.json, every scene

Each view gives the camera index, the time (microseconds, seconds and normalised to [0, 1]), the
intrinsics, the pose (world-to-camera and camera-to-world in OpenCV axes; camera-to-world in
Blender/OpenGL axes as D-NeRF style code reads `transform_matrix`), the image size, the file the
render must be saved as (relative to <renders>/<scene>/, extension .png or .exr) and the ground
truth it is scored against: `rgb` for methods that see RGB frames, `gray` for events-only ones.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from common.fileio import write_text_atomic
from scene_format.cameras import opencv_to_blender
from scene_format.reader import FrameRecord, SceneDataset

FORMAT = "e4dgs-testviews/1"
RENDER_SUFFIXES = (".png", ".exr")
CONVENTION = ("OpenCV camera axes (x right, y down, z forward); w2c maps world to camera, c2w_opencv is its inverse; "
              "transform_matrix is c2w in Blender/OpenGL axes (c2w_opencv @ diag(1, -1, -1, 1)) as in transforms_*.json. "
              "Pixel (u, v) is centred at (u + 0.5, v + 0.5) with K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].")
RENDERS = ("One image per view at <renders>/<scene>/<file>.png (8- or 16-bit PNG) or .exr (float32, the same "
           "sRGB-encoded values in [0, 1] a PNG holds, not linear light). Methods that see RGB render colour (3 "
           "channels); events-only methods render gray (1 channel), scored after a per-image gain / offset on log "
           "intensity, as the paper scores them.")


def render_stem(rec: FrameRecord) -> str:
    """The name (without extension) a view's render must have under <renders>/<scene>/."""
    return rec.stem


def test_views(dataset: SceneDataset) -> dict:
    """Every held-out view of a scene (or speed variant), in the order the benchmark scores them."""
    intr = dataset.intrinsics
    intrinsics = {"fx": intr.fx, "fy": intr.fy, "cx": intr.cx, "cy": intr.cy, "width": intr.width, "height": intr.height}
    views = []
    for rec in dataset.frames("test"):
        c2w = np.asarray(dataset.pose(rec.camera, rec.t_us), np.float64)
        views.append({
            "file": render_stem(rec), "camera": rec.camera, "index": rec.index,
            "timestamp_us": rec.t_us, "time_s": rec.t_us * 1e-6, "time": rec.time,
            "w2c": np.linalg.inv(c2w).tolist(), "c2w_opencv": c2w.tolist(),
            "transform_matrix": opencv_to_blender(c2w).tolist(),
            "ground_truth": {"rgb": str(rec.path.relative_to(dataset.dir)),
                             "gray": str(rec.gray_path.relative_to(dataset.dir)) if rec.gray_path else None}})
    speed = dataset.facts.speed
    return {"format": FORMAT, "scene": dataset.dir.name, "speed": speed, "duration_us": dataset.duration_us,
            "width": intr.width, "height": intr.height, "intrinsics": intrinsics,
            "K": intr.K.tolist(), "convention": CONVENTION, "renders": RENDERS,
            "scored_against": {"rgb": "rgb", "events+rgb": "rgb", "events": "gray"}, "views": views}


def write_test_views(path: Path, out: Path | None = None) -> list[Path]:
    """testviews.json for the scene at `path`, or for every scene (speed variants included) under a
    dataset root; into each scene's folder, or into out/<scene>/. Returns the files written."""
    from scene_format.reader import DatasetError
    from scene_format.verify import scene_dirs

    dirs = scene_dirs(path)
    if not dirs:
        raise DatasetError(f"{path}: neither a generated scene nor a dataset root holding one "
                           "(expected manifest.json in it or in its sub-folders)")
    written = []
    for d in dirs:
        target = (out / d.name if out is not None else d) / "testviews.json"
        target.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(target, json.dumps(test_views(SceneDataset(d)), indent=1))
        written.append(target)
    return written
