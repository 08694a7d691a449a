"""Why Workbench: events per second of simulated time from each render engine (prints a table).

Per-frame Monte-Carlo noise of a path tracer changes pixel values from one frame to the next and
the simulator turns that into events nobody asked for. This renders the same clip of one scene from
one camera with Workbench (the default), Cycles at 1 and 16 samples per pixel, simulates events with
the scene's own sensor config, and reports events per second of simulated time, for the moving clip
and for a frozen one (scene and camera held at the middle of the clip, where an ideal renderer
gives no events at all), next to the render time per view.

    python -m tools.bench_engines [--scene cubes] [--frames 90]
"""
from __future__ import annotations

import argparse

import numpy as np

from datagen.config import load_preset, resolve_scene
from datagen.render import render_clip
from common.config import replace_checked
from common.color import rec709_luma
from simulator.simulator import simulate
from tools.tool_cli import positive_int, run_tool

ENGINES = [("workbench", 8), ("cycles", 1), ("cycles", 16)]


def events_per_second(frames: np.ndarray, t_us: np.ndarray, sensor) -> float:
    stream = simulate((rec709_luma(f) for f in frames), t_us, sensor)
    return len(stream) / ((t_us[-1] - t_us[0]) * 1e-6)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cubes")
    ap.add_argument("--frames", type=positive_int, default=90, help="rendered frames at the scene's fps (default 90 = 30 ms)")
    ap.add_argument("--preset", default="quick")
    args = ap.parse_args(argv)
    base = resolve_scene(args.scene, load_preset(args.preset).overrides)
    fps = base.render.fps
    t_us = np.round(np.arange(args.frames) * 1e6 / fps).astype(np.int64)
    tau = t_us / (base.duration_s * 1e6)
    rows = []
    for engine, spp in ENGINES:
        cfg = replace_checked(base, render=replace_checked(base.render, engine=engine, samples=spp))
        moving, sec = render_clip(cfg, tau)
        frozen, _ = render_clip(cfg, np.full(len(tau), 0.5))
        rows.append((engine, spp, events_per_second(moving[0], t_us, cfg.sensor),
                     events_per_second(frozen[0], t_us, cfg.sensor), sec / len(tau)))
        print(f"  {engine} {spp} spp done", flush=True)
    print(f"\nevents per second of simulated time, scene {args.scene}, camera 0, {args.frames} frames at {fps:g} FPS, "
          f"{base.render.width}x{base.render.height}")
    print("| engine | samples | events/s, moving clip | events/s, frozen clip | render s/view |")
    print("|---|---|---|---|---|")
    for engine, spp, ev_moving, ev_frozen, s in rows:
        print(f"| {engine} | {spp} | {ev_moving / 1e6:,.2f} M | {ev_frozen / 1e6:,.3f} M | {s:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
