"""Seeds and ties: a cell's scores over its training seeds, the spread a cell with one seed is taken
to have, and the ranking of a table column that calls differences within the spread ties.

A benchmark cell trained at seeds 0..N-1 (`e4dgs bench --seeds N`) is shown as the mean and the
sample standard deviation over its seeds; its standard error is sd / sqrt(N). A cell with one seed
takes the spread of its kind: the pooled standard deviation of the same cell over the scenes where
the results hold two seeds or more, else the preset's measured `seed_spread`.

Two cells of a column differ when Welch's t-test rejects equal means at ALPHA = 0.05 (two-sided):
|m_a - m_b| > t(1 - ALPHA/2, df) sqrt(se_a^2 + se_b^2), with the Welch-Satterthwaite degrees of
freedom df = (se_a^2 + se_b^2)^2 / (se_a^4 / df_a + se_b^4 / df_b), df = seeds - 1 for a cell's own
spread (a borrowed spread, measured over many seeds, counts as known: df infinite). Two cells with
equal true means are then called different 5 % of the time at any seed count (the old rule, twice
the standard error of the difference, did so 11.5-18 % of the time at 3 seeds: the t quantile at 4
degrees of freedom is 2.78, not 2).

Groups cannot contradict themselves: the column is sorted, and it is cut between two neighbours
only where every cell above the cut differs from every cell below it (in the current group). The
first group is bold, the second underlined; a group of several is a tie (≈). So a bold value is
significantly better than every value that is not bold, and an underlined one than every value
below it.
"""
from __future__ import annotations

import math

# columns averaged over seeds (the first row's other fields stand for the cell)
AVERAGED = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn", "psnr_luma_dyn", "ssim_dyn", "lpips_dyn",
            "dyn_fraction", "floor_psnr", "floor_psnr_luma", "floor_psnr_dyn", "wall_s", "n_gaussians")
SPREAD_KEYS = ("psnr", "ssim", "lpips", "psnr_luma", "psnr_dyn", "ssim_dyn", "lpips_dyn")
ALPHA = 0.05   # two-sided false-call rate of one comparison of two cells with equal true means


def mean_sd(values: list[float]) -> tuple[float, float]:
    """(mean, sample standard deviation; 0 for one value)."""
    m = sum(values) / len(values)
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else 0.0
    return m, sd


def combine_seeds(rows: list[dict]) -> dict:
    """One cell on one scene from its rows at several seeds: the lowest seed's row with the AVERAGED
    columns replaced by their means, `seeds` (the seeds, 0 for the default), `n_seeds`, `seed_axes`
    (what the seeds varied, benchmark.config.SEED_AXES, read from the rows' overrides), `spread`
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
    from benchmark.config import SEED_AXES

    axes = [a for a, f in SEED_AXES.items() if f and any(f in (r.get("overrides") or {}) for r in rows)]
    if any("@noise" in str(r.get("dataset") or "") for r in rows):
        axes.append("noise")
    out.update(seeds=[r.get("seed") or 0 for r in rows], n_seeds=len(rows), spread=spread, seed_axes=axes,
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


def degrees_of_freedom(row: dict, key: str) -> float:
    """The degrees of freedom of standard_error(row, key): seeds - 1 for its own spread, infinite for
    a borrowed one (a measured kind spread)."""
    n = row.get("n_seeds", 1)
    return float(n - 1) if n > 1 and key in (row.get("spread") or {}) else math.inf


def average_error(errors: list[float | None]) -> float | None:
    """Standard error of a mean over scenes of independent values with these errors."""
    if not errors or any(e is None for e in errors):
        return None
    return math.sqrt(sum(e * e for e in errors)) / len(errors)


def welch_df(errors: list[float], dfs: list[float]) -> float:
    """Welch-Satterthwaite degrees of freedom of a sum of independent terms with these standard errors
    and degrees of freedom (infinite terms add none to the denominator)."""
    num = sum(e * e for e in errors) ** 2
    den = sum(e ** 4 / d for e, d in zip(errors, dfs) if math.isfinite(d) and d > 0)
    return num / den if den > 0 else math.inf


def critical_t(df: float, alpha: float = ALPHA) -> float:
    """The two-sided critical value of Student's t at `df` degrees of freedom (normal for infinite)."""
    from scipy import stats

    return float(stats.norm.ppf(1 - alpha / 2) if not math.isfinite(df) else stats.t.ppf(1 - alpha / 2, df))


Value = tuple  # (mean, standard error or None, degrees of freedom (default infinite))


def differ(a: Value, b: Value, alpha: float = ALPHA) -> bool:
    """Whether two (mean, standard error[, degrees of freedom]) values differ by Welch's t-test at
    `alpha` (an unknown or zero error on both: plain ranking, any difference counts)."""
    se_a, se_b = a[1] or 0.0, b[1] or 0.0
    se = math.sqrt(se_a ** 2 + se_b ** 2)
    if se == 0.0:
        return a[0] != b[0]
    df = welch_df([se_a, se_b], [a[2] if len(a) > 2 else math.inf, b[2] if len(b) > 2 else math.inf])
    return abs(a[0] - b[0]) > critical_t(df, alpha) * se


def rank_with_ties(values: dict[str, Value | None], higher: bool, alpha: float = ALPHA) -> dict[str, str]:
    """cell -> "best", "best=" (a tie for best), "second", "second=" or "" for one column of (mean,
    standard error[, df]) values (None: no value). Sorted, the column is cut before a cell only where
    every cell of the current group above differs from every cell from there down (module note): the
    first group is best, the second second."""
    valid = [(v, c) for c, v in values.items() if v is not None]
    order = [c for v, c in sorted(valid, key=lambda vc: vc[0][0], reverse=higher)]
    out = {c: "" for c in values}
    groups: list[list[str]] = []
    current: list[str] = []
    for i, c in enumerate(order):
        if current and all(differ(values[a], values[b], alpha) for a in current for b in order[i:]):
            groups.append(current)
            current = []
        current.append(c)
    if current:
        groups.append(current)
    for rank, group in zip(("best", "second"), groups):
        for c in group:
            out[c] = rank if len(group) == 1 else rank + "="
    return out
