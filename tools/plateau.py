"""How far from flat each leaderboard cell stops: from a results file's main-study curves (every cell
is scored on every test view at 10, 25, 50 and 100 % of its steps), per scene and cell the PSNR at
half the steps, at the end, and the gain over the second half (mean over seeds), with each
cell's training seconds.

    python -m tools.plateau runs/quick/results.jsonl

A gain near zero (within the seed spread) says the curve is flat at the budget; a large one says the
cell is still learning and the table ranks how fast it starts. Where the curve goes later (10x the
steps) is measured apart (docs/results/learning_curves.md).
"""
from __future__ import annotations

import argparse
import sys
from collections import defaultdict

from tools.tool_cli import existing_file, run_tool


def half_and_end(row: dict) -> tuple[float, float] | None:
    """(PSNR at the snapshot nearest half the steps, PSNR at the end) of one row; None without curves."""
    snaps = [s for s in row.get("snapshots") or [] if "iteration" in s and "psnr" in s]
    n = row.get("iterations")
    if len(snaps) < 2 or not n:
        return None
    half = min(snaps[:-1], key=lambda s: abs(s["iteration"] - n / 2))
    return half["psnr"], snaps[-1]["psnr"]


def plateau_table(rows: list[dict]) -> str:
    """Markdown: scene, cell, seeds, steps, seconds, PSNR at half the steps, at the end, second-half gain."""
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in rows:
        if r.get("study") == "main" and r.get("status") != "failed" and half_and_end(r):
            groups[(r["scene"], r["cell"])].append(r)
    lines = ["| scene | cell | seeds | steps | train s | PSNR at half the steps | PSNR at the end | second-half gain (dB) |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    mean = lambda v: sum(v) / len(v)  # noqa: E731
    for (scene, cell), rs in sorted(groups.items()):
        pairs = [half_and_end(r) for r in rs]
        h, e = mean([p[0] for p in pairs]), mean([p[1] for p in pairs])
        secs = mean([r.get("train_elapsed_s") or 0.0 for r in rs])
        lines.append(f"| {scene} | {rs[0].get('label') or cell} | {len(rs)} | {rs[0]['iterations']:,} | {secs:.0f} | "
                     f"{h:.2f} | {e:.2f} | {e - h:+.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from benchmark.rows import read_results

    ap = argparse.ArgumentParser(prog="python -m tools.plateau", description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=existing_file, help="a results.jsonl")
    args = ap.parse_args(argv)
    text = plateau_table(read_results(args.results))
    if text.count("\n") <= 2:
        raise SystemExit(f"{args.results}: no main-study row has its learning curve (snapshots)")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
