"""Rasterizer speed: forward + backward time per step at 346x260 (prints a table of medians).

Two scenes, a loss touching image, alpha and depth:
- `trained`: N Gaussians of realistic sizes (a trained 3DGS of an object: centres in a 2 m cube seen
  from 4 m, scales log-uniform in [0.005, 0.05] m, random orientations and opacities), RGB colours;
- `early`: the start of training, what the methods' initialisation makes of a quick object scene:
  N points uniform in a cube of half-size 0.35 x the rig radius (3.8 m) seen from 4 m with a 50 degree
  horizontal field of view, isotropic scales from the 3 nearest neighbours, opacity 0.1, grey, one
  channel (the events-only model). Its footprints are ~20 px in radius and cover the whole image
  hundreds of times over, so the per-pixel work dominates (and training's first hundreds of steps).
Backends `torch` (reference) and `cpu` (numba), 1 and 2 threads, alternated so that machine stalls
hit all alike.

`--runs DIR ...` is the headline: the states training really visits. Each training folder's
snapshots and final model (a quick run's 10 / 25 / 50 / 75 / 100 %) are rendered from the scene's
camera 0 at t = 0.5 with the deformation applied, forward + backward of the same loss, with the cpu
backend at 1 thread, at full resolution and at the coarse-to-fine factors 2 and 4
(recon.coarse.coarse_camera), all alternated.

    python -m tools.bench_raster [--sizes 20000 100000] [--scenes trained early] [--repeats 7] [--torch-max 20000]
    python -m tools.bench_raster --runs runs/field_curves/hinge/d3dgs_trajectory [--factors 1 2 4]
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import numba
import torch

from recon.raster import Camera, render
from tools.tool_cli import positive_int, run_tool


def make_scene(n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    means = (torch.rand(n, 3, generator=g) - 0.5) * 2.0
    quats = torch.randn(n, 4, generator=g)
    scales = torch.exp(torch.empty(n, 3).uniform_(torch.log(torch.tensor(0.005)), torch.log(torch.tensor(0.05)), generator=g))
    opac = torch.rand(n, generator=g) * 0.9 + 0.05
    colors = torch.rand(n, 3, generator=g)
    K = torch.tensor([[300.0, 0, 173.0], [0, 300.0, 130.0], [0, 0, 1]])
    w2c = torch.eye(4)
    w2c[2, 3] = 4.0
    return [means, quats, scales, opac, colors], Camera(K, w2c, 346, 260), torch.zeros(3)


def make_early_scene(n: int, seed: int = 0):
    from recon.gaussians import nearest_neighbour_scale
    from recon.point_clouds import random_cube

    points = random_cube(n, 0.35 * 3.8, seed=seed)      # the methods' object initialisation
    means = torch.from_numpy(points)
    scales = torch.from_numpy(nearest_neighbour_scale(points))[:, None].expand(-1, 3).contiguous()
    quats = torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(n, 1)
    opac = torch.full((n,), 0.1)
    colors = torch.full((n, 1), 0.5)
    fx = 173.0 / math.tan(math.radians(25.0))
    K = torch.tensor([[fx, 0, 173.0], [0, fx, 130.0], [0, 0, 1]])
    w2c = torch.eye(4)
    w2c[2, 3] = 4.0
    return [means, quats, scales, opac, colors], Camera(K, w2c, 346, 260), torch.zeros(1)


SCENES = {"trained": make_scene, "early": make_early_scene}


def step(params, cam, bg, backend):
    for p in params:
        p.grad = None
    out = render(*params, cam, bg, backend=backend)
    loss = out.image.square().mean() + out.alpha.mean() + 0.01 * out.depth.mean()
    loss.backward()


def training_states(run_dirs: list[str]) -> list[tuple[str, object]]:
    """(label, model) of every snapshot and the final model of each training folder, in iteration order."""
    from pathlib import Path

    import recon
    states = []
    for run in map(Path, run_dirs):
        files = sorted((run / "snapshots").glob("iter_*.pt")) + [run / "model.pt"]
        seen = set()
        for f in files:
            if not f.exists():
                raise SystemExit(f"bench_raster: {f} does not exist (--runs takes finished training folders)")
            model = recon.load(f)
            if model.meta.iteration in seen:       # the last snapshot is the final model
                continue
            seen.add(model.meta.iteration)
            states.append((f"{run.name} @ {model.meta.iteration}", model))
    return states


def time_training_states(run_dirs: list[str], factors: list[int], repeats: int) -> int:
    from common.machine import cpu_summary
    from recon.coarse import coarse_camera
    from recon.render import deformed, render_deformed

    numba.set_num_threads(1)
    torch.set_num_threads(1)
    rows = []
    for label, model in training_states(run_dirs):
        g = model.gaussians
        for p in g.parameters():
            p.requires_grad_(True)
        field = model.deform if model.meta.deform_enabled else None
        cam = model.camera(0, 0.5)

        def once(f):
            for p in g.parameters():
                p.grad = None
            out = render_deformed(g, deformed(g, field, 0.5, model.meta.precision), coarse_camera(cam, f),
                                  model.background, "cpu")
            (out.image.square().mean() + out.alpha.mean() + 0.01 * out.depth.mean()).backward()
            return out
        times = {f: [] for f in factors}
        for f in factors:
            once(f)
        for _ in range(repeats):
            for f in factors:
                t0 = time.perf_counter()
                once(f)
                times[f].append(time.perf_counter() - t0)
        radii = once(1).radii.detach().float()
        rows.append((label, len(model), float(radii[radii > 0].median()) if (radii > 0).any() else 0.0,
                     [statistics.median(times[f]) * 1e3 for f in factors]))
    print(f"training states: forward + backward per render (deformation included), cpu backend, 1 thread, "
          f"median of {repeats} (ms); CPU: {cpu_summary()}")
    print("| state | Gaussians | median radius px | " + " | ".join(f"factor {f}" for f in factors) + " |")
    print("|---|---:|---:|" + "---:|" * len(factors))
    for label, n, rad, ms in rows:
        print(f"| {label} | {n:,} | {rad:.0f} | " + " | ".join(f"{m:,.1f}" for m in ms) + " |")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", nargs="+", metavar="DIR", help="time the saved states of these training folders")
    ap.add_argument("--factors", type=positive_int, nargs="+", default=[1, 2, 4], help="coarse-to-fine factors (--runs)")
    ap.add_argument("--sizes", type=positive_int, nargs="+", default=[20000, 100000])
    ap.add_argument("--repeats", type=positive_int, default=7)
    ap.add_argument("--torch-max", type=positive_int, default=20000, help="largest N timed with the slow torch backend")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    args = ap.parse_args(argv)
    if args.runs:
        return time_training_states(args.runs, args.factors, args.repeats)
    rows = []
    for kind, n in [(k, n) for k in args.scenes for n in args.sizes]:
        params, cam, bg = SCENES[kind](n)
        for p in params:
            p.requires_grad_(True)
        cells = [(b, t) for b in ("cpu", "torch") for t in (1, 2) if b == "cpu" or n <= args.torch_max]
        times = {c: [] for c in cells}
        for b, t in cells:  # warm-up / compile
            numba.set_num_threads(t)
            torch.set_num_threads(t)
            step(params, cam, bg, b)
        for r in range(args.repeats if n <= args.torch_max else args.repeats):
            for b, t in cells:
                if b == "torch" and r >= 3:
                    continue
                numba.set_num_threads(t)
                torch.set_num_threads(t)
                t0 = time.perf_counter()
                step(params, cam, bg, b)
                times[(b, t)].append(time.perf_counter() - t0)
        with torch.no_grad():
            radii = render(*params, cam, bg, backend="cpu").radii.float()
        for b, t in cells:
            rows.append((kind, n, b, t, statistics.median(times[(b, t)]) * 1e3, float(radii[radii > 0].median())))
    print("forward + backward per step, 346x260 (median ms)")
    print("| scene | Gaussians | backend | threads | ms / step | median radius px |")
    print("|---|---|---|---|---|---|")
    for kind, n, b, t, ms, rad in rows:
        print(f"| {kind} | {n:,} | {b} | {t} | {ms:,.1f} | {rad:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
