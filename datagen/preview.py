"""Contact sheet of a generated scene and the blurred-vs-sharp PSNR of its blur levels.

The contact sheet has one row per camera: the sharp RGB frame, the same frame at every blur level
(labelled with its measured blur length), the events around it, and its dynamic region (the pixels
whose surface moves, datagen.dynamic) tinted on the sharp frame.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from scene_format.reader import SceneDataset
from common.imageio import write_png
from common.metrics import psnr
from eventio.h5io import read_window
from eventio.representations import event_frame


def _label(img: np.ndarray, text: str) -> np.ndarray:
    img = img.copy()
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 2, cv2.LINE_AA)
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def _rgb8(path: Path) -> np.ndarray:
    """uint8 RGB [H, W, 3] of a stored sRGB PNG (exact: the reader returns k / 255)."""
    return np.round(SceneDataset.load_image(path) * 255.0).astype(np.uint8)


def dynamic_overlay(rgb8: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The frame dimmed, its dynamic pixels tinted orange."""
    out = (rgb8.astype(np.float32) * 0.45).astype(np.uint8)
    out[mask] = (0.5 * rgb8[mask] + 0.5 * np.array([255, 140, 0])).astype(np.uint8)
    return out


def contact_sheet(scene_dir: Path, n_cameras: int, frame_index: int, t_us: int, window_us: int,
                  blur_labels: dict[str, list[str]], out: Path, folders: list[str] | None = None,
                  dynamic: list[np.ndarray | None] | None = None) -> Path:
    """Per camera a row: sharp | each blur level in blur_labels' order (labelled "<level> <label[k]>";
    read from blur/<folders[i]>, default the level names) | events in [t - w/2, t + w/2) | the
    dynamic mask dynamic[k] over the sharp frame (when given)."""
    rows = []
    name = f"{frame_index:05d}.png"
    folders = folders or list(blur_labels)
    for k in range(n_cameras):
        row = [_label(_rgb8(scene_dir / "rgb" / f"cam{k}" / name), f"cam{k} sharp")]
        for folder, (level, labels) in zip(folders, blur_labels.items()):
            row.append(_label(_rgb8(scene_dir / "blur" / folder / f"cam{k}" / name), f"{level} {labels[k]}"))
        ev = read_window(scene_dir / "events" / f"cam{k}.h5", t_us - window_us // 2, t_us + window_us // 2)
        row.append(_label(event_frame(ev), f"{len(ev)} ev / {window_us / 1000:.3g} ms"))
        if dynamic is not None and dynamic[k] is not None:
            row.append(_label(dynamic_overlay(_rgb8(scene_dir / "rgb" / f"cam{k}" / name), dynamic[k]),
                              f"dynamic {100 * dynamic[k].mean():.1f} % px"))
        rows.append(np.concatenate(row, axis=1))
    return write_png(out, np.concatenate(rows, axis=0))


def speed_sheet(scene_dir: Path, variant_dirs: list[Path], frame_index: int, out: Path, camera: int = 0) -> Path:
    """One camera at every speed: a row per variant (from the manifests written before): its blurred
    frame (labelled with speed, exposure, median blur px and PSNR against sharp) and the events of
    its exposure window; the sharp frame heads the first column."""
    import json

    name = f"{frame_index:05d}.png"
    sharp = _label(_rgb8(scene_dir / "rgb" / f"cam{camera}" / name), f"cam{camera} sharp (every speed)")
    rows = []
    for d in variant_dirs:
        m = json.loads((d / "manifest.json").read_text())
        lv = m["blur"]["levels"]["shutter"]
        exposure = next(e for e in json.loads((d / "blur" / "shutter" / "exposures.json").read_text())
                        if e["camera"] == camera and e["index"] == frame_index)
        blurred = _label(_rgb8(d / "blur" / "shutter" / f"cam{camera}" / name),
                         f"x{m['speed']['factor']:g} {m['speed']['exposure_ms']:g} ms: {lv['median_px']:.0f} px, "
                         f"{lv['psnr_vs_sharp_db']['median_db']:.1f} dB")
        ev = read_window(d / "events" / f"cam{camera}.h5", exposure["first_frame_us"], exposure["last_frame_us"] + 1)
        rate = m["events_per_second_per_camera"][camera] / 1e6
        rows.append(np.concatenate([sharp if not rows else np.full_like(sharp, 255), blurred,
                                    _label(event_frame(ev), f"{len(ev)} ev in exposure, {rate:.0f} Mev/s")], axis=1))
    return write_png(out, np.concatenate(rows, axis=0))


def blur_psnr(scene_dir: Path, level: str, n_cameras: int, n_frames: int) -> dict:
    """PSNR of every blurred frame of a level against the sharp frame at its kept timestamp (the 8-bit
    sRGB PNGs that RGB methods train on): median and mean over all frames, median per camera."""
    per_cam = []
    for k in range(n_cameras):
        per_cam.append([psnr(SceneDataset.load_image(scene_dir / "blur" / level / f"cam{k}" / f"{j:05d}.png"),
                             SceneDataset.load_image(scene_dir / "rgb" / f"cam{k}" / f"{j:05d}.png"))
                        for j in range(n_frames)])
    allv = np.array([v for c in per_cam for v in c])
    finite = allv[np.isfinite(allv)]
    return {"median_db": round(float(np.median(allv)), 3), "mean_db": round(float(finite.mean()), 3) if len(finite) else None,
            "per_camera_median_db": [round(float(np.median(c)), 3) for c in per_cam]}
