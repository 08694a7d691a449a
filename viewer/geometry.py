"""Pure camera arithmetic of the viewer: the browser's camera as a raster camera, dataset poses as
viser frusta, and the resolution to render at.

viser's cameras follow OpenCV's axes (x right, y down, looking along +z), as the dataset's poses do,
so a pose passes between them unchanged; only the rotation's form differs (a wxyz quaternion there,
a matrix here).
"""
from __future__ import annotations

import math

import numpy as np

MOVING_SCALE = 0.5            # render scale while the browser's camera moves
REST_S = 0.3                  # seconds without a camera update after which the view is at rest


def quat_wxyz_to_matrix(wxyz) -> np.ndarray:
    """Rotation [3, 3] of a quaternion (w, x, y, z); it need not be normalised (ValueError if zero)."""
    q = np.asarray(wxyz, np.float64)
    n = float(np.linalg.norm(q))
    if q.shape != (4,) or not math.isfinite(n) or n == 0.0:
        raise ValueError(f"quaternion: expected 4 finite numbers, not all zero; got {wxyz!r}")
    w, x, y, z = q / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat_wxyz(R) -> np.ndarray:
    """Unit quaternion (w, x, y, z) with w >= 0 of a rotation [3, 3] (Shepperd's method)."""
    R = np.asarray(R, np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.asarray(q) / np.linalg.norm(q)
    return -q if q[0] < 0 else q


def pose_from_wxyz(position, wxyz) -> np.ndarray:
    """OpenCV camera-to-world [4, 4] from a position [3] and an orientation (w, x, y, z)."""
    c2w = np.eye(4)
    c2w[:3, :3] = quat_wxyz_to_matrix(wxyz)
    c2w[:3, 3] = np.asarray(position, np.float64)
    return c2w


def browser_intrinsics(fov_y_rad: float, aspect: float, height_px: int) -> tuple[np.ndarray, int, int]:
    """(K [3, 3], width, height) of a centred pinhole with vertical field of view `fov_y_rad` and
    width / height `aspect`, `height_px` pixels high (what the browser's canvas shows)."""
    if not (0.0 < fov_y_rad < math.pi) or not aspect > 0 or height_px < 1:
        raise ValueError(f"browser camera: fov {fov_y_rad!r} rad, aspect {aspect!r}, height {height_px!r} px")
    height = int(height_px)
    width = max(1, int(round(height * aspect)))
    f = 0.5 * height / math.tan(0.5 * fov_y_rad)
    K = np.array([[f, 0.0, 0.5 * width], [0.0, f, 0.5 * height], [0.0, 0.0, 1.0]])
    return K, width, height


def fov_y_of(K, height: int) -> float:
    """Vertical field of view (rad) of intrinsics K [3, 3] for an image `height` pixels high."""
    return 2.0 * math.atan(0.5 * height / float(np.asarray(K)[1, 1]))


def scaled(K, width: int, height: int, scale: float) -> tuple[np.ndarray, int, int]:
    """Intrinsics and size of the same camera rendered at `scale` times the resolution (pixel-centre
    convention of K kept: the image covers the same field of view)."""
    w, h = max(1, int(round(width * scale))), max(1, int(round(height * scale)))
    K2 = np.asarray(K, np.float64).copy()
    K2[0] *= w / width
    K2[1] *= h / height
    K2[2] = [0.0, 0.0, 1.0]
    return K2, w, h


def render_scale(seconds_since_move: float, moving_scale: float = MOVING_SCALE, rest_s: float = REST_S) -> float:
    """The resolution factor to render at: `moving_scale` while the camera moved within `rest_s`
    seconds, 1 (full) once it rests."""
    return moving_scale if seconds_since_move < rest_s else 1.0


def letterbox(image, aspect: float, fill) -> tuple[np.ndarray, tuple[int, int]]:
    """`image` [H, W, C] centred on a canvas of width / height `aspect` (padding filled with `fill`),
    so that a browser stretching it to its canvas shows it undistorted; returns (canvas, (x0, y0)),
    where the image sits at [y0:y0+H, x0:x0+W]. The aspect is clamped to [W/H / 4, 4 W/H]."""
    h, w = image.shape[:2]
    aspect = float(np.clip(aspect, w / h / 4.0, 4.0 * w / h))
    W, H = (max(w, int(round(h * aspect))), h) if aspect >= w / h else (w, max(h, int(round(w / aspect))))
    x0, y0 = (W - w) // 2, (H - h) // 2
    canvas = np.empty((H, W) + image.shape[2:], image.dtype)
    canvas[...] = np.asarray(fill, image.dtype)
    canvas[y0:y0 + h, x0:x0 + w] = image
    return canvas, (x0, y0)
