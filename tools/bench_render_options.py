"""What Workbench's anti-aliasing samples and shadows cost in render time and change in the events
(prints a table).

Renders the same clip of one scene from the given cameras with the preset's own settings (the
reference) and with each variant (anti-aliasing samples, shadows on / off), simulates events with the
scene's sensor, and compares each stream with the reference's as the render-rate study does: the
relative error of the event count, the time from each event to the nearest reference event of the
same pixel and polarity, and the share of events with no such counterpart; next to render seconds
per view.

    python -m tools.bench_render_options [--scene hinge] [--preset paper] [--duration-ms 40]
        [--cameras 0] [--samples 1 5 8 16] [--shadows on off]
"""
from __future__ import annotations

import argparse

import numpy as np

from common.color import rec709_luma
from common.config import replace_checked
from common.machine import cpu_summary
from datagen.config import load_preset, resolve_scene
from datagen.render import render_clip
from simulator.simulator import simulate
from tools.bench_render_rate import compare_streams
from tools.tool_cli import camera_index, int_in, positive_float, run_tool


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="hinge")
    ap.add_argument("--preset", default="paper")
    ap.add_argument("--duration-ms", type=positive_float, default=40.0)
    ap.add_argument("--cameras", type=camera_index, nargs="+", default=[0])
    ap.add_argument("--samples", type=int_in(0, 64, "Workbench samples"), nargs="+", default=[1, 5, 8, 16], help="Workbench AA samples to try")
    ap.add_argument("--shadows", nargs="+", default=["on", "off"], choices=["on", "off"])
    args = ap.parse_args(argv)
    base = resolve_scene(args.scene, load_preset(args.preset).overrides)
    if base.render.engine != "workbench":
        raise SystemExit(f"bench_render_options: scene {args.scene} renders with {base.render.engine}, not workbench")
    fps = base.render.fps
    t_us = np.round(np.arange(0, args.duration_ms * 1000 * fps / 1e6 + 1e-9) * 1e6 / fps).astype(np.int64)
    tau = t_us / (base.duration_s * 1e6)
    own = (base.render.samples, base.lighting.shadows)
    variants = [own] + [(s, sh == "on") for sh in args.shadows for s in args.samples if (s, sh == "on") != own]
    rows = []
    for samples, shadows in variants:
        cfg = replace_checked(base, render=replace_checked(base.render, samples=samples),
                              lighting=replace_checked(base.lighting, shadows=shadows))
        frames, sec = render_clip(cfg, tau, args.cameras)
        streams = [simulate((rec709_luma(f) for f in frames[c]), t_us, cfg.sensor).events for c in range(len(args.cameras))]
        rows.append((samples, shadows, sec / (len(tau) * len(args.cameras)), streams))
        print(f"  samples {samples}, shadows {'on' if shadows else 'off'}: {sec:.1f} s", flush=True)
    ref = rows[0][3]
    print(f"\nWorkbench options vs. the preset's own (samples {own[0]}, shadows {'on' if own[1] else 'off'}), scene "
          f"{args.scene} ({args.preset}), cameras {args.cameras}, {args.duration_ms:g} ms at {fps:g} FPS, "
          f"{base.render.width}x{base.render.height}; CPU {cpu_summary()}")
    print("| AA samples | shadows | render s / view | vs own | events | count error | time to nearest own event, "
          "median / p90 (us) | events with no counterpart |")
    print("|---|---|---|---|---|---|---|---|")
    for samples, shadows, per_view, streams in rows:
        count_err, med, p90, lost = compare_streams(streams, ref, base.render.width)
        print(f"| {samples} | {'on' if shadows else 'off'} | {per_view:.3f} | {per_view / rows[0][2]:.2f}x | "
              f"{sum(len(s) for s in streams):,} | {count_err:+.2f} % | {med:.1f} / {p90:.1f} | {lost:.2f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
