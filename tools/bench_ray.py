"""Wall time of a tiny benchmark grid run serially (today's default) and as Ray tasks on this machine.

The grid: the six leaderboard cells on the `tiny_motion` dataset's cubes scene (2 cameras, 64x48),
`--iterations` each, densification off, LPIPS (AlexNet) scoring. Serial runs in this process with
torch's default thread count; Ray starts a local instance with `--cpus` CPUs and gives each job one
CPU (so `--cpus` jobs run at once, one thread each). Ray's time includes starting Ray and its
workers, which is what a user pays. The two modes alternate `--repeats` times into fresh folders
(stalls of the machine hit both alike); the table shows medians and the serial / Ray ratio, and
checks that both modes produced the same PSNR per job.

    python -m tools.bench_ray [--iterations 100] [--repeats 2] [--cpus 2] [--data data/tiny_motion]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from benchmark.config import BenchConfig, CellSpec
from benchmark.runner import run_bench
from common.config import build_config
from common.taskpool import RayOptions
from tools.tool_cli import positive_int, run_tool


# the bundled methods' six cells, as in the quick preset
CELLS = ("d3dgs_sharp", "d3dgs_blur", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")


def tiny_grid(iterations: int, scene: str = "cubes") -> BenchConfig:
    train = {"train.iterations": iterations, "train.scale_schedule": False, "train.densify.enabled": False,
             "train.init.n_points_object": 300, "train.checkpoint_every": max(iterations // 4, 1),
             "train.snapshots": [0.5, 1.0]}
    extra = {"d3dgs_sharp": {"frames": "sharp"}, "d3dgs_blur": {"frames": "strong"},
             "deblur_d3dgs": {"frames": "strong"}, "e4dgs_rgb": {"rgb_frames": "strong"}}
    method = {"d3dgs_sharp": "d3dgs", "d3dgs_blur": "d3dgs"}
    cells = {c: CellSpec(method.get(c, c), overrides={**train, **extra.get(c, {})}) for c in CELLS}
    return build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [scene], "cells": cells, "lpips_net": "alex"})


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--iterations", type=positive_int, default=100)
    ap.add_argument("--repeats", type=positive_int, default=2)
    ap.add_argument("--cpus", type=positive_int, default=2, help="CPUs of the local Ray (one per job)")
    ap.add_argument("--data", type=Path, default=Path("data/tiny_motion"), help="tiny_motion dataset root (made if missing)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_ray_") as tmp:
        return _compare(tiny_grid(args.iterations), args, Path(tmp))


def _compare(cfg: BenchConfig, args, tmp: Path) -> int:
    quiet = lambda s: None  # noqa: E731
    run_bench(cfg, "tiny", args.data, tmp / "warm", studies=("main",), progress=False, log=quiet)
    # ^ dataset, numba caches, page cache: not timed
    times: dict[str, list[float]] = {"serial": [], "ray": []}
    psnr: dict[str, dict[str, float]] = {}
    for rep in range(args.repeats):
        for mode in ("serial", "ray"):
            out = tmp / f"{mode}{rep}"
            t0 = time.perf_counter()
            rows = run_bench(cfg, "tiny", args.data, out, studies=("main",), progress=False, log=quiet,
                             ray=RayOptions(local_cpus=args.cpus) if mode == "ray" else None)
            times[mode].append(time.perf_counter() - t0)
            psnr[mode] = {r["key"]: r["psnr"] for r in rows}
            print(f"  repeat {rep + 1} {mode}: {times[mode][-1]:.1f} s", flush=True)
    med = {m: statistics.median(v) for m, v in times.items()}
    print(f"\nTiny grid: {len(CELLS)} jobs x {args.iterations} iterations on tiny_motion/cubes; "
          f"local Ray with {args.cpus} CPUs, 1 per job; medians of {args.repeats}")
    print("| mode | wall (s), median | runs (s) |\n|---|---|---|")
    for m in ("serial", "ray"):
        print(f"| {m} | {med[m]:.1f} | {', '.join(f'{t:.1f}' for t in times[m])} |")
    print(f"\nserial / Ray: {med['serial'] / med['ray']:.2f}x")
    diff = max(abs(psnr["serial"][k] - psnr["ray"][k]) for k in psnr["serial"])
    print(f"largest PSNR difference between the modes: {diff:.2e} dB (serial uses torch's default threads, "
          "Ray one thread per job)")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
