"""Benchmarks and the leaderboard harness."""
