"""Optical flow and depth as files and pictures (pure NumPy + OpenCV).

- DSEC-Flow's 16-bit PNG: channels (x, y, valid), x and y stored as flow * 128 + 2**15, so flows
  within +-256 px keep 1/128 px (`encode_dsec_flow`, `decode_dsec_flow`, `read_flow`);
- the colour wheel of flow pictures: hue = direction (0 deg, red = +x, 90 deg = +y, image down),
  saturation = speed relative to the largest valid flow, black where invalid (`flow_to_rgb`);
- depth pictures: near bright, far dark, on a fixed range or the valid depths' own (`depth_to_rgb`).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

DSEC_SCALE = 128.0
DSEC_OFFSET = 2 ** 15


def encode_dsec_flow(flow: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """uint16 [H, W, 3] (x, y, valid) in DSEC-Flow's convention; ValueError for a flow beyond +-256 px."""
    scaled = np.round(flow * DSEC_SCALE) + DSEC_OFFSET
    if valid.any() and (scaled[valid].min() < 0 or scaled[valid].max() > 65535):
        raise ValueError(f"flow of {np.abs(flow[valid]).max():.1f} px does not fit DSEC's 16-bit PNG (+-256 px)")
    out = np.zeros(flow.shape[:2] + (3,), np.uint16)
    out[..., :2] = np.where(valid[..., None], np.clip(scaled, 0, 65535), DSEC_OFFSET)
    out[..., 2] = valid
    return out


def decode_dsec_flow(png: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(flow float64 [H, W, 2], valid bool [H, W]) from a DSEC-Flow array (x, y, valid), as DSEC's
    loader reads it: (value - 2**15) / 128."""
    png = png.astype(np.float64)
    return (png[..., :2] - DSEC_OFFSET) / DSEC_SCALE, png[..., 2] > 0


def read_flow(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(flow [H, W, 2] px, valid [H, W]) from a DSEC-Flow PNG or a ground-truth .npz (a flow file's
    forward_px and valid; a velocity file's px_per_ms, valid where nonzero). ValueError naming the
    file otherwise."""
    import cv2

    path = Path(path)
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path) as z:
                if "forward_px" in z.files:
                    flow, valid = z["forward_px"].astype(np.float64), z["valid"].astype(bool)
                else:
                    flow = z["px_per_ms"].astype(np.float64)
                    valid = np.any(flow != 0, -1)
            if flow.ndim != 3 or flow.shape[2] != 2 or valid.shape != flow.shape[:2]:
                raise ValueError(f"arrays of shape {flow.shape} and {valid.shape}, expected [H, W, 2] and [H, W]")
            if not np.isfinite(flow[valid]).all():
                raise ValueError("non-finite flow at valid pixels")
            return flow, valid
        except (OSError, KeyError, ValueError) as exc:
            raise ValueError(f"{path}: not a ground-truth flow file ({exc})") from None
    if not path.is_file():
        raise ValueError(f"{path}: no such flow file")
    if path.suffix.lower() != ".png":
        raise ValueError(f"{path}: expected a DSEC-Flow 16-bit PNG or a ground-truth .npz flow file, got a "
                         f"{path.suffix or 'suffix-less'} file")
    try:
        png = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    except cv2.error as exc:
        raise ValueError(f"{path}: cannot be read as a PNG ({str(exc).strip().splitlines()[-1]})") from None
    if png is None or png.dtype != np.uint16 or png.ndim != 3 or png.shape[2] != 3:
        raise ValueError(f"{path}: expected a DSEC-Flow 16-bit PNG with 3 channels (x, y, valid)")
    return decode_dsec_flow(png[..., ::-1])           # OpenCV reads BGR; the file's channels are x, y, valid


def flow_to_rgb(flow: np.ndarray, valid: np.ndarray | None = None, max_px: float | None = None) -> np.ndarray:
    """uint8 [H, W, 3] colour-wheel picture of a flow [H, W, 2]."""
    import cv2

    valid = np.ones(flow.shape[:2], bool) if valid is None else valid
    mag = np.hypot(flow[..., 0], flow[..., 1])
    top = max_px if max_px else (float(mag[valid].max()) if valid.any() else 1.0)
    hue = (np.degrees(np.arctan2(flow[..., 1], flow[..., 0])) % 360.0) / 2.0        # OpenCV hue: 0..180
    hsv = np.stack([hue, np.clip(mag / max(top, 1e-9), 0, 1) * 255, np.full(mag.shape, 255.0)], -1)
    rgb = cv2.cvtColor(hsv.astype(np.uint8), cv2.COLOR_HSV2RGB)
    rgb[~valid] = 0
    return rgb


def depth_to_rgb(depth: np.ndarray, near: float | None = None, far: float | None = None) -> np.ndarray:
    """uint8 [H, W, 3]: depth [H, W] (0 = none) from bright (near) to dark (far) on the inferno map;
    black where no surface."""
    import cv2

    seen = depth > 0
    lo = near if near is not None else (float(depth[seen].min()) if seen.any() else 0.0)
    hi = far if far is not None else (float(depth[seen].max()) if seen.any() else 1.0)
    x = 1.0 - np.clip((depth - lo) / max(hi - lo, 1e-9), 0, 1)
    rgb = cv2.applyColorMap(np.round(x * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)[..., ::-1].copy()
    rgb[~seen] = 0
    return rgb
