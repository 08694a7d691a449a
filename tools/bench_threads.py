"""Thread settings on an idle and on a shared machine: the deformation MLP (torch, OpenMP) and the
numba rasterizer (numba's OpenMP layer) under 1 or 2 threads, with OpenMP's default wait policy
(idle threads spin) and with OMP_WAIT_POLICY=PASSIVE (idle threads sleep).

    python -m tools.bench_threads [--repeats 5] [--points 1000 4096] [--gaussians 20000]

Each setting runs in its own process (OpenMP reads its environment once, at start); settings are
alternated within every repeat so machine stalls hit all alike; "loaded" runs one busy process per
core but one beside them (another job sharing the machine). Prints medians (ms) and the CPU.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from tools.tool_cli import positive_int, run_tool

SETTINGS = [(1, None), (1, "PASSIVE"), (2, None), (2, "PASSIVE")]


def child(part: str, size: int, reps: int) -> None:
    """One setting's process: time `part` reps times after a warm-up, print the times (ms) as JSON."""
    import torch

    threads = int(os.environ["OMP_NUM_THREADS"])
    torch.set_num_threads(threads)
    if part == "mlp":
        from recon.precision import timing_field

        f = timing_field(torch.device("cpu"))
        x = torch.rand(size, 3, generator=torch.Generator().manual_seed(1))

        def run():
            dx, dq, ds = f(x, 0.5)
            (dx.square().sum() + dq.square().sum() + ds.square().sum()).backward()
    else:
        import numba

        from tools.bench_raster import SCENES, step

        numba.set_num_threads(threads)
        params, cam, bg = SCENES["trained"](size)
        for p in params:
            p.requires_grad_(True)

        def run():
            step(params, cam, bg, "cpu")
    run()
    times = []
    for _ in range(reps):
        t0 = time.perf_counter()
        run()
        times.append((time.perf_counter() - t0) * 1e3)
    print(json.dumps(times))


def run_setting(part: str, size: int, threads: int, policy: str | None, reps: int) -> list[float]:
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), NUMBA_NUM_THREADS=str(threads))
    env.pop("OMP_WAIT_POLICY", None)
    if policy:
        env["OMP_WAIT_POLICY"] = policy
    out = subprocess.run([sys.executable, "-m", "tools.bench_threads", "--child", part, str(size), str(reps)],
                         env=env, capture_output=True, text=True, check=True, cwd=Path(__file__).resolve().parents[1])
    return json.loads(out.stdout.strip().splitlines()[-1])


def start_load(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def main(argv=None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
        return 0
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=positive_int, default=5, help="processes per setting (each times --reps passes)")
    ap.add_argument("--reps", type=positive_int, default=5)
    ap.add_argument("--points", type=positive_int, nargs="+", default=[1000, 4096], help="MLP sizes (Gaussians)")
    ap.add_argument("--gaussians", type=positive_int, nargs="+", default=[20000], help="rasterizer sizes")
    args = ap.parse_args(argv)
    from common.machine import cpu_summary

    cores = os.cpu_count() or 1
    cases = [("mlp", n) for n in args.points] + [("raster", n) for n in args.gaussians]
    print(f"CPU: {cpu_summary()}, {cores} cores; forward + backward, median ms of {args.repeats} processes x "
          f"{args.reps} passes")
    print("| part | size | machine | " + " | ".join(f"{t} thr{', ' + p if p else ''}" for t, p in SETTINGS) + " |")
    print("|---|---:|---|" + "---:|" * len(SETTINGS))
    for load in ("idle", "loaded"):
        procs = start_load(max(cores - 1, 1)) if load == "loaded" else []
        try:
            for part, size in cases:
                times = {s: [] for s in SETTINGS}
                for _ in range(args.repeats):
                    for s in SETTINGS:
                        times[s] += run_setting(part, size, s[0], s[1], args.reps)
                cells = " | ".join(f"{statistics.median(times[s]):.0f}" for s in SETTINGS)
                print(f"| {part} | {size:,} | {load} | {cells} |", flush=True)
        finally:
            for p in procs:
                p.kill()
                p.wait()
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
