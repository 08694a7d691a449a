"""What a training step costs outside the rasterizer: each part's fast implementation against the form it replaced.

    python -m tools.bench_step_rest [--scene data/quick/hinge_x26.2] [--gaussians 11574] [--reps 15]

Parts (forward + backward where differentiable, 1 thread, median of --reps, ms), each at the quick
scenes' size (346 x 260) and at the coarse-to-fine stages' 1/2 and 1/4:
- D-SSIM: `recon.losses.ssim` (two 1-D passes) against `ssim_ref` (the 11 x 11 window), for the RGB
  frames of D3DGS and the grayscale frames of E2VID + D3DGS;
- the trajectory offsets of N Gaussians: the broadcast sum against `basis @ motion` (N batched products);
- one Adam step over a late model's parameters: torch's fused kernel against its per-tensor loop;
- an ESS window's events (E-4DGS cuts one per step): from the columns in memory against the HDF5 file.
The CPU (model and flags) is printed above the table.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from tools.tool_cli import positive_int, run_tool


def timed(fn, reps: int) -> float:
    fn()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times) * 1e3


def grad_of(loss_fn, x):
    """fn() for timed(): the loss of a fresh leaf copy of x, forward and backward."""
    def run():
        leaf = x.clone().requires_grad_(True)
        loss_fn(leaf).backward()
    return run


def rows(args) -> list[tuple[str, str, float, float]]:
    import numpy as np
    import torch

    from recon.losses import ssim, ssim_ref
    from recon.trajectory import n_basis, trajectory_basis, trajectory_offsets

    out = []
    g = torch.Generator().manual_seed(0)
    for factor in (1, 2, 4):
        h, w = 260 // factor, 346 // factor
        for c, who in ((3, "RGB"), (1, "gray")):
            a = torch.rand(h, w, c, generator=g)
            b = (a + 0.1 * torch.rand(h, w, c, generator=g)).clamp(0, 1)
            out.append((f"D-SSIM, {who}", f"{w} x {h}", timed(grad_of(lambda x: ssim(x, b), a), args.reps),
                        timed(grad_of(lambda x: ssim_ref(x, b), a), args.reps)))
    nb = n_basis(3, 2)
    motion = torch.randn(args.gaussians, nb, 10, generator=g)
    basis = trajectory_basis(torch.tensor(0.37), 3, 2)
    wgt = torch.randn(args.gaussians, 10, generator=g)
    out.append(("trajectory offsets", f"{args.gaussians:,} Gaussians",
                timed(grad_of(lambda m: (torch.cat(trajectory_offsets(m, 0.37, 3, 2), 1) * wgt).sum(), motion), args.reps),
                timed(grad_of(lambda m: (torch.matmul(basis, m) * wgt).sum(), motion), args.reps)))
    # a late model's parameter shapes: means, SH DC and rest (degree 3), opacity, scales, rotations, trajectories
    shapes = [(3,), (1, 1), (15, 1), (1,), (3,), (4,), (nb, 10)]
    adam = []
    for kw in ({"fused": True}, {}):
        ps = [torch.nn.Parameter(torch.randn(args.gaussians, *s, generator=g)) for s in shapes]
        opt = torch.optim.Adam([{"params": [p], "lr": 1e-3} for p in ps], lr=0.0, eps=1e-15, **kw)
        for p in ps:
            p.grad = torch.randn_like(p)
        adam.append(timed(opt.step, args.reps))
    out.append(("Adam step", f"{sum(np.prod(s) for s in shapes) * args.gaussians:,} values", *adam))
    scene = Path(args.scene or DEFAULT_SCENE)
    if not (scene / "manifest.json").exists():
        print(f"bench_step_rest: {scene}: no dataset here, the event-window row is left out "
              f"(make dataset SCENES={scene.name.split('_x')[0]})", file=sys.stderr)
    else:
        from recon.event_windows import EventSource
        from scene_format.reader import SceneDataset

        ds = SceneDataset(scene)
        disk, mem = EventSource(ds.event_file(0)), EventSource(ds.event_file(0))
        mem.load()
        n = max(1, int(0.125 * disk.n))         # the middle of ESS's 5-20 % of a camera's events
        rng = np.random.default_rng(0)
        starts = [int(rng.integers(1, disk.n - n + 1)) for _ in range(args.reps + 1)]
        it = {"m": iter(starts), "d": iter(starts)}
        out.append(("event window", f"{n:,} of {disk.n:,} events",
                    timed(lambda: mem.window(0, next(it["m"]), n), args.reps),
                    timed(lambda: disk.window(0, next(it["d"]), n), args.reps)))
    return out


DEFAULT_SCENE = "data/quick/hinge_x26.2"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default=None,
                    help="a scene folder for the event-window row (default data/quick/hinge_x26.2, left out if missing)")
    ap.add_argument("--gaussians", type=positive_int, default=11574, help="model size (bench_train's late state)")
    ap.add_argument("--reps", type=positive_int, default=15)
    args = ap.parse_args(argv)
    if args.scene is not None and not (Path(args.scene) / "manifest.json").exists():   # before any timing
        ap.error(f"--scene {args.scene}: no generated scene here (no manifest.json)")
    import numba
    import torch

    from common.machine import cpu_summary

    torch.set_num_threads(1)
    numba.set_num_threads(1)
    print(f"The rest of a training step, 1 thread, median of {args.reps} (ms; forward + backward where "
          f"differentiable); CPU: {cpu_summary()}")
    print("| part | size | now | before | speed-up |")
    print("|---|---|---:|---:|---:|")
    for part, size, now, before in rows(args):
        print(f"| {part} | {size} | {now:.2f} | {before:.2f} | {before / now:.1f}x |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
