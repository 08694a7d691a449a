"""Simulator throughput: frames/s and events/s on a dense moving grating (prints a table).

Input: 600 frames of 346x260, a vertical sinusoidal grating of period 32 px moving 1 px per frame,
brightness 20..235 of 255 (frames are DN/255, used as linear intensity), at 3000 FPS.
Configs: `clean` (noise-free, C = 0.2) and `all effects` (mismatch, low-pass, refractory, leak,
shot noise, hot pixels), each with the log response and with v2e's lin-log response (the latter
is configs/sensors/realistic.yaml's choice); the lin-log / log frame-rate ratios are printed last. Each (config, threads) cell is run `--repeats` times, alternating cells so
machine stalls hit all of them alike; the table shows medians. Time covers `EventSimulator.push`
(validation, log response, every enabled stage, sorted EVENT_DTYPE output), not frame generation.

    python -m tools.bench_simulator [--frames 600] [--repeats 5] [--threads 1 2]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numba
import numpy as np

from simulator import EventSimulator, SimulatorConfig
from tools.tool_cli import int_in, positive_int, run_tool

WIDTH, HEIGHT, FPS = 346, 260, 3000
_EFFECTS = dict(threshold_sigma=0.03, lowpass_cutoff_hz=200.0, refractory_us=100, leak_rate_hz=0.1,
                shot_noise_rate_hz=1.0, hot_pixel_fraction=0.001, hot_pixel_rate_hz=20.0)
CONFIGS = {
    "clean": SimulatorConfig(),
    "clean, lin-log": SimulatorConfig(log_mode="linlog"),
    "all effects": SimulatorConfig(**_EFFECTS),
    "all effects, lin-log": SimulatorConfig(log_mode="linlog", **_EFFECTS),
}


def grating_frames(n_frames: int) -> list[np.ndarray]:
    x = np.arange(WIDTH, dtype=np.float64)[None, :].repeat(HEIGHT, axis=0)
    return [((20.0 + 215.0 * (0.5 + 0.5 * np.sin(2 * np.pi * (x - k) / 32.0))) / 255.0).astype(np.float32)
            for k in range(n_frames)]


def run_once(config: SimulatorConfig, frames, t_us, threads: int) -> tuple[float, int]:
    numba.set_num_threads(threads)
    sim = EventSimulator(config, WIDTH, HEIGHT, seed=0, threads=threads)
    n_events = 0
    start = time.perf_counter()
    for frame, t in zip(frames, t_us):
        n_events += len(sim.push(frame, t))
    return time.perf_counter() - start, n_events


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int_in(2, 1_000_000, "frames"), default=600)
    ap.add_argument("--repeats", type=positive_int, default=5)
    ap.add_argument("--threads", type=int_in(1, 1024, "threads"), nargs="+", default=[1, 2])
    args = ap.parse_args(argv)
    threads = [t for t in args.threads if t <= numba.config.NUMBA_NUM_THREADS]
    frames = grating_frames(args.frames)
    t_us = [round(k * 1e6 / FPS) for k in range(args.frames)]
    cells = [(name, th) for name in CONFIGS for th in threads]
    for name, th in cells:  # compile and warm up every specialisation
        run_once(CONFIGS[name], frames[:4], t_us[:4], th)
    times = {cell: [] for cell in cells}
    counts = {}
    for _ in range(args.repeats):
        for cell in cells:
            seconds, n = run_once(CONFIGS[cell[0]], frames, t_us, cell[1])
            times[cell].append(seconds)
            counts[cell] = n
    print(f"simulator throughput: {args.frames} frames {WIDTH}x{HEIGHT} grating at {FPS} FPS, "
          f"median of {args.repeats} runs")
    print("| config | threads | frames/s | events/s | events | us/frame | x real time |")
    print("|---|---|---|---|---|---|---|")
    for cell in cells:
        med = statistics.median(times[cell])
        fps = args.frames / med
        print(f"| {cell[0]} | {cell[1]} | {fps:,.0f} | {counts[cell] / med / 1e6:,.1f} M | {counts[cell]:,} | "
              f"{med / args.frames * 1e6:,.0f} | {fps / FPS:.2f} |")
    for base in ("clean", "all effects"):
        for th in threads:
            ratio = statistics.median(times[(f"{base}, lin-log", th)]) / statistics.median(times[(base, th)])
            print(f"lin-log / log time per frame, {base}, {th} thread(s): {ratio:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
