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
# `--set effects`: the DAVIS346-like pixel (configs/sensors/davis346.yaml's fitted values) alone and with
# each optional effect on (the values its `effects:` section supplies; the DVXplorer's 200 us readout
# steps; shot noise with an OFF-heavy split, light dependence and per-pixel spread as the IMX636 fit's, and
# diffusion noise alike)
_PIXEL = dict(pos_threshold=0.25, neg_threshold=0.25, threshold_sigma=0.03, refractory_us=500, leak_rate_hz=0.0029)
EFFECT_CONFIGS = {
    "pixel only": SimulatorConfig(**_PIXEL),
    "+ latency and jitter (20 +- 10 us)": SimulatorConfig(**_PIXEL, latency_us=20.0, latency_jitter_us=10.0),
    "+ semi-synchronous readout (200 us)": SimulatorConfig(**_PIXEL, readout_period_us=200),
    "+ bandwidth (12 Mev/s, 1 ms buffer)": SimulatorConfig(**_PIXEL, max_event_rate_hz=12e6, max_readout_delay_us=1000),
    "+ ON / OFF mismatch apart (0.02 / 0.04)": SimulatorConfig(**_PIXEL, pos_threshold_sigma=0.02, neg_threshold_sigma=0.04),
    "+ shot noise (1 Hz, 34 % ON, spread 0.6 dec)": SimulatorConfig(**_PIXEL, shot_noise_rate_hz=1.0, shot_noise_on_fraction=0.34,
                                                                  shot_noise_sigma_decades=0.6),
    "+ diffusion noise (1 Hz, 34 % ON, spread 0.6 dec)": SimulatorConfig(**_PIXEL, diffusion_noise_rate_hz=1.0,
                                                                       diffusion_noise_on_fraction=0.34,
                                                                       diffusion_noise_sigma_decades=0.6),
}
SETS = {"default": CONFIGS, "effects": EFFECT_CONFIGS}


def grating_frames(n_frames: int) -> list[np.ndarray]:
    x = np.arange(WIDTH, dtype=np.float64)[None, :].repeat(HEIGHT, axis=0)
    return [((20.0 + 215.0 * (0.5 + 0.5 * np.sin(2 * np.pi * (x - k) / 32.0))) / 255.0).astype(np.float32)
            for k in range(n_frames)]


def run_once(config: SimulatorConfig, frames, t_us, threads: int, keep: list | None = None) -> tuple[float, int]:
    numba.set_num_threads(threads)
    sim = EventSimulator(config, WIDTH, HEIGHT, seed=0, threads=threads)
    n_events = 0
    start = time.perf_counter()
    for frame, t in zip(frames, t_us):
        out = sim.push(frame, t)
        n_events += len(out)
        if keep is not None:
            keep.append(out)
    out = sim.flush()
    n_events += len(out)
    seconds = time.perf_counter() - start
    if keep is not None:
        keep.append(out)
    return seconds, n_events


def stream_figures(chunks: list) -> str:
    """What an effect changes in the realism report: the interval floor and the timestamps' steps."""
    from eventio.events import EventStream
    from eventio.realism import inter_event_intervals

    s = EventStream(np.concatenate(chunks), WIDTH, HEIGHT)
    iei, same = inter_event_intervals(s)
    steps = np.diff(np.unique(s.events["t"]))
    return (f"{np.percentile(iei, 0.1):,.0f} / {np.percentile(iei, 50):,.0f} | {same.mean():.3f} | "
            f"{np.median(steps):,.0f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int_in(2, 1_000_000, "frames"), default=600)
    ap.add_argument("--repeats", type=positive_int, default=5)
    ap.add_argument("--threads", type=int_in(1, 1024, "threads"), nargs="+", default=[1, 2])
    ap.add_argument("--set", dest="config_set", choices=tuple(SETS), default="default",
                    help="default: clean and all pixel effects, log and lin-log; effects: the optional effects one "
                         "at a time beside the pixel alone, with what each changes in the stream")
    args = ap.parse_args(argv)
    configs = SETS[args.config_set]
    threads = [t for t in args.threads if t <= numba.config.NUMBA_NUM_THREADS]
    frames = grating_frames(args.frames)
    t_us = [round(k * 1e6 / FPS) for k in range(args.frames)]
    cells = [(name, th) for name in configs for th in threads]
    for name, th in cells:  # compile and warm up every specialisation
        run_once(configs[name], frames[:4], t_us[:4], th)
    times = {cell: [] for cell in cells}
    counts = {}
    for _ in range(args.repeats):
        for cell in cells:
            seconds, n = run_once(configs[cell[0]], frames, t_us, cell[1])
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
    if args.config_set == "effects":
        print("\n| config | events | IEI p0.1 / p50 (us) | same polarity | median step between timestamps (us) |")
        print("|---|---|---|---|---|")
        for name, cfg in configs.items():
            chunks: list = []
            _, n = run_once(cfg, frames, t_us, threads[0], chunks)
            print(f"| {name} | {n:,} | {stream_figures(chunks)} |")
        return 0
    for base in ("clean", "all effects"):
        for th in threads:
            ratio = statistics.median(times[(f"{base}, lin-log", th)]) / statistics.median(times[(base, th)])
            print(f"lin-log / log time per frame, {base}, {th} thread(s): {ratio:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
