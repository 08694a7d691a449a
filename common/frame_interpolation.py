"""Frames in between two frames, along the motion between them (pure NumPy + OpenCV).

A frame-to-event simulator needs its input finer in time than a camera's frames: v2e upsamples
video with SuperSloMo, a network. Here the in-between frames follow the optical flow between the
two frames (OpenCV's DIS flow, both directions), with SuperSloMo's flow approximation and no
visibility maps (Jiang et al., CVPR 2018, eq. 4): for a fraction w in [0, 1] between frame a (w = 0)
and frame b (w = 1), with flows F_ab, F_ba in pixels,

    F_wa = -(1 - w) w F_ab + w^2 F_ba          (from the in-between frame back to a)
    F_wb = (1 - w)^2 F_ab - w (1 - w) F_ba     (and forward to b)
    I_w  = (1 - w) warp(a, F_wa) + w warp(b, F_wb),   warp(I, F)(x) = I(x + F(x)) (bilinear, edges clamped)

so I_0 = a and I_1 = b exactly, and a pattern translating by d pixels is at w d at fraction w. Where
the flow is wrong (occlusions, fast motion beyond the flow's reach) the result is a blend of two
misplaced frames, which a linear blend of the frames always is.

`warp_ref` is the readable bilinear warp; `warp` (cv2.remap) is the one used, tested equal.
"""
from __future__ import annotations

import numpy as np


def warp_ref(image: np.ndarray, flow_px: np.ndarray) -> np.ndarray:
    """float32 [H, W]: image [H, W] sampled at x + flow [H, W, 2] (x, y), bilinear, coordinates
    clamped to the image (readable reference of `warp`)."""
    H, W = image.shape
    img = np.asarray(image, np.float64)
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    sx = np.clip(xs + flow_px[..., 0], 0, W - 1)
    sy = np.clip(ys + flow_px[..., 1], 0, H - 1)
    x0 = np.minimum(np.floor(sx).astype(int), W - 2) if W > 1 else np.zeros_like(sx, int)
    y0 = np.minimum(np.floor(sy).astype(int), H - 2) if H > 1 else np.zeros_like(sy, int)
    fx, fy = sx - x0, sy - y0
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    top = (1 - fx) * img[y0, x0] + fx * img[y0, x1]
    bottom = (1 - fx) * img[y1, x0] + fx * img[y1, x1]
    return ((1 - fy) * top + fy * bottom).astype(np.float32)


def warp(image: np.ndarray, flow_px: np.ndarray) -> np.ndarray:
    """Same as warp_ref, with cv2.remap (bilinear, border replicated: the clamped coordinates); OpenCV
    rounds the sample position to 1/32 px, so values differ by at most 1/64 of a neighbour difference."""
    import cv2

    H, W = image.shape
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    mx = (gx + flow_px[..., 0]).astype(np.float32)
    my = (gy + flow_px[..., 1]).astype(np.float32)
    return cv2.remap(np.asarray(image, np.float32), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def optical_flow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """float32 [H, W, 2]: the flow from frame a to frame b (a(x) ~ b(x + F(x))), OpenCV's DIS flow
    (preset medium) on the frames as 8-bit images scaled by their common range."""
    import cv2

    if max(a.shape) < 12:
        raise ValueError(f"optical_flow: frames of {a.shape[1]} x {a.shape[0]} px are too small for DIS flow "
                         "(12 px or more in one direction)")
    lo = float(min(a.min(), b.min()))
    span = max(float(max(a.max(), b.max())) - lo, 1e-12)
    to8 = lambda im: np.round((np.asarray(im, np.float64) - lo) / span * 255).astype(np.uint8)  # noqa: E731
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(to8(a), to8(b), None).astype(np.float32)


def in_between(a: np.ndarray, b: np.ndarray, flow_ab: np.ndarray, flow_ba: np.ndarray, w: float) -> np.ndarray:
    """float32 [H, W]: the frame at fraction w in [0, 1] from a to b along the flows (module docstring)."""
    if not 0.0 <= w <= 1.0:
        raise ValueError(f"in_between: the fraction must lie in [0, 1], got {w!r}")
    if w == 0.0:
        return np.array(a, np.float32)          # a copy: the caller may write into it
    if w == 1.0:
        return np.array(b, np.float32)
    f_wa = -(1 - w) * w * flow_ab + w * w * flow_ba
    f_wb = (1 - w) ** 2 * flow_ab - w * (1 - w) * flow_ba
    return ((1 - w) * warp(a, f_wa) + w * warp(b, f_wb)).astype(np.float32)
