"""The static-background check: a sensor's noise (leak, shot noise, hot pixels), its refractory floor and
its readout's timestamp steps, fitted on the still pixels of a real recording's first half and
reported on its second half (held out), for a camera without frames to feed the simulator (the
`imx636` and `dvxplorer` presets).

    python -m tools.noise_check --clip imx636.raw [--fit] [--intensity 0.5] [--json OUT]

Still pixels: pixels none of whose events, over the whole recording, has an event at a neighbour
(3x3) within 5 ms before it (eventio.realism.isolated_events): a moving edge fires neighbours
together, noise does not. Every event there is noise. On a half, per still pixel: its events (rate
in Hz), their ON fraction, the same-pixel intervals, hot pixels (eventio.realism's rule).

Fit (first half): hot pixels are the still pixels the realism rule calls hot (fraction, and their
median rate); the rest's noise, mean rate r per pixel with ON fraction f, is leak (ON only, regular)
for its ON excess, leak = max(0, 2f - 1) r', and shot noise (Poisson) for the rest, with ON share
min(f, 1/2); its light dependence is not measured (a still clip has one light level: white factor 1);
the per-pixel spread of the noise rate (decades, leak and shot noise alike) from the counts' excess
variance over Poisson, var = m + m^2 (exp((s ln 10)^2) - 1), which sets the rates' median
r' = r / exp((s ln 10)^2 / 2) (the configured rates; their mean is r); the refractory period is the p0.1 of the
same-pixel intervals of every non-hot pixel (moving edges reach it), or the still pixels' own p0.1 where that is
shorter (a refractory period bounds every pixel's intervals, so none it allows can be shorter than it); the readout period, the most
common step between distinct timestamps when more than half of the timestamps share it (a
semi-synchronous readout; else none). The noise that is not leak is split between shot noise
(Poisson) and diffusion noise (a random walk on the input whose threshold crossings are events: a
renewal process, more regular than Poisson) by the one figure that tells them apart, the regularity:
a still scene of the first half's duration is simulated with 0, 1/4, ... 1 of it as diffusion noise,
and the share whose regularity is the camera's is interpolated between them (0 when the camera is
no more regular than Poisson: bursts are not modelled).

Report (second half): a still scene (one grey level, `--intensity`, linear) simulated for the
half's duration at the clip's resolution by each sensor, against the camera's still pixels:
the noise rate, its ON fraction, hot-pixel fraction, the interval floor, consecutive same polarity
(of each non-hot still pixel's consecutive events), the regularity (the median
interval of pixels with two events against two events placed at random: 1 for Poisson noise) and the
Wasserstein-1 distances of log10 per-pixel rate (pixels with an event) and log10 interval. Thresholds are not
measured here (no frames: a still scene's noise does not depend on them but through shot noise's
threshold scaling).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from eventio.realism_goal import goal, goal_figures, goal_lines

# the goal's four figures in this check's figures (eventio.realism_goal): the camera's still pixels
GOAL = goal_figures("rate_hz")
FRAME_RATE_HZ = 200.0           # the still scene's frames (only noise and leak happen between them)


def still_pixels(stream) -> np.ndarray:
    """bool [H, W]: pixels whose every event is isolated (module note); pixels with no event included."""
    from eventio.realism import isolated_events

    e = stream.events
    iso = isolated_events(stream)
    pix = e["y"].astype(np.int64) * stream.width + e["x"].astype(np.int64)
    moving = np.zeros(stream.width * stream.height, bool)
    moving[pix[~iso]] = True
    return ~moving.reshape(stream.height, stream.width)


def window(stream, t0: int, t1: int):
    from eventio.events import EventStream

    e = stream.events
    return EventStream(e[(e["t"] >= t0) & (e["t"] < t1)], stream.width, stream.height)


def noise_figures(stream, mask: np.ndarray, duration_s: float) -> dict:
    """Noise statistics of the events on `mask`'s pixels over `duration_s` (module note)."""
    from eventio.realism import HOT_FACTOR, HOT_MIN_EVENTS

    e = stream.events
    inside = mask[e["y"].astype(np.int64), e["x"].astype(np.int64)]
    e = e[inside]
    W = stream.width
    pix = e["y"].astype(np.int64) * W + e["x"].astype(np.int64)
    per_pixel = np.bincount(pix, minlength=mask.size)
    counts = per_pixel[mask.reshape(-1)]
    active = counts[counts > 0]
    rates = active / duration_s
    p99 = float(np.percentile(rates, 99)) if len(rates) else 0.0
    hot_sel = (counts >= HOT_MIN_EVENTS) & (counts / duration_s > HOT_FACTOR * p99)
    order = np.lexsort((e["t"], pix))
    ps, ts = pix[order], e["t"][order].astype(np.int64)
    same = ps[1:] == ps[:-1]
    hot_pix = np.flatnonzero(mask.reshape(-1))[hot_sel]
    not_hot = ~np.isin(ps[1:], hot_pix)
    iei = np.diff(ts)[same]
    iei_cold = np.diff(ts)[same & not_hot]
    cold_counts = counts[~hot_sel]
    m = cold_counts.mean() if len(cold_counts) else 0.0
    excess = cold_counts.var() - m if len(cold_counts) else 0.0
    spread = math.sqrt(math.log1p(excess / m ** 2)) / math.log(10) if m > 0 and excess > 0 else 0.0
    cold_events = e[~np.isin(pix, hot_pix)]
    n_of = per_pixel[ps[1:]]                          # the events of each interval's pixel
    two = np.diff(ts)[same & (n_of == 2)]            # the interval of each pixel with exactly two events
    pol = e["p"][order]
    kept = same & not_hot
    same_pol = float(np.mean(pol[1:][kept] == pol[:-1][kept])) if kept.any() else float("nan")
    return {"pixels": int(mask.sum()), "events": int(len(e)), "rate_hz": len(e) / mask.sum() / duration_s,
            "regularity": two_event_regularity(two, duration_s), "same_polarity": same_pol,
            "cold_rate_hz": len(cold_events) / max(len(cold_counts), 1) / duration_s,
            "cold_on_fraction": float(np.mean(cold_events["p"] > 0)) if len(cold_events) else float("nan"),
            "on_fraction": float(np.mean(e["p"] > 0)) if len(e) else float("nan"),
            "hot_fraction": float(hot_sel.sum()) / mask.sum(), "hot_rate_hz": float(np.median(counts[hot_sel]) / duration_s)
            if hot_sel.any() else 0.0, "rate_spread_decades": spread,
            "iei_p0_1_us": float(np.percentile(iei_cold, 0.1)) if len(iei_cold) else float("nan"),
            "iei_p1_us": float(np.percentile(iei, 1)) if len(iei) else float("nan"),
            "log_rates": np.log10(rates), "log_iei": np.log10(np.maximum(iei, 1)).astype(float)}


