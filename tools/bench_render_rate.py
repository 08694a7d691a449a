"""What render rate costs and buys (prints a table).

Renders the same clip of one scene at several rates (default 3000, 1500 and 750 FPS), simulates
events from each (the scene's sensor config), and compares each stream with the one from the highest
rate: the relative error of the event count, and the timestamp error (each event against the
nearest reference event of the same pixel and polarity), next to the render time each rate took.
With fast camera motion, `--rates 6000 3000 1500` checks whether 3000 FPS still resolves the
per-pixel crossing times when the image moves several pixels per rendered frame.

    python -m tools.bench_render_rate [--scene lego] [--duration-ms 40] [--cameras 0] [--rates 6000 3000]
"""
from __future__ import annotations

import argparse

import numpy as np

from datagen.config import load_preset, resolve_scene
from datagen.render import render_clip
from common.color import rec709_luma
from simulator.simulator import simulate
from tools.tool_cli import camera_index, int_in, positive_float, run_tool

RATES = (3000, 1500, 750)


def nearest_time_errors(events: np.ndarray, reference: np.ndarray, width: int) -> np.ndarray:
    """For each event: |t - t_ref| (us) to the nearest reference event of the same pixel and polarity
    (inf where that pixel and polarity has no reference event)."""
    def keyed(ev):
        key = (ev["y"].astype(np.int64) * width + ev["x"]) * 2 + (ev["p"] > 0)
        return key, ev["t"].astype(np.int64)

    ka, ta = keyed(events)
    kb, tb = keyed(reference)
    span = np.int64(1) << 40
    ref = np.sort(kb * span + tb)
    val = ka * span + ta
    i = np.searchsorted(ref, val)
    best = np.full(len(val), np.inf)
    for j in (i - 1, i):
        ok = (j >= 0) & (j < len(ref))
        jj = np.clip(j, 0, len(ref) - 1)
        same = ok & (ref[jj] // span == ka)
        best = np.where(same, np.minimum(best, np.abs(ref[jj] - val)), best)
    return best


def compare_streams(streams: list[np.ndarray], reference: list[np.ndarray], width: int) -> tuple[float, float, float, float]:
    """Per-camera event streams against the reference's -> (count error %, median and p90 us to the
    nearest reference event of the same pixel and polarity, % of events with no such counterpart)."""
    n, n_ref = sum(len(s) for s in streams), sum(len(s) for s in reference)
    errs = np.concatenate([nearest_time_errors(s, r, width) for s, r in zip(streams, reference)])
    found = errs[np.isfinite(errs)]
    med, p90 = (float(np.median(found)), float(np.percentile(found, 90))) if len(found) else (np.nan, np.nan)
    return 100 * (n - n_ref) / max(n_ref, 1), med, p90, 100 * (len(errs) - len(found)) / max(n, 1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="lego")
    ap.add_argument("--duration-ms", type=positive_float, default=40.0)
    ap.add_argument("--cameras", type=camera_index, nargs="+", default=[0])
    ap.add_argument("--preset", default="quick")
    ap.add_argument("--rates", type=int_in(1, 1_000_000, "frames per second"), nargs="+", default=list(RATES), help="render rates (FPS); the highest is the reference")
    args = ap.parse_args(argv)
    rates = sorted(set(args.rates), reverse=True)
    cfg = resolve_scene(args.scene, load_preset(args.preset).overrides)
    clip_us = int(round(args.duration_ms * 1000))
    streams, seconds = {}, {}
    for fps in rates:
        t_us = np.round(np.arange(0, clip_us * fps / 1e6 + 1e-9) * 1e6 / fps).astype(np.int64)
        tau = t_us / (cfg.duration_s * 1e6)
        frames, seconds[fps] = render_clip(cfg, tau, args.cameras)
        streams[fps] = [simulate((rec709_luma(f) for f in frames[c]), t_us, cfg.sensor).events
                        for c in range(len(args.cameras))]
        print(f"  {fps} FPS: {len(t_us)} frames rendered in {seconds[fps]:.1f} s", flush=True)
    ref = streams[rates[0]]
    print(f"\nrender rate vs. {rates[0]} FPS events, scene {args.scene} ({args.preset}), cameras {args.cameras}, "
          f"{args.duration_ms:g} ms clip")
    print(f"| render FPS | render s | events | count error | time to nearest {rates[0]} FPS event, median / p90 (us) | "
          "events with no counterpart |")
    print("|---|---|---|---|---|---|")
    for fps in rates:
        count_err, med, p90, lost = compare_streams(streams[fps], ref, cfg.render.width)
        print(f"| {fps} | {seconds[fps]:.1f} | {sum(len(s) for s in streams[fps]):,} | {count_err:+.1f} % | "
              f"{med:.1f} / {p90:.1f} | {lost:.2f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
