"""Colour conversions every layer shares: sRGB encoding (IEC 61966-2-1) and Rec.709 luminance of
linear light. Arrays in, arrays out (float64)."""
from __future__ import annotations

import numpy as np

REC709_LUMA = (0.2126, 0.7152, 0.0722)


def rec709_luma(rgb: np.ndarray) -> np.ndarray:
    """Linear RGB [H,W,3] -> linear luminance [H,W] (Rec.709 / sRGB primaries)."""
    r, g, b = REC709_LUMA
    return r * rgb[..., 0] + g * rgb[..., 1] + b * rgb[..., 2]


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0,1] -> linear light (IEC 61966-2-1)."""
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    """Linear light -> sRGB-encoded values, clipped to [0,1]."""
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def srgb_luma(rgb: np.ndarray) -> np.ndarray:
    """sRGB-encoded [..., 3] -> sRGB-encoded [...] Rec.709 luma of its linear light (how the dataset's
    gray/ frames are made)."""
    return linear_to_srgb(rec709_luma(srgb_to_linear(rgb)))