def two_event_regularity(intervals_us: np.ndarray, duration_s: float) -> float:
    """The median interval of the pixels with exactly two events in a window of duration_s, over the
    median for two events placed at random in it, (1 - 1/sqrt(2)) duration (a Poisson process given
    its count): 1 for Poisson noise, above 1 for noise more regular than Poisson (a leak), below for
    bursts; nan with fewer than 20 such pixels."""
    if len(intervals_us) < 20:
        return float("nan")
    return float(np.median(intervals_us) / 1e6 / ((1 - 1 / math.sqrt(2)) * duration_s))


def readout_period_us(stream, max_period_us: float = 1000.0) -> int:
    """A semi-synchronous readout's period: among P from 20 us to max_period_us (0.1 us steps), the
    largest of those of which the same-pixel intervals under 2.5 ms are closest to whole multiples
    (the mean resultant length of their phases iei / P mod 1 within 0.005 of the best; a divisor P / k
    fits as well, so the largest); 0 when the best is under 0.9 (an asynchronous readout)."""
    from eventio.realism import inter_event_intervals

    iei, _ = inter_event_intervals(stream)
    iei = iei[(iei > 0) & (iei < 2500)].astype(np.float64)
    if len(iei) < 100:
        return 0
    iei = np.random.default_rng(0).choice(iei, size=min(len(iei), 5000), replace=False)
    periods = np.arange(20.0, max_period_us, 0.1)
    fit = np.array([abs(np.mean(np.exp(2j * np.pi * iei / period))) for period in periods])
    if fit.max() < 0.9:
        return 0
    return int(round(periods[np.flatnonzero(fit >= fit.max() - 0.005)[-1]]))


