"""The D-NeRF style frame lists of a scene folder (pure: NumPy and JSON, no bpy).

    transforms_{train,val,test}.json         the sharp frames (val = the held-out test views)
    blur/<level>/transforms_{train,val,test}.json, exposures.json
                                             each blur level a complete D-NeRF folder: its blurred
                                             training frames, the sharp held-out views

`file_path` has no extension and is relative to the JSON's own folder, as D-NeRF style loaders read
it; `transform_matrix` is camera-to-world in Blender/OpenGL axes; `time` is normalised to [0, 1].
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from common.fileio import write_text_atomic
from scene_format.cameras import Intrinsics, interpolate_pose, opencv_to_blender


def frame_entry(t_us_all: np.ndarray, poses_k: np.ndarray, k: int, j: int, path: str, t_us: int) -> dict:
    """One frame of camera k (poses_k [T, 4, 4] OpenCV c2w at times t_us_all [T]) at t_us."""
    c2w = interpolate_pose(t_us_all, poses_k, t_us)
    return {"file_path": path, "transform_matrix": opencv_to_blender(c2w).tolist(),
            "time": float(t_us / t_us_all[-1]) if t_us_all[-1] else 0.0,
            "camera": k, "index": j, "timestamp_us": int(t_us)}


def write_transforms(scene_dir: Path, intr: Intrinsics, t_us: np.ndarray, poses: np.ndarray, kept: np.ndarray,
                     windows: dict[str, dict[int, tuple[int, int]]], test_every: int, render_fps: float) -> None:
    """Every transforms file of a scene: t_us [T] rendered times, poses [C, T, 4, 4], kept [J] the kept
    rendered frames, windows {level: {j: (first, last) rendered frame}} of the blur levels."""
    n_cameras = poses.shape[0]
    base = {"camera_angle_x": intr.fov_x_rad, "fl_x": intr.fx, "fl_y": intr.fy,
            "cx": intr.cx, "cy": intr.cy, "w": intr.width, "h": intr.height}
    split = {"train": [], "test": []}
    for k in range(n_cameras):
        for j, i in enumerate(kept):
            entry = frame_entry(t_us, poses[k], k, j, f"./rgb/cam{k}/{j:05d}", int(t_us[i]))
            entry["gray_path"] = f"./gray/cam{k}/{j:05d}"
            split["test" if j % test_every == 0 else "train"].append(entry)
    # D-NeRF style loaders read transforms_{train,val,test}.json beside each other and resolve
    # file_path against that folder: the held-out views are the val split too, and every blur
    # level's folder is a complete D-NeRF scene (its blurred training frames, the sharp test views)
    split["val"] = split["test"]
    for name, frames in split.items():
        write_text_atomic(scene_dir / f"transforms_{name}.json", json.dumps({**base, "frames": frames}, indent=1))
    held_out = [{**f, "file_path": "../../" + f["file_path"][2:], "gray_path": "../../" + f["gray_path"][2:]}
                for f in split["test"]]
    for level, level_windows in windows.items():
        frames, exposures = [], []
        for name in ("test", "val"):
            write_text_atomic(scene_dir / "blur" / level / f"transforms_{name}.json",
                              json.dumps({**base, "frames": held_out}, indent=1))
        for k in range(n_cameras):
            for j, (first, last) in level_windows.items():
                t_mid = int(round((t_us[first] + t_us[last]) / 2))
                if j % test_every:
                    frames.append(frame_entry(t_us, poses[k], k, j, f"./cam{k}/{j:05d}", t_mid))
                exposures.append({"camera": k, "index": j, "first_frame_us": int(t_us[first]),
                                  "last_frame_us": int(t_us[last]), "center_us": t_mid,
                                  "n_frames": int(last - first + 1),
                                  "exposure_ms": round(1e3 * (last - first + 1) / render_fps, 4)})
        write_text_atomic(scene_dir / "blur" / level / "transforms_train.json",
                          json.dumps({**base, "frames": frames}, indent=1))
        write_text_atomic(scene_dir / "blur" / level / "exposures.json", json.dumps(exposures, indent=1))
