"""Count images: events summed per pixel (signed by polarity, or ON and OFF apart).

    >>> import numpy as np
    >>> x, y, p = np.array([0, 0, 2]), np.array([1, 1, 0]), np.array([1, 1, -1])
    >>> count_image(x, y, p, 3, 2).tolist()                  # sum of polarities per pixel
    [[0.0, 0.0, -1.0], [2.0, 0.0, 0.0]]
    >>> count_image(x, y, p, 3, 2, split=True)[:, 1, 0].tolist()   # [ON, OFF] counts
    [2.0, 0.0]
"""
from __future__ import annotations

import numpy as np


def count_image(x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int,
                split: bool = False) -> np.ndarray:
    """x, y, p [N] (p in {-1, +1}) -> [H, W] float64 sum of polarities per pixel, or with split
    [2, H, W] float64: ON counts, OFF counts."""
    flat = np.asarray(y, np.int64) * width + np.asarray(x, np.int64)
    pol = np.asarray(p)
    if not split:
        return np.bincount(flat, weights=pol.astype(np.float64), minlength=width * height).reshape(height, width)
    both = np.bincount(flat * 2 + (pol < 0), minlength=2 * width * height)     # one pass: [pixel, ON / OFF]
    return both.reshape(height, width, 2).transpose(2, 0, 1).astype(np.float64)
