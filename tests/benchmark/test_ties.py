"""Ties: differences within the seed spread are not ranked (benchmark.ties)."""
import math

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
