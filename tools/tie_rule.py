"""How often a table's tie rule calls a difference that is not there: cells with equal true means
and normal seed noise, scored by the old rule (twice the standard error of the difference) and by
the tables' rule (benchmark.ties: Welch's t-test at 0.05 with separable groups), at several seed
counts. Prints a table: per pair (two cells), and per column of six cells (any cell put outside
the best group).

    python -m tools.tie_rule --seeds 3 5 --trials 20000
"""
from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from benchmark.ties import rank_with_ties


def old_differ(a, b) -> bool:
    return abs(a[0] - b[0]) > 2.0 * math.sqrt(a[1] ** 2 + b[1] ** 2)


def old_ranks(values: dict, higher: bool = True) -> dict[str, str]:
    """The rule the tables used before: groups of cells within 2 SE of the difference of each group's top."""
    order = [c for c in sorted(values, key=lambda c: values[c][0], reverse=higher)]
    out = {c: "" for c in values}
    for rank in ("best", "second"):
        if not order:
            break
        group = [c for c in order if c == order[0] or not old_differ(values[order[0]], values[c])]
        for c in group:
            out[c] = rank if len(group) == 1 else rank + "="
        order = [c for c in order if c not in group]
    return out


def _declared(ranks: dict[str, str]) -> bool:
    return any(not r.startswith("best") for r in ranks.values())


def false_calls(n_seeds: int, n_cells: int, trials: int, seed: int = 0) -> tuple[float, float]:
    """(old rule, tables' rule): the fraction of trials in which the column declares a difference (a
    cell outside the best group) though every cell has the same true mean (sd 1 over seeds)."""
    rng = np.random.default_rng(seed)
    draws = rng.normal(size=(trials, n_cells, n_seeds))
    means, sds = draws.mean(-1), draws.std(-1, ddof=1)
    old = new = 0
    for m, s in zip(means, sds):
        values = {f"c{i}": (float(m[i]), float(s[i] / math.sqrt(n_seeds)), float(n_seeds - 1)) for i in range(n_cells)}
        old += _declared(old_ranks(values))
        new += _declared(rank_with_ties(values, True))
    return old / trials, new / trials


def main(argv: list[str] | None = None) -> int:
    from tools.tool_cli import int_in

    p = argparse.ArgumentParser(prog="python -m tools.tie_rule", description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int_in(2, 100, "seeds per cell"), nargs="+", default=[3, 5],
                   help="seed counts to simulate (default 3 5)")
    p.add_argument("--trials", type=int_in(1, 10_000_000, "simulated columns"), default=20000,
                   help="simulated columns per setting (default 20000)")
    args = p.parse_args(argv)
    print("| seeds | cells | old rule (2 SE): false calls | Welch t at 0.05, separable groups: false calls |")
    print("|---|---|---|---|")
    for n in args.seeds:
        for cells in (2, 6):
            old, new = false_calls(n, cells, args.trials)
            print(f"| {n} | {cells} | {old:.1%} | {new:.1%} |")
    return 0


if __name__ == "__main__":
    from tools.tool_cli import run_tool

    sys.exit(run_tool(main))
