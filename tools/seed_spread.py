"""The seed spread of a results file: every main cell trained at several seeds (`e4dgs bench --seeds N`),
per scene the scores at each seed, their mean and sample standard deviation, and per cell the pooled
standard deviation over the scenes, the figure a preset's `seed_spread:` holds for its one-seed cells.

    python -m tools.seed_spread runs/quick/results.jsonl [--yaml]

`--yaml` prints the pooled figures as a preset's `seed_spread:` block.
"""
from __future__ import annotations

import argparse
import sys
from collections import defaultdict

from tools.tool_cli import existing_file, run_tool

METRICS = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn")


def spread_table(rows: list[dict]) -> tuple[str, dict[str, dict[str, float]]]:
    """(markdown table, cell -> {metric: pooled sd}) of the main study's cells with several seeds."""
    from benchmark.report import main_table
    from benchmark.ties import pooled_spread

    scenes, table = main_table([r for r in rows if r.get("study") == "main" and r.get("status") != "failed"])
    per_seed: dict[tuple[str, str], dict[int, float]] = defaultdict(dict)
    for r in rows:
        if r.get("study") == "main" and r.get("status") != "failed":
            per_seed[(r["cell"], r["scene"])][r.get("seed") or 0] = r["psnr"]
    pooled = pooled_spread(table)
    lines = ["| Cell | Scene | Seeds | PSNR per seed | PSNR mean ± sd | SSIM sd | LPIPS sd |", "|---|---|---|---|---|---|---|"]
    for cell in table:
        for scene in scenes:
            r = table[cell].get(scene)
            if not r or r.get("n_seeds", 1) < 2:
                continue
            sp = r["spread"]
            seeds = per_seed[(cell, scene)]
            lines.append(f"| {r.get('label') or cell} | {scene} | {r['n_seeds']} | "
                         + " / ".join(f"{seeds[k]:.2f}" for k in sorted(seeds))
                         + f" | {r['psnr']:.2f} ± {sp['psnr']:.2f} | {sp.get('ssim', float('nan')):.4f} | "
                         + (f"{sp['lpips']:.4f}" if "lpips" in sp else "–") + " |")
        if cell in pooled:
            p = pooled[cell]
            lines.append(f"| {cell}: pooled | | | | sd {p['psnr']:.2f} dB | {p.get('ssim', float('nan')):.4f} | "
                         + (f"{p['lpips']:.4f}" if "lpips" in p else "–") + " |")
    return "\n".join(lines) + "\n", {c: {k: v for k, v in p.items() if k in METRICS} for c, p in pooled.items()}


def main(argv: list[str] | None = None) -> int:
    from benchmark.rows import read_results

    ap = argparse.ArgumentParser(prog="python -m tools.seed_spread", description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=existing_file, help="a results.jsonl")
    ap.add_argument("--yaml", action="store_true", help="print the pooled spread as a preset's seed_spread: block")
    args = ap.parse_args(argv)
    text, pooled = spread_table(read_results(args.results))
    if not pooled:
        raise SystemExit(f"{args.results}: no main cell has rows at two seeds or more (`e4dgs bench --seeds 3`)")
    print(text)
    if args.yaml:
        print("seed_spread:")
        for cell, p in pooled.items():
            print(f"  {cell}: {{" + ", ".join(f"{k}: {round(v, 4 if k in ('ssim', 'lpips') else 2)}"
                                              for k, v in sorted(p.items())) + "}")
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
