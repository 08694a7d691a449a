"""Motion blur: exposure windows and the running sums that average sharp frames over them (pure)."""
from __future__ import annotations

import numpy as np


def exposure_window(i_center: int, n_frames: int, n_timestamps: int) -> tuple[int, int]:
    """Rendered-frame indices [first, last] of an exposure of n_frames centred on frame i_center,
    shifted (not shortened) to stay inside the clip [0, n_timestamps - 1]."""
    n_frames = min(n_frames, n_timestamps)
    first = i_center - (n_frames - 1) // 2
    first = min(max(first, 0), n_timestamps - n_frames)
    return first, first + n_frames - 1


class BlurStack:
    """Running sums of frames for the exposure windows of one camera and one blur level.

    `add(i, frame)` adds rendered frame i to every open window that covers it and returns the
    (key, mean) pairs of windows completed by it. The sums are float64, so the mean equals
    `np.mean` of the same frames up to rounding of the final division.
    """

    def __init__(self, windows: dict[int, tuple[int, int]]):
        self.windows = dict(windows)
        self.sums: dict[int, np.ndarray] = {}

    def add(self, i: int, frame: np.ndarray) -> list[tuple[int, np.ndarray]]:
        done = []
        for key, (first, last) in self.windows.items():
            if first <= i <= last:
                if key in self.sums:
                    self.sums[key] += frame
                else:
                    self.sums[key] = frame.astype(np.float64)
                if i == last:
                    done.append((key, (self.sums.pop(key) / (last - first + 1)).astype(np.float32)))
        return done

    def state(self, prefix: str) -> dict[str, np.ndarray]:
        return {f"{prefix}{key}": s for key, s in self.sums.items()}

    def load_state(self, state: dict, prefix: str) -> None:
        self.sums = {int(k[len(prefix):]): np.array(v, np.float64) for k, v in state.items() if k.startswith(prefix)}