def refractory_floor_us(stream, hot_pixels: np.ndarray) -> int:
    """p0.1 of the same-pixel intervals of every pixel but the hot ones (moving edges included: they
    are what reaches the refractory period)."""
    from eventio.realism import pixel_order

    pix, order = pixel_order(stream)
    p, t = pix[order], stream.events["t"][order].astype(np.int64)
    keep = (p[1:] == p[:-1]) & ~np.isin(p[1:], hot_pixels)
    iei = np.diff(t)[keep]
    return int(round(float(np.percentile(iei, 0.1)))) if len(iei) else 0


def refractory_us(all_pixels_p0_1_us: float, still_pixels_p0_1_us: float) -> int:
    """The refractory period from the interval floors (p0.1) of every non-hot pixel and of the still
    ones: the first, unless the still pixels show shorter intervals (the period bounds them all)."""
    floors = [v for v in (all_pixels_p0_1_us, still_pixels_p0_1_us) if math.isfinite(v) and v > 0]
    return int(round(min(floors))) if floors else 0


def fit(real_half, mask, duration_s: float, clip_stream) -> dict:
    """A preset's noise, refractory and readout values from the first half (module note)."""
    from eventio.realism import HOT_FACTOR, HOT_MIN_EVENTS

    f = noise_figures(real_half, mask, duration_s)
    on, r = f["cold_on_fraction"], f["cold_rate_hz"]
    on = on if math.isfinite(on) else 0.5
    spread = f["rate_spread_decades"]
    median = r / math.exp((spread * math.log(10)) ** 2 / 2)   # the log-normal's median, whose mean is r
    leak = max(0.0, 2 * on - 1) * median                       # ON beyond half: leak (ON only, regular)
    shot = median - leak
    e = real_half.events
    counts = np.bincount(e["y"].astype(np.int64) * real_half.width + e["x"].astype(np.int64),
                         minlength=mask.size) * mask.reshape(-1)
    active = counts[counts > 0] / duration_s
    p99 = float(np.percentile(active, 99)) if len(active) else 0.0
    hot = np.flatnonzero((counts >= HOT_MIN_EVENTS) & (counts / duration_s > HOT_FACTOR * p99))
    return {"leak_rate_hz": round(leak, 5), "shot_noise_rate_hz": round(shot, 5),
            "shot_noise_on_fraction": round(min(on, 0.5), 3), "shot_noise_white_factor": 1.0,
            "shot_noise_sigma_decades": round(f["rate_spread_decades"], 3),
            "leak_rate_sigma_decades": round(f["rate_spread_decades"], 3),
            "hot_pixel_fraction": round(f["hot_fraction"], 6), "hot_pixel_rate_hz": round(f["hot_rate_hz"], 3),
            "refractory_us": refractory_us(refractory_floor_us(real_half, hot), f["iei_p0_1_us"]),
            "readout_period_us": readout_period_us(clip_stream)}


DIFFUSION_SHARES = (0.0, 0.25, 0.5, 0.75, 1.0)


