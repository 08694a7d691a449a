"""Benchmarks and the leaderboard harness."""
import common  # noqa: F401  (first: it sets the OpenMP wait policy before torch or numba loads)
