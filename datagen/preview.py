"""Contact sheet of a generated scene: per camera a sharp RGB frame, a blurred frame, an event frame."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from simulator.h5io import read_window
from e4dgs.imageio import write_png
from simulator.view import event_frame


def _label(img: np.ndarray, text: str) -> np.ndarray:
    img = img.copy()
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 2, cv2.LINE_AA)
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def contact_sheet(scene_dir: Path, n_cameras: int, frame_index: int, t_us: int, window_us: int,
                  blur_level: str | None, out: Path) -> Path:
    """Rows: sharp RGB, blurred RGB (if any level), events in [t - w/2, t + w/2); one column per camera."""
    rows: list[list[np.ndarray]] = [[], [], []]
    for k in range(n_cameras):
        sharp = cv2.imread(str(scene_dir / "rgb" / f"cam{k}" / f"{frame_index:05d}.png"))[..., ::-1]
        rows[0].append(_label(sharp, f"cam{k} rgb"))
        if blur_level:
            blurred = cv2.imread(str(scene_dir / "blur" / blur_level / f"cam{k}" / f"{frame_index:05d}.png"))[..., ::-1]
            rows[1].append(_label(blurred, f"{blur_level} blur"))
        ev = read_window(scene_dir / "events" / f"cam{k}.h5", t_us - window_us // 2, t_us + window_us // 2)
        rows[2].append(_label(event_frame(ev), f"{len(ev)} ev / {window_us / 1000:g} ms"))
    grid = np.concatenate([np.concatenate(r, axis=1) for r in rows if r], axis=0)
    return write_png(out, grid)

