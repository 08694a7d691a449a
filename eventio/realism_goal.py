"""The calibration goal of a named sensor preset: closer to its real clip than every v2e preset on the
realism report's two distances, the still-pixel noise rate and the refractory floor, on held-out data.

Pure functions on the figure dicts `tools.aps_check` and `tools.noise_check` write (one dict per sensor
config, the held-out half), used by both to print the verdict and by the tests that guard the presets.
"""
from __future__ import annotations

import math

V2E_PRESETS = ("v2e defaults", "v2e clean", "v2e noisy")
# how a figure is compared with the camera's: as a distance already, or by the log10 of its ratio
DISTANCE, LOG_RATIO = "distance", "log ratio"


def goal_figures(noise_key: str) -> dict[str, tuple[str, str]]:
    """The goal's four figures as (key in a check's figures, how compared): the checks name their
    still-pixel noise rate differently (`noise_key`); the rest is shared."""
    return {"W1 log rate": ("w1_log_rate", DISTANCE), "W1 log interval": ("w1_log_iei", DISTANCE),
            "still-pixel noise": (noise_key, LOG_RATIO), "interval floor p0.1": ("iei_p0_1_us", LOG_RATIO)}


def figure_distance(value: float, real: float | None, kind: str) -> float:
    """How far one figure is from the camera's: a distance as it is; a rate or floor as |log10(sim / real)|
    (0 or NaN: infinitely far, a sensor that makes no noise is not close to one that does)."""
    if value is None or not math.isfinite(value):
        return math.inf
    if kind == DISTANCE:
        return float(value)
    if value <= 0 or real is None or not math.isfinite(real) or real <= 0:
        return math.inf
    return abs(math.log10(value / real))


def goal(configs: dict[str, dict], real: dict, preset: str, keys: dict[str, tuple[str, str]],
         peers: tuple[str, ...] = V2E_PRESETS) -> dict:
    """{figure: {"preset": its distance, "best_peer": a name, "best_peer_distance", "met": bool}} and
    "met" overall.

    configs: {name: figures on the held-out half}; real: the camera's figures there; keys: {figure label:
    (key in the figures, DISTANCE or LOG_RATIO)}. A figure is met when the preset is strictly closer than
    every peer present in `configs`."""
    if preset not in configs:
        raise KeyError(f"no figures for the preset {preset!r} (have {', '.join(configs)})")
    out: dict = {}
    for label, (key, kind) in keys.items():
        mine = figure_distance(configs[preset].get(key), real.get(key), kind)
        theirs = {p: figure_distance(configs[p].get(key), real.get(key), kind) for p in peers if p in configs}
        best = min(theirs.items(), key=lambda kv: kv[1]) if theirs else ("none", math.inf)
        out[label] = {"preset": mine, "best_peer": best[0], "best_peer_distance": best[1], "met": mine < best[1]}
    out["met"] = all(v["met"] for v in out.values())
    return out


def goal_lines(verdict: dict, preset: str) -> list[str]:
    """The verdict as printed lines: one per figure, then the summary."""
    lines = []
    for label, v in verdict.items():
        if label == "met":
            continue
        lines.append(f"  {label}: {preset} {v['preset']:.3f}, best v2e preset ({v['best_peer']}) "
                     f"{v['best_peer_distance']:.3f}: {'met' if v['met'] else 'NOT met'}")
    head = f"goal ({preset} closer to the camera than every v2e preset on all four, held out): " + \
        ("met" if verdict["met"] else "NOT met")
    return [head, *lines]
