"""Speed variants of a scene (pure Python; no bpy): the same render traversed s times faster.

Construction (time compression over one high-rate render). A scene renders its clip once at
`render.fps` (3000 FPS): rendered frame i shows normalised time tau_i = i / (T - 1). Variant s
shows the same frames at real timestamps i / (fps * s): the scene's animation, the camera orbits and
the camera shake all run s times faster, and nothing is rendered again. What changes with s:

- the events: every camera's frames are pushed through the scene's sensor again, at the compressed
  timestamps. An ideal sensor has no time constant, so its events are variant 1's with timestamps
  divided by s; a real one (refractory period, photoreceptor bandwidth, leak and shot noise in
  events per real second) sees motion s times faster and loses or gains events accordingly.
- the blurred frames: the camera keeps one shutter, `speeds.exposure_ms` of real time, which now
  spans exposure_ms * fps * s rendered frames, so the blur length grows in proportion to s.
- nothing else: the image moves as many pixels between two rendered frames at every s, so the
  simulator's per-pixel linear interpolation between frames is as accurate at every speed as at
  s = 1. That accuracy is a property of the render (measured as px per rendered frame), checked
  against `speeds.max_px_per_frame`; where a render moves more, raise `render.fps`.

A variant is a complete scene folder `<scene>_x<s>` beside the scene's own (same sharp frames, hard
links where the file system allows), readable by every method unchanged.
"""
from __future__ import annotations

import dataclasses
import math

from common.config import ConfigError
from scene_format.naming import SHUTTER_LEVEL, speed_label


def shutter_frames(exposure_ms: float, fps: float, speed: float) -> int:
    """Rendered frames a real-time exposure of exposure_ms integrates at speed s: exposure * fps * s
    (at least one: an exposure shorter than a frame period is a sharp frame)."""
    return max(1, int(round(exposure_ms * 1e-3 * fps * speed)))


def max_speed(exposure_ms: float, fps: float, n_timestamps: int) -> float:
    """The fastest speed whose exposure still fits inside the clip of n_timestamps rendered frames."""
    return n_timestamps / (exposure_ms * 1e-3 * fps)


def check_speeds(scene: str, factors, exposure_ms: float, fps: float, n_timestamps: int) -> None:
    """ConfigError naming the scene and the speed when a speed's exposure spans more than the clip."""
    for s in factors:
        n = shutter_frames(exposure_ms, fps, s)
        if n > n_timestamps:
            raise ConfigError(
                f"scene {scene}, speed x{speed_label(s)}: the {exposure_ms:g} ms exposure spans {n} rendered frames, "
                f"more than the clip's {n_timestamps} (the clip lasts {1e3 * (n_timestamps - 1) / (fps * s):.3g} ms "
                f"at this speed); the fastest speed this exposure allows is x{math.floor(max_speed(exposure_ms, fps, n_timestamps) * 100) / 100:g}")


def check_interpolation(scene: str, factors, px_per_frame_p90: float, limit_px: float) -> None:
    """ConfigError naming the scene and its speeds when the render moves the image more than limit_px
    (p90) between rendered frames: the simulator's linear interpolation would not hold at any speed."""
    if factors and px_per_frame_p90 > limit_px:
        speeds = ", ".join(f"x{speed_label(s)}" for s in factors)
        raise ConfigError(
            f"scene {scene}, speeds {speeds}: the image moves {px_per_frame_p90:.2f} px (p90) between rendered "
            f"frames, more than speeds.max_px_per_frame = {limit_px:g} px that the simulator's per-pixel "
            f"interpolation is trusted with; raise render.fps (time compression keeps the px per frame of the render)")


def variant_config(cfg, speed: float):
    """The SceneConfig of speed variant `speed` of `cfg`: time compressed by `speed`, one blur level
    (`shutter`) of the declared exposure, no variants of its own. The scene, rig, seed and sensor stay."""
    blur = dataclasses.replace(cfg.blur, target_px={}, exposure_ms={SHUTTER_LEVEL: cfg.speeds.exposure_ms})
    return dataclasses.replace(cfg, speed=float(speed), blur=blur, speeds=dataclasses.replace(cfg.speeds, factors=()))
