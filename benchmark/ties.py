"""Seeds and ties: a cell's scores over its training seeds, the spread a cell with one seed is taken
to have, and the ranking of a table column that calls differences within the spread ties.

A benchmark cell trained at seeds 0..N-1 (`e4dgs bench --seeds N`) is shown as the mean and the
sample standard deviation over its seeds; its standard error is sd / sqrt(N). A cell with one seed
takes the spread of its kind: the pooled standard deviation of the same cell over the scenes where
the results hold two seeds or more, else the preset's measured `seed_spread`. Two cells of a column
differ when their means are further apart than twice the standard error of the difference,
2 sqrt(se_a^2 + se_b^2) (about 95 % for normal spreads); otherwise they tie.
"""
from __future__ import annotations

import math

# columns averaged over seeds (the first row's other fields stand for the cell)
AVERAGED = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn", "psnr_luma_dyn", "ssim_dyn", "lpips_dyn",
            "dyn_fraction", "floor_psnr", "floor_psnr_luma", "floor_psnr_dyn", "wall_s", "n_gaussians")
SPREAD_KEYS = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn", "ssim_dyn", "lpips_dyn")
Z = 2.0        # differences beyond Z standard errors of the difference are called differences


def mean_sd(values: list[float]) -> tuple[float, float]:
    """(mean, sample standard deviation; 0 for one value)."""
    m = sum(values) / len(values)
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else 0.0
    return m, sd


def combine_seeds(rows: list[dict]) -> dict:
    """One cell on one scene from its rows at several seeds: the lowest seed's row with the AVERAGED
    columns replaced by their means, `seeds` (the seeds, 0 for the default), `n_seeds`, `spread`
    ({metric: sample sd}, with two seeds or more) and `older` (the first row's note, if one is kept
    from another version)."""
    rows = sorted(rows, key=lambda r: r.get("seed") or 0)
    out = dict(rows[0])
    spread = {}
    for k in AVERAGED:
        vals = [r.get(k) for r in rows]
        if vals and all(isinstance(v, (int, float)) for v in vals):
            out[k], sd = mean_sd([float(v) for v in vals])
            if k in SPREAD_KEYS and len(vals) > 1:
                spread[k] = sd
    out.update(seeds=[r.get("seed") or 0 for r in rows], n_seeds=len(rows), spread=spread,
               older=next((r["older"] for r in rows if r.get("older")), None))
    return out


def pooled_spread(table: dict[str, dict[str, dict]]) -> dict[str, dict[str, float]]:
    """cell -> {metric: pooled sd} over the scenes where the cell has two seeds or more (root of the
    mean variance); cells with one seed everywhere are left out."""
    out: dict[str, dict[str, float]] = {}
    for cell, per_scene in table.items():
        with_seeds = [r["spread"] for r in per_scene.values() if r.get("n_seeds", 1) > 1]
        keys = {k for s in with_seeds for k in s}
        out_cell = {k: math.sqrt(sum(s[k] ** 2 for s in with_seeds if k in s) / sum(k in s for s in with_seeds))
                    for k in keys}
        if out_cell:
            out[cell] = out_cell
    return out


def standard_error(row: dict, key: str, kind_spread: dict[str, float] | None) -> float | None:
    """The standard error of a combined row's `key`: its own seeds' sd / sqrt(n), or with one seed the
    spread of its kind (None: unknown)."""
    n = row.get("n_seeds", 1)
    if n > 1 and key in (row.get("spread") or {}):
        return row["spread"][key] / math.sqrt(n)
    return (kind_spread or {}).get(key)


def average_error(errors: list[float | None]) -> float | None:
    """Standard error of a mean over scenes of independent values with these errors."""
    if not errors or any(e is None for e in errors):
        return None
    return math.sqrt(sum(e * e for e in errors)) / len(errors)


def differ(a: tuple[float, float | None], b: tuple[float, float | None]) -> bool:
    """Whether two (mean, standard error) values differ: further apart than Z standard errors of the
    difference (an unknown error counts as 0: plain ranking)."""
    se = math.sqrt((a[1] or 0.0) ** 2 + (b[1] or 0.0) ** 2)
    return abs(a[0] - b[0]) > Z * se


def rank_with_ties(values: dict[str, tuple[float, float | None] | None], higher: bool) -> dict[str, str]:
    """cell -> "best", "best=" (tied for best), "second", "second=" or "" for one column of
    (mean, standard error) values (None: no value). The best group is every cell that does not differ
    from the top one; the second group likewise among the rest."""
    valid = [(v, c) for c, v in values.items() if v is not None]
    order = [c for v, c in sorted(valid, key=lambda vc: vc[0][0], reverse=higher)]
    out = {c: "" for c in values}
    for rank in ("best", "second"):
        if not order:
            break
        top = values[order[0]]
        group = [c for c in order if c == order[0] or not differ(top, values[c])]
        for c in group:
            out[c] = rank if len(group) == 1 else rank + "="
        order = [c for c in order if c not in group]
    return out