def with_diffusion_share(fitted: dict, share: float) -> dict:
    """`fitted`'s values with `share` of its shot noise made diffusion noise instead (same ON share and
    per-pixel spread)."""
    from simulator.config import SimulatorConfig

    total = fitted["shot_noise_rate_hz"] + fitted.get("diffusion_noise_rate_hz", 0.0)
    lo, hi, _ = SimulatorConfig.BOUNDS["diffusion_noise_on_fraction"]    # a walk cannot be all ON or all OFF
    on = min(max(fitted["shot_noise_on_fraction"], lo), hi)
    return {**fitted, "shot_noise_rate_hz": round((1 - share) * total, 6),
            "diffusion_noise_rate_hz": round(share * total, 6), "diffusion_noise_on_fraction": round(on, 3),
            "diffusion_noise_sigma_decades": fitted["shot_noise_sigma_decades"]}


def fit_diffusion_share(fitted: dict, target_regularity: float, width: int, height: int, duration_s: float,
                        intensity: float, seed: int = 0) -> tuple[float, dict]:
    """The diffusion noise's share of the non-leak noise whose still scene has `target_regularity`
    (module note), and the regularity simulated at each of DIFFUSION_SHARES."""
    from dataclasses import replace

    from simulator.config import SimulatorConfig

    table = {}
    for share in DIFFUSION_SHARES:
        cfg = replace(SimulatorConfig(), **with_diffusion_share(fitted, share))
        sim = still_scene(cfg, width, height, duration_s, intensity, seed)
        table[share] = noise_figures(sim, np.ones((height, width), bool), duration_s)["regularity"]
    regs = np.array([table[s] for s in DIFFUSION_SHARES])
    if not (math.isfinite(target_regularity) and np.all(np.isfinite(regs))) or target_regularity <= regs[0]:
        return 0.0, table
    if target_regularity >= regs.max():
        return float(DIFFUSION_SHARES[int(np.argmax(regs))]), table
    k = int(np.flatnonzero(regs >= target_regularity)[0])          # the first share at or above the target
    lo, hi = DIFFUSION_SHARES[k - 1], DIFFUSION_SHARES[k]
    return round(lo + (hi - lo) * (target_regularity - regs[k - 1]) / (regs[k] - regs[k - 1]), 3), table


def still_scene(config, width: int, height: int, duration_s: float, intensity: float, seed: int = 0):
    """The events `config`'s sensor makes of a still scene at one linear grey level."""
    from eventio.events import EventStream
    from simulator.simulator import EventSimulator

    sim = EventSimulator(config, width, height, seed=seed)
    frame = np.full((height, width), intensity, np.float32)
    n = int(math.ceil(duration_s * FRAME_RATE_HZ))
    chunks = [sim.push(frame, int(round(k * 1e6 / FRAME_RATE_HZ))) for k in range(n + 1)] + [sim.flush()]
    return EventStream(np.concatenate(chunks), width, height)


def compare(sim: dict, real: dict) -> dict:
    from scipy.stats import wasserstein_distance

    w1 = lambda a, b: float(wasserstein_distance(a, b)) if len(a) and len(b) else float("nan")  # noqa: E731
    return {"w1_log_rate": w1(sim["log_rates"], real["log_rates"]), "w1_log_iei": w1(sim["log_iei"], real["log_iei"])}


def sensor_figures(config, real: dict, width: int, height: int, duration_s: float, intensity: float) -> dict:
    """A sensor's still scene at the clip's resolution for `duration_s`: its noise figures and its distances
    to the camera's (`real`: noise_figures of the camera's still pixels on the same half)."""
    sim = still_scene(config, width, height, duration_s, intensity)
    f = noise_figures(sim, np.ones((height, width), bool), duration_s)
    return {**{k: v for k, v in f.items() if not k.startswith("log_")}, **compare(f, real)}


