"""A real camera's APS frames as the simulator's input, for the classic realism check of a
frame-to-event simulator (v2e's authors did it on DDD17/20): a DAVIS's grey frames and its events
come from the same pixels, so the events the simulator makes from the frames can be compared with
the events the camera made over the same span (tools/aps_check.py).

- APS values to intensity: the APS output is linear in the light (after correlated double
  sampling), so a frame's linear intensity is DN / 255 (8-bit DN).
- APS noise is the frames' own (read noise ~1.5 DN, frame-wide jumps of 0.4-0.8 DN), not the event
  sensor's: fed raw through a log response it becomes tens of events per second in dark pixels. It
  is removed before simulating: each pixel's deviation from its temporal median is soft-thresholded
  by `threshold_dn` (4 DN): m + sign(d) max(|d| - 4, 0).
- In time: the frames are samples at their exposures' centres (25 fps); the simulator gets them at
  `rate_hz` (2 kHz), in linear intensity, interpolated in one of two ways (`motion`):
  `flow` (the default) moves the frames along the optical flow between them
  (common.frame_interpolation: an edge crosses a pixel when it passes it, as in the scene), and a
  pixel whose value is the same in every frame keeps it in between (the flow's errors near a
  moving edge would otherwise move a still point of the scene);
  `linear` blends the two frames, so every pixel changes at one slope for the 40 ms between them
  (an edge that passes a pixel in a millisecond is spread over 40).
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from common.frame_interpolation import in_between, optical_flow
from eventio.events import EventStream
from simulator.config import SimulatorConfig
from simulator.simulator import EventSimulator

DN_FULL_SCALE = 255.0


def denoise_aps(dn: np.ndarray, threshold_dn: float = 4.0) -> np.ndarray:
    """float32 [F, H, W]: each pixel's median over the frames plus its deviation soft-thresholded by
    threshold_dn (dn [F, H, W] digital numbers)."""
    dn = np.asarray(dn, np.float32)
    med = np.median(dn, axis=0)
    d = dn - med
    return med + np.sign(d) * np.maximum(np.abs(d) - np.float32(threshold_dn), 0.0)


def static_pixels(denoised: np.ndarray) -> np.ndarray:
    """bool [H, W]: pixels whose denoised value never changes over the frames (their scene is still:
    every event the camera makes there is noise)."""
    return np.all(denoised == denoised[:1], axis=0)


MOTIONS = ("flow", "linear")


def upsampled(frames: np.ndarray, t_us: np.ndarray, rate_hz: float,
              motion: str = "flow") -> Iterator[tuple[np.ndarray, int]]:
    """(frame, t_us) at rate_hz from the first to the last frame time: frames [F, H, W] linear
    intensity at increasing t_us [F], interpolated in between along the optical flow (`flow`) or
    linearly (`linear`)."""
    if motion not in MOTIONS:
        raise ValueError(f"upsampled: motion must be one of {', '.join(MOTIONS)}, got {motion!r}")
    t_us = np.asarray(t_us, np.int64)
    step = 1e6 / rate_hz
    times = np.unique(np.round(np.arange(t_us[0], t_us[-1] + 1, step)).astype(np.int64))
    flows: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    still = static_pixels(frames)          # never changes: a still point of the scene stays still in between
    for t in times.tolist():
        k = min(int(np.searchsorted(t_us, t, side="right")) - 1, len(t_us) - 2)
        w = (t - t_us[k]) / (t_us[k + 1] - t_us[k])
        if motion == "linear":
            yield ((1 - w) * frames[k] + w * frames[k + 1]).astype(np.float32), int(t)
            continue
        if k not in flows:
            flows = {k: (optical_flow(frames[k], frames[k + 1]), optical_flow(frames[k + 1], frames[k]))}
        frame = in_between(frames[k], frames[k + 1], *flows[k], float(w))
        frame[still] = frames[0][still]
        yield frame, int(t)


def simulate_frames(frames: np.ndarray, t_us: np.ndarray, config: SimulatorConfig, rate_hz: float = 2000.0,
                    seed: int = 0, motion: str = "flow") -> EventStream:
    """The events `config`'s sensor makes from frames [F, H, W] (linear intensity at t_us [F]),
    upsampled to rate_hz (`motion`: along the optical flow or linearly); times on the frames' clock."""
    return simulate_sequence(upsampled(frames, t_us, rate_hz, motion), config, frames.shape[2], frames.shape[1], seed)


def simulate_sequence(sequence: Iterable[tuple[np.ndarray, int]], config: SimulatorConfig, width: int, height: int,
                      seed: int = 0) -> EventStream:
    """The events `config`'s sensor makes from (frame [H, W], t_us) pairs (e.g. `upsampled`'s, kept in a
    list to simulate several sensors from one upsampling)."""
    sim = EventSimulator(config, width, height, seed=seed)
    chunks = [sim.push(frame, t) for frame, t in sequence] + [sim.flush()]
    return EventStream(np.concatenate(chunks), width, height)
