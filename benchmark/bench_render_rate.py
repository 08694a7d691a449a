"""What render rate costs and buys (prints a table).

Renders the same clip of one scene at 3000, 1500 and 750 FPS, simulates events from each (the
scene's sensor config), and compares each stream with the 3000 FPS one: the relative error of the
event count, and the timestamp error of matched events (per pixel and polarity, the k-th event of
a stream is matched to the k-th of the reference), next to the render time each rate took.

    python -m benchmark.bench_render_rate [--scene lego] [--duration-ms 40] [--cameras 0]
"""
from __future__ import annotations

import argparse

import numpy as np

from datagen.config import load_preset, resolve_scene
from datagen.render import render_clip
from simulator.pixel import rec709_luma
from simulator.simulator import simulate

RATES = (3000, 1500, 750)


def matched_time_errors(events: np.ndarray, reference: np.ndarray, width: int) -> np.ndarray:
    """|t - t_ref| (us) of the k-th event of each (pixel, polarity) against the reference's k-th."""
    def grouped(ev):
        key = (ev["y"].astype(np.int64) * width + ev["x"]) * 2 + (ev["p"] > 0)
        order = np.lexsort((ev["t"], key))
        key, t = key[order], ev["t"][order]
        start = np.r_[0, np.flatnonzero(np.diff(key)) + 1]
        rank = np.arange(len(key)) - np.repeat(start, np.diff(np.r_[start, len(key)]))
        return key * (1 << 20) + rank, t

    ka, ta = grouped(events)
    kb, tb = grouped(reference)
    common, ia, ib = np.intersect1d(ka, kb, assume_unique=True, return_indices=True)
    return np.abs(ta[ia] - tb[ib]).astype(np.float64)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="lego")
    ap.add_argument("--duration-ms", type=float, default=40.0)
    ap.add_argument("--cameras", type=int, nargs="+", default=[0])
    ap.add_argument("--preset", default="quick")
    args = ap.parse_args(argv)
    cfg = resolve_scene(args.scene, load_preset(args.preset).overrides)
    clip_us = int(round(args.duration_ms * 1000))
    streams, seconds = {}, {}
    for fps in RATES:
        t_us = np.round(np.arange(0, clip_us * fps / 1e6 + 1e-9) * 1e6 / fps).astype(np.int64)
        tau = t_us / (cfg.duration_s * 1e6)
        frames, seconds[fps] = render_clip(cfg, tau, args.cameras)
        streams[fps] = [simulate((rec709_luma(f) for f in frames[c]), t_us, cfg.sensor).events
                        for c in range(len(args.cameras))]
        print(f"  {fps} FPS: {len(t_us)} frames rendered in {seconds[fps]:.1f} s", flush=True)
    ref = streams[RATES[0]]
    print(f"\nrender rate vs. 3000 FPS events, scene {args.scene}, cameras {args.cameras}, {args.duration_ms:g} ms clip")
    print("| render FPS | render s | events | count error | timestamp error median / p90 (us) | matched |")
    print("|---|---|---|---|---|---|")
    for fps in RATES:
        n = sum(len(s) for s in streams[fps])
        n_ref = sum(len(s) for s in ref)
        errs = np.concatenate([matched_time_errors(s, r, cfg.render.width) for s, r in zip(streams[fps], ref)])
        print(f"| {fps} | {seconds[fps]:.1f} | {n:,} | {100 * (n - n_ref) / max(n_ref, 1):+.1f} % | "
              f"{np.median(errs):.1f} / {np.percentile(errs, 90):.1f} | {100 * len(errs) / max(n_ref, 1):.1f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
