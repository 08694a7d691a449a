"""Viewer frame rate: a deformable model of N Gaussians (a trained run's Gaussians repeated with a small
jitter up to N) served by `e4dgs viewer`'s server to a real headless Chromium, whose view is then
moved continuously for a few seconds (an orbit around the scene, updated at 30 Hz).

Prints per phase the frames the server rendered and sent per second and the median render + encode
time: the view moving (half resolution, JPEG; the deformation is cached since time stands still),
the one frame drawn when it comes to rest (full resolution, PNG), and time playing at a dataset
camera (each frame deforms the model anew). While the view moves, a new frame is drawn for each
camera update the browser reports, so frames / s is bounded by the browser too (a headless Chromium
renders WebGL in software) and by the render time.

    python -m tools.bench_viewer --run runs/quick/hinge/e4dgs_rgb [--gaussians 20000] [--seconds 10]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch
from tools.tool_cli import positive_float, positive_int, run_tool


def upsampled(model, n: int, seed: int = 0):
    """The model with its Gaussians repeated (with 2 mm of jitter) or subsampled to exactly n."""
    from recon.model import DynamicGaussians

    state = model.state()
    m = state["gaussians"]["means"].shape[0]
    idx = torch.arange(n) % m
    g = torch.Generator().manual_seed(seed)
    for k, v in state["gaussians"].items():
        if v is not None and v.ndim >= 1 and v.shape[0] == m:
            state["gaussians"][k] = v[idx].clone()
    state["gaussians"]["means"] += 0.002 * torch.randn(n, 3, generator=g)
    return DynamicGaussians.from_state(state)


def _wait(pred, timeout_s: float = 60.0) -> None:
    t0 = time.monotonic()
    while not pred():
        if time.monotonic() - t0 > timeout_s:
            raise TimeoutError("the viewer did not answer")
        time.sleep(0.05)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", required=True, help="a trained run folder (its scene must be readable)")
    ap.add_argument("--gaussians", type=positive_int, default=20000)
    ap.add_argument("--seconds", type=positive_float, default=10.0)
    args = ap.parse_args(argv)
    from viewer.app import Viewer
    from viewer.headless import HeadlessChromium
    from viewer.sources import open_source

    src = open_source(args.run)
    src.model = upsampled(src.model, args.gaussians)
    src.model.meta.deform_enabled = True
    viewer = Viewer([src], port=0)
    browser = HeadlessChromium(1280, 800)
    rows = []
    try:
        browser.open(viewer.url)
        _wait(lambda: viewer.tab_ids() and viewer.tab_ids()[0] in viewer.sent
              and viewer.sent[viewer.tab_ids()[0]].scale == 1.0)
        cid = viewer.tab_ids()[0]
        client = viewer.server.get_clients()[cid]
        target = np.asarray(viewer.trajectories[0].c2w[:, :3, 3].mean(axis=0))
        start = np.asarray(client.camera.position)
        radius = float(np.linalg.norm(start[:2] - target[:2]))

        def phase(name, step):
            viewer.move_render_s.clear()
            before = dict(n=0)
            seen = []

            def count():
                s = viewer.sent.get(cid)
                if s is not None and (not seen or s is not seen[-1]):
                    seen.append(s)
            t0 = time.monotonic()
            k = 0
            while time.monotonic() - t0 < args.seconds:
                step(k)
                k += 1
                t_next = t0 + k / 30.0
                while time.monotonic() < t_next:
                    count()
                    time.sleep(0.002)
            wall = time.monotonic() - t0
            frames = [s for s in seen[1:]]
            before["n"] = len(frames)
            sizes = sorted({f"{s.image.shape[1]}x{s.image.shape[0]}" for s in frames})
            ms = statistics.median(s.seconds for s in frames) * 1e3 if frames else float("nan")
            rows.append((name, ", ".join(sizes), len(frames) / wall, ms))

        def orbit(k):
            a = 0.02 * k
            pos = target + np.array([radius * np.cos(a), radius * np.sin(a), start[2] - target[2]])
            client.camera.position = pos
            client.camera.look_at = target

        phase("view moving (time still)", orbit)
        _wait(lambda: viewer.sent[cid].scale == 1.0)
        rest = viewer.sent[cid]
        rows.append(("view comes to rest: one frame", f"{rest.image.shape[1]}x{rest.image.shape[0]}", float("nan"),
                     rest.seconds * 1e3))
        viewer.snap(cid, 0)
        viewer.set_playing(cid, True)
        phase("time playing (cam0 view)", lambda k: None)
    finally:
        browser.close()
        viewer.stop()
    print(f"viewer, {args.gaussians:,} Gaussians, torch {torch.get_num_threads()} threads "
          f"(frames the server rendered and sent to a headless Chromium)")
    print("| phase | resolution | frames / s | median render + encode ms |")
    print("|---|---|---|---|")
    for name, size, fps, ms in rows:
        print(f"| {name} | {size or '-'} | {'-' if fps != fps else f'{fps:.1f}'} | {ms:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
