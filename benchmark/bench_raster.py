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

    python -m benchmark.bench_raster [--sizes 20000 100000] [--scenes trained early] [--repeats 7] [--torch-max 20000]
"""
from __future__ import annotations

import argparse
import math
import statistics
import time

import numba
import torch

from recon.raster import Camera, render


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
    from recon.initial_points import random_cube

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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[20000, 100000])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--torch-max", type=int, default=20000, help="largest N timed with the slow torch backend")
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    args = ap.parse_args(argv)
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
    raise SystemExit(main())
