"""The leaderboard's cells under two sensors side by side: each cell's mean ± sd over its seeds on each
scene, per sensor, and the difference with Welch's t-test (two-sided, 0.05), from two results folders
of the same preset (`e4dgs bench ... --seeds 3` and the same with `--sensor NAME`).

    python -m tools.sensor_compare runs/quick@own runs/quick@davis346 [--metric psnr] [--reference runs/quick]

`--reference` adds the RGB cells of another results folder as fixed rows (they see no events: the
sensor does not change them).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

METRICS = ("psnr", "psnr_dyn", "ssim", "lpips")


def read_rows(folder: Path) -> list[dict]:
    path = folder / "results.jsonl"
    if not path.is_file():
        raise SystemExit(f"sensor_compare: error: {path}: no such results file")
    rows = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            try:
                rows.append(json.loads(line))
            except ValueError as exc:
                raise SystemExit(f"sensor_compare: error: {path}:{i}: not a JSON row ({exc})") from None
    return [r for r in rows if r.get("study") == "main" and r.get("status") != "failed"]


def by_cell(rows: list[dict], metric: str) -> dict[tuple[str, str], list[float]]:
    out: dict[tuple[str, str], list[float]] = {}
    for r in rows:
        if r.get(metric) is not None:
            out.setdefault((r["cell"], r["scene"]), []).append(float(r[metric]))
    return out


def welch_p(a: list[float], b: list[float]) -> float:
    """Two-sided p-value of Welch's t-test; nan with fewer than two values on a side."""
    from scipy.stats import ttest_ind

    if len(a) < 2 or len(b) < 2:
        return float("nan")
    return float(ttest_ind(a, b, equal_var=False).pvalue)


def fmt(v: list[float]) -> str:
    if not v:
        return "-"
    return f"{np.mean(v):.2f} ± {np.std(v, ddof=1):.2f}" if len(v) > 1 else f"{v[0]:.2f}"


def main(argv: list[str] | None = None) -> int:
    from tools.tool_cli import existing_folder

    p = argparse.ArgumentParser(prog="python -m tools.sensor_compare", description=__doc__.split("\n\n")[0])
    p.add_argument("first", type=existing_folder, help="results folder of the first sensor (e.g. runs/quick@own)")
    p.add_argument("second", type=existing_folder, help="results folder of the second sensor (runs/quick@davis346)")
    p.add_argument("--metric", choices=METRICS, default="psnr")
    p.add_argument("--reference", type=existing_folder, default=None,
                   help="a results folder whose RGB cells are shown as fixed rows")
    args = p.parse_args(argv)
    a, b = (by_cell(read_rows(f), args.metric) for f in (args.first, args.second))
    cells = sorted({c for c, _ in a} | {c for c, _ in b})
    scenes = sorted({s for _, s in a} | {s for _, s in b})
    if not cells:
        raise SystemExit(f"sensor_compare: error: {args.first} and {args.second}: no main rows with {args.metric}")
    head = " | ".join(f"{s} {args.first.name} | {s} {args.second.name} | {s} difference" for s in scenes)
    print(f"| cell | {head} |")
    print("|---|" + "---|" * (3 * len(scenes)))
    for c in cells:
        parts = []
        for s in scenes:
            x, y = a.get((c, s), []), b.get((c, s), [])
            pval = welch_p(x, y)
            diff = f"{np.mean(y) - np.mean(x):+.2f}" if x and y else "-"
            mark = "" if math.isnan(pval) else (" (p < 0.05)" if pval < 0.05 else " (tie)")
            parts.append(f"{fmt(x)} | {fmt(y)} | {diff}{mark}")
        print(f"| {c} | " + " | ".join(parts) + " |")
    if args.reference is not None:
        ref = by_cell([r for r in read_rows(args.reference) if "events" not in r.get("inputs", [])], args.metric)
        for c in sorted({c for c, _ in ref}):
            vals = " | ".join(f"{fmt(ref.get((c, s), []))} | {fmt(ref.get((c, s), []))} | 0" for s in scenes)
            print(f"| {c} (sees no events: {args.reference.name}'s rows) | {vals} |")
    return 0


if __name__ == "__main__":
    from tools.tool_cli import run_tool

    sys.exit(run_tool(main))
