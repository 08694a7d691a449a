"""Ties: differences within the seed spread are not ranked (benchmark.ties)."""
import math

import numpy as np
import pytest

from benchmark.ties import average_error, combine_seeds, differ, mean_sd, pooled_spread, rank_with_ties, standard_error


def test_a_best_further_than_two_standard_errors_is_bold_else_a_tie():
    # se 0.1 each: the difference's se is 0.1414, the margin 0.283
    assert rank_with_ties({"a": (30.0, 0.1), "b": (29.6, 0.1), "c": (28.0, 0.1)}, higher=True) == \
        {"a": "best", "b": "second", "c": ""}
    assert rank_with_ties({"a": (30.0, 0.1), "b": (29.8, 0.1), "c": (28.0, 0.1)}, higher=True) == \
        {"a": "best=", "b": "best=", "c": "second"}
    assert rank_with_ties({"a": (0.20, 0.01), "b": (0.25, 0.01), "c": None}, higher=False) == \
        {"a": "best", "b": "second", "c": ""}
    # unknown spreads: a plain ordering
    assert rank_with_ties({"a": (30.0, None), "b": (29.99, None)}, higher=True) == {"a": "best", "b": "second"}
    assert differ((1.0, 0.0), (1.0 + 1e-9, 0.0)) and not differ((1.0, 0.1), (1.2, 0.1))


def test_seeds_combine_into_mean_and_sample_sd_and_pool_per_cell():
    rows = [{"seed": s, "psnr": p, "ssim": 0.5, "wall_s": 10.0} for s, p in ((None, 30.0), (1, 31.0), (2, 32.0))]
    c = combine_seeds(rows)
    assert c["psnr"] == 31.0 and c["spread"]["psnr"] == pytest.approx(1.0) and c["n_seeds"] == 3 and c["seeds"] == [0, 1, 2]
    assert standard_error(c, "psnr", None) == pytest.approx(1 / math.sqrt(3))
    one = combine_seeds(rows[:1])
    assert one["spread"] == {} and standard_error(one, "psnr", {"psnr": 0.4}) == 0.4 and standard_error(one, "psnr", None) is None
    other = combine_seeds([{"seed": None, "psnr": 20.0}, {"seed": 1, "psnr": 22.0}])     # sd sqrt(2)
    pooled = pooled_spread({"m": {"x": c, "y": other, "z": one}})
    assert pooled["m"]["psnr"] == pytest.approx(math.sqrt((1.0 + 2.0) / 2))
    assert average_error([0.3, 0.4]) == pytest.approx(0.25) and average_error([0.3, None]) is None
    assert mean_sd([2.0]) == (2.0, 0.0)


def test_welch_t_at_three_seeds_needs_the_t_quantile_not_two_standard_errors():
    from benchmark.ties import critical_t, welch_df

    # se 0.1 each, 2 degrees of freedom each (3 seeds): Welch df 4, t(0.975, 4) = 2.776
    assert welch_df([0.1, 0.1], [2.0, 2.0]) == pytest.approx(4.0)
    assert critical_t(4.0) == pytest.approx(2.7764, abs=1e-4) and critical_t(math.inf) == pytest.approx(1.95996, abs=1e-5)
    margin = 2.7764 * math.sqrt(0.02)                                    # 0.3926
    assert not differ((30.0, 0.1, 2.0), (30.0 - 0.35, 0.1, 2.0))          # the old 2-SE rule called this (0.283)
    assert differ((30.0, 0.1, 2.0), (30.0 - margin - 1e-3, 0.1, 2.0))
    assert welch_df([0.1, 0.2], [2.0, math.inf]) == pytest.approx(0.05 ** 2 / (0.1 ** 4 / 2))


def test_groups_are_cut_only_where_every_value_above_differs_from_every_value_below():
    # a ~ b and b ~ c but a differs from c: one group, no underlined c "within the margin" of a bold b
    vals = {"a": (30.0, 0.1), "b": (29.75, 0.1), "c": (29.5, 0.1), "d": (27.0, 0.1)}
    assert differ(vals["a"], vals["c"]) and not differ(vals["a"], vals["b"]) and not differ(vals["b"], vals["c"])
    assert rank_with_ties(vals, higher=True) == {"a": "best=", "b": "best=", "c": "best=", "d": "second"}


def test_random_columns_never_contradict_their_marks():
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(2, 7))
        vals = {f"c{i}": (float(rng.normal(0, 1)), float(rng.uniform(0.05, 0.6)), float(rng.integers(1, 5)))
                for i in range(n)}
        ranks = rank_with_ties(vals, higher=bool(rng.integers(0, 2)))
        best = [c for c, r in ranks.items() if r.startswith("best")]
        second = [c for c, r in ranks.items() if r.startswith("second")]
        rest = [c for c in vals if c not in best]
        assert best and all(differ(vals[a], vals[b]) for a in best for b in rest)
        below = [c for c in rest if c not in second]
        assert all(differ(vals[a], vals[b]) for a in second for b in below)


def test_the_false_call_rate_of_equal_cells_is_about_alpha():
    from tools.tie_rule import false_calls

    old, new = false_calls(n_seeds=3, n_cells=2, trials=6000, seed=1)
    assert 0.02 < new < 0.06 and old > 0.09          # Welch at 0.05 (measured 3.4 %) against the 2-SE rule (11 %)
