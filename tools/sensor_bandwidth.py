"""What a sensor makes of fast motion: a sharp edge and a fine grating sweeping across a row of pixels
at a given image speed, each pixel's events counted, for a sensor with and without its photoreceptor
low-pass. It separates the bandwidth's effect from the thresholds' and refractory period's on a
dataset's speed variants (docs/results/sensors.md).

    python -m tools.sensor_bandwidth [--sensor davis346] [--speed-px-per-ms 33] [--duration-us 3800]

Frames at 3000 x 26.2 Hz (the mild speed level's effective frame rate) over `--duration-us`; the edge
steps from `--bright` to `--dark` linear intensity; the grating is a sinusoid of 8 px period between
0.1 and 0.5. Leak is off (only the motion's events are counted).
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

FRAME_RATE_HZ = 3000.0 * 26.2
WIDTH, HEIGHT, EDGE_START_PX, GRATING_PERIOD_PX = 200, 4, 20.0, 8.0


def _frames(pattern, duration_us: float):
    """(frame [H, W], t_us) at FRAME_RATE_HZ over duration_us: pattern(x [1, W], t_us) -> a row [1, W]."""
    x = np.arange(WIDTH)[None, :] + 0.5
    dt = 1e6 / FRAME_RATE_HZ
    for i in range(int(duration_us / dt) + 1):
        yield pattern(x, i * dt) * np.ones((HEIGHT, 1)), int(round(i * dt))


def edge_frames(speed_px_per_us: float, duration_us: float, bright: float, dark: float):
    """A bright-to-dark edge moving right from EDGE_START_PX."""
    return _frames(lambda x, t: np.where(x < EDGE_START_PX + speed_px_per_us * t, bright, dark), duration_us)


def grating_frames(speed_px_per_us: float, duration_us: float):
    """A sinusoid of GRATING_PERIOD_PX between 0.1 and 0.5 moving right."""
    return _frames(lambda x, t: 0.3 + 0.2 * np.sin(2 * np.pi * (x - speed_px_per_us * t) / GRATING_PERIOD_PX),
                   duration_us)


def crossed_pixels(speed_px_per_us: float, duration_us: float) -> np.ndarray:
    """Columns the edge passes well inside the clip (bool [W])."""
    x = np.arange(WIDTH) + 0.5
    return (x > EDGE_START_PX) & (x < EDGE_START_PX + speed_px_per_us * duration_us - 5)


def events_per_pixel(config, frames, columns: np.ndarray | None = None) -> float:
    """Mean events per pixel (of `columns`, default all) that `config` (leak off) makes from `frames`."""
    from simulator.aps import simulate_sequence

    ev = simulate_sequence(list(frames), replace(config, leak_rate_hz=0.0), WIDTH, HEIGHT).events
    per = np.bincount(ev["x"].astype(np.int64), minlength=WIDTH) / HEIGHT
    return float(per[columns].mean() if columns is not None else per.mean())


def main(argv: list[str] | None = None) -> int:
    from simulator.sensor_presets import load_sensor
    from tools.tool_cli import float_in

    p = argparse.ArgumentParser(prog="python -m tools.sensor_bandwidth", description=__doc__.split("\n\n")[0])
    p.add_argument("--sensor", default="davis346", help="a shipped sensor (default davis346)")
    p.add_argument("--speed-px-per-ms", type=float_in(0.001, 1e4, "pixels per millisecond"), default=33.0,
                   help="image speed (default 33: hinge's ~67 px of blur in a 2 ms shutter at the mild level)")
    p.add_argument("--duration-us", type=float_in(100.0, 1e6, "microseconds"), default=3800.0,
                   help="clip length (default 3,800: the 0.1 s clip at 26.2x)")
    p.add_argument("--bright", type=float_in(1e-3, 1.0, "linear intensity"), default=0.5)
    p.add_argument("--dark", type=float_in(1e-3, 1.0, "linear intensity"), default=0.05)
    args = p.parse_args(argv)
    sensor = load_sensor(args.sensor)
    speed = args.speed_px_per_ms / 1000.0
    configs = {args.sensor: sensor, f"{args.sensor} without its cutoff": replace(sensor, lowpass_cutoff_hz=0.0),
               "ideal": load_sensor("ideal")}
    cols = crossed_pixels(speed, args.duration_us)
    print(f"| sensor ({args.speed_px_per_ms:g} px/ms, {args.duration_us:g} us) | events per pixel the edge "
          f"({args.bright:g} -> {args.dark:g}) crosses | events per pixel, grating ({GRATING_PERIOD_PX:g} px, "
          f"{args.speed_px_per_ms / GRATING_PERIOD_PX:g} kHz) |")
    print("|---|---:|---:|")
    for name, cfg in configs.items():
        edge = events_per_pixel(cfg, edge_frames(speed, args.duration_us, args.bright, args.dark), cols)
        grating = events_per_pixel(cfg, grating_frames(speed, args.duration_us))
        print(f"| {name} | {edge:.2f} | {grating:.2f} |")
    return 0


if __name__ == "__main__":
    from tools.tool_cli import run_tool

    sys.exit(run_tool(main))