def main(argv: list[str] | None = None) -> int:
    from dataclasses import replace

    from common.config import to_dict
    from eventio.formats import read_recording
    from simulator.config import SimulatorConfig
    from simulator.sensor_presets import load_sensor
    from tools.aps_check import V2E
    from tools.tool_cli import existing_file, float_in, write_json

    p = argparse.ArgumentParser(prog="python -m tools.noise_check", description=__doc__.split("\n\n")[0])
    p.add_argument("--clip", type=existing_file, required=True, help="an event recording (any format `e4dgs import` reads)")
    p.add_argument("--sensor", default=None, help="a shipped sensor to report beside ideal, realistic and v2e's presets")
    p.add_argument("--fit", action="store_true", help="print the values fitted on the first half")
    p.add_argument("--intensity", type=float_in(0.0, 1.0, "linear intensity"), default=0.5,
                   help="the still scene's linear grey level (default 0.5)")
    p.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = p.parse_args(argv)
    stream, fmt = read_recording(args.clip)
    e = stream.events
    t0, t1 = int(e["t"].min()), int(e["t"].max())
    mid = (t0 + t1) // 2
    mask = still_pixels(stream)
    halves = {"fit": window(stream, t0, mid), "held_out": window(stream, mid, t1)}
    dur = {"fit": (mid - t0) / 1e6, "held_out": (t1 - mid) / 1e6}
    real = {h: noise_figures(s, mask, dur[h]) for h, s in halves.items()}
    out = {"clip": str(args.clip), "format": fmt, "width": stream.width, "height": stream.height,
           "still_pixels": int(mask.sum()), "real": {h: {k: v for k, v in f.items() if not k.startswith("log_")}
                                                    for h, f in real.items()}}
    fitted = fit(halves["fit"], mask, dur["fit"], stream)
    if args.fit:
        share, table = fit_diffusion_share(fitted, real["fit"]["regularity"], stream.width, stream.height,
                                           dur["fit"], args.intensity)
        fitted = with_diffusion_share(fitted, share)
        out["diffusion_share_regularity"] = {str(k): v for k, v in table.items()}
        print(f"diffusion noise's share: {share} (the camera's regularity {real['fit']['regularity']:.2f} on the "
              f"first half; simulated at each share: {', '.join(f'{k}: {v:.2f}' for k, v in table.items())})")
    out["fitted"] = fitted
    configs = {"ideal": load_sensor("ideal"), "realistic": load_sensor("realistic")}
    configs.update({k: SimulatorConfig(**v) for k, v in V2E.items()})
    if args.fit:
        configs["fitted"] = replace(SimulatorConfig(), **fitted)
    if args.sensor:
        configs[args.sensor] = load_sensor(args.sensor, ("readout",) if fitted["readout_period_us"] else ())
        out["sensor_values"] = to_dict(configs[args.sensor])     # what the report's row was made with
    print(f"{args.clip} ({fmt}, {stream.width}x{stream.height}, {len(e):,} events, {(t1 - t0) / 1e6:.2f} s): "
          f"{int(mask.sum()):,} still pixels ({mask.mean():.1%}); fitted on the first half: {fitted}\n")
    held = real["held_out"]
    print("| sensor (held-out half) | noise (Hz / still pixel) | ON | hot pixels | IEI p0.1 (us) | regularity | "
          "same polarity | W1 log rate | W1 log IEI |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| the camera | {held['rate_hz']:.4f} | {held['on_fraction']:.3f} | {held['hot_fraction']:.5f} | "
          f"{held['iei_p0_1_us']:.0f} | {held['regularity']:.2f} | {held['same_polarity']:.3f} | 0 | 0 |")
    out["configs"] = {}
    for name, cfg in configs.items():
        f = out["configs"][name] = sensor_figures(cfg, held, stream.width, stream.height, dur["held_out"],
                                                  args.intensity)
        print(f"| {name} | {f['rate_hz']:.4f} | {f['on_fraction']:.3f} | {f['hot_fraction']:.5f} | "
              f"{f['iei_p0_1_us']:.0f} | {f['regularity']:.2f} | {f['same_polarity']:.3f} | {f['w1_log_rate']:.3f} | "
              f"{f['w1_log_iei']:.3f} |")
    if args.sensor:
        verdict = goal(out["configs"], held, args.sensor, GOAL)
        out["goal"] = verdict
        print("\n" + "\n".join(goal_lines(verdict, args.sensor)))
    if args.json:
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    from tools.tool_cli import run_tool

    sys.exit(run_tool(main))
