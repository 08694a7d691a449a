"""The DAVIS346 APS check: the clip's grey frames through the simulator, against the events the camera
made from the same pixels over the same span; and the `davis346` sensor preset fitted on the first
half of the span, reported on the second (held out).

    python -m tools.aps_check --clip davis346.aedat4 [--fit] [--json OUT]

Frames: linear intensity DN / 255 at each exposure's centre, APS noise removed (simulator.aps:
each pixel's deviation from its temporal median soft-thresholded by 4 DN), upsampled to 2 kHz
along the optical flow between frames (`--motion flow`, the default) or linearly (`--motion
linear`). The span is the first to the last frame centre; its halves split at the middle. Per sensor
config, on each half: events, ON fraction, consecutive same polarity, the inter-event-interval floor
(min, p0.1), the noise rate on static pixels (pixels whose denoised APS value never changes: every
event there is noise), and the realism report's two distances (Wasserstein-1 of log10 per-pixel
rate and of log10 inter-event interval, eventio.realism).

`--fit` searches thresholds (ON and OFF), refractory period and photoreceptor cutoff (`FIT_GRID`) on
the first half (the sum of the two distances, the static-pixel rate's and the event count's log10
ratios), with the
leak rate set to the camera's static-pixel ON rate on the first half. v2e's own presets are given as their parameters run through
this simulator (not v2e itself). `--fit --wide` searches `WIDE_GRID` (thresholds from 0.2, their
pixel-to-pixel spread, refractory 250-1000 us), adds the inter-event-interval floor's (p0.1)
log10 ratio to the objective, and then refines the best point's refractory period in 50 us steps
(+-150 us): how configs/sensors/davis346.yaml was fitted (docs/results/sensors.md). The report ends
with the goal's verdict for `davis346` (eventio.realism_goal): closer to the camera than every v2e preset
on the two distances, the still-pixel noise and the interval floor, on the held-out half.
"""
from __future__ import annotations

import argparse
import itertools
import math
import sys
from pathlib import Path

import numpy as np

from eventio.realism_goal import goal, goal_figures, goal_lines

RATE_HZ = 2000.0

# v2e's command-line defaults and its `clean` / `noisy` presets (v2ecore/v2e_args.py), in our model's terms
V2E = {"v2e defaults": dict(pos_threshold=0.2, neg_threshold=0.2, threshold_sigma=0.03, lowpass_cutoff_hz=300.0,
                            leak_rate_hz=0.01, shot_noise_rate_hz=0.001, refractory_us=500),
       "v2e clean": dict(pos_threshold=0.2, neg_threshold=0.2, threshold_sigma=0.02),
       "v2e noisy": dict(pos_threshold=0.2, neg_threshold=0.2, threshold_sigma=0.05, lowpass_cutoff_hz=30.0,
                         leak_rate_hz=0.1, shot_noise_rate_hz=5.0)}


# the goal's four figures in this check's figures (eventio.realism_goal)
GOAL = goal_figures("static_rate_hz")


def read_clip(path: Path) -> tuple[np.ndarray, np.ndarray, object]:
    """(APS frames uint8 [F, H, W], their exposure centres in us [F], the event stream)."""
    import aedat

    from eventio.formats import read_recording

    frames, t = [], []
    try:
        for packet in aedat.Decoder(str(path)):
            if "frame" in packet:
                f = packet["frame"]
                frames.append(f["pixels"])
                t.append((int(f["exposure_begin_t"]) + int(f["exposure_end_t"])) // 2)
    except Exception as exc:  # noqa: BLE001 - the decoder's errors name neither the file nor what was expected
        raise ValueError(f"{path}: not an AEDAT4 recording the aedat package reads ({exc})") from None
    if len(frames) < 2:
        raise ValueError(f"{path}: {len(frames)} APS frame(s): the check needs a DAVIS recording with frames and events")
    return np.stack(frames), np.array(t, np.int64), read_recording(path)[0]


def window(stream, t0: int, t1: int):
    from eventio.events import EventStream

    e = stream.events
    return EventStream(e[(e["t"] > t0) & (e["t"] <= t1)], stream.width, stream.height)


def figures(sim, real, static: np.ndarray) -> dict:
    from eventio.realism import distances, pixel_rate_hz, stream_stats

    s, r = stream_stats(sim), stream_stats(real)
    d = distances(s, r)
    return {"events": s.n_events, "real_events": r.n_events, "on_fraction": s.on_fraction,
            "same_polarity": s.same_polarity_fraction, "iei_min_us": s.iei_min_us, "iei_p0_1_us": s.iei_p0_1_us,
            "static_rate_hz": pixel_rate_hz(sim, static), "w1_log_rate": d["w1_log_rate"],
            "w1_log_iei": d["w1_log_iei"]}


def real_figures(real, static: np.ndarray) -> dict:
    from eventio.realism import pixel_rate_hz, stream_stats

    r = stream_stats(real)
    return {"events": r.n_events, "on_fraction": r.on_fraction, "same_polarity": r.same_polarity_fraction,
            "iei_min_us": r.iei_min_us, "iei_p0_1_us": r.iei_p0_1_us, "static_rate_hz": pixel_rate_hz(real, static)}


def run(configs: dict, frames: np.ndarray, t_us: np.ndarray, real, static: np.ndarray, motion: str = "flow") -> dict:
    """{name: {"fit": figures on the first half, "held_out": on the second}} for every sensor config."""
    from simulator.aps import simulate_sequence, upsampled

    mid = (int(t_us[0]) + int(t_us[-1])) // 2
    halves = {"fit": (int(t_us[0]), mid), "held_out": (mid, int(t_us[-1]))}
    sequence = list(upsampled(frames, t_us, RATE_HZ, motion))      # once for every sensor
    out = {}
    for name, cfg in configs.items():
        sim = simulate_sequence(sequence, cfg, frames.shape[2], frames.shape[1])
        out[name] = {h: figures(window(sim, a, b), window(real, a, b), static) for h, (a, b) in halves.items()}
    return out


# What --fit searches (configs/sensors/davis346.yaml came from it): ON / OFF thresholds, refractory (us),
# photoreceptor cutoff (Hz); the thresholds' spread fixed at 0.03
FIT_GRID = {"pos_threshold": (0.25, 0.3, 0.35, 0.4), "neg_threshold": (0.25, 0.3, 0.35, 0.4), "threshold_sigma": (0.03,),
            "refractory_us": (500, 1000), "lowpass_cutoff_hz": (0.0, 100.0, 300.0)}
# --wide: lower thresholds, the spread, shorter refractory periods (216 configs, ~25 min on one core), then
# the refractory period refined around the best point (REFINE_*)
WIDE_GRID = {"pos_threshold": (0.2, 0.25, 0.3), "neg_threshold": (0.2, 0.25, 0.3), "threshold_sigma": (0.03, 0.06),
             "refractory_us": (250, 500, 750, 1000), "lowpass_cutoff_hz": (0.0, 100.0, 300.0)}


REFINE_STEP_US, REFINE_REACH_US = 50, 150     # --wide then refines the refractory period: 50 us steps, +-150 us


def objective(f: dict, real: dict, floor_term: bool = False) -> float:
    """What the fit minimises on the first half: the two distances, the static-pixel rate's and the
    event count's log10 ratios to the camera's (and with floor_term the interval floor's, p0.1)."""
    rate = abs(math.log10(max(f["static_rate_hz"], 1e-6) / max(real["static_rate_hz"], 1e-6)))
    count = abs(math.log10(max(f["events"], 1) / max(real["events"], 1)))
    floor = abs(math.log10(max(f["iei_p0_1_us"], 1.0) / max(real["iei_p0_1_us"], 1.0))) if floor_term else 0.0
    return f["w1_log_rate"] + f["w1_log_iei"] + floor + 0.25 * rate + count


def fit(frames, t_us, real, static, log=print, wide: bool = False, motion: str = "flow"):
    """The sensor config that minimises `objective` on the first half (grid search), and its leak."""
    from dataclasses import replace

    from simulator.aps import simulate_sequence, upsampled
    from simulator.config import SimulatorConfig

    mid = (int(t_us[0]) + int(t_us[-1])) // 2
    first = window(real, int(t_us[0]), mid)
    target = real_figures(first, static)
    e = first.events
    on_static = e[static[e["y"].astype(int), e["x"].astype(int)] & (e["p"] > 0)]
    leak = len(on_static) / max(static.sum(), 1) / ((mid - int(t_us[0])) / 1e6)
    half = t_us <= mid + (t_us[1] - t_us[0])
    sequence = list(upsampled(frames[half], t_us[half], RATE_HZ, motion))    # the first half's frames only
    best = None
    grid = WIDE_GRID if wide else FIT_GRID

    def score(cfg):
        sim = window(simulate_sequence(sequence, cfg, frames.shape[2], frames.shape[1]), int(t_us[0]), mid)
        return objective(figures(sim, first, static), target, floor_term=wide)

    for values in itertools.product(*grid.values()):
        cfg = SimulatorConfig(**dict(zip(grid, values)), leak_rate_hz=leak)
        s = score(cfg)
        if best is None or s < best[0]:
            best = (s, cfg)
            log("fit: " + " ".join(f"{k} {v}" for k, v in zip(grid, values)) + f": {s:.3f} (best)")
    if wide:        # the grid's refractory steps are coarse (250 us): refine it around the best point
        for r in refractory_refinement(best[1].refractory_us):
            cfg = replace(best[1], refractory_us=r)
            s = score(cfg)
            if s < best[0]:
                best = (s, cfg)
                log(f"fit: refractory_us {r}: {s:.3f} (best)")
    return best[1], leak, target


def refractory_refinement(refractory_us: int, step_us: int = REFINE_STEP_US) -> list[int]:
    """The refractory periods --wide tries after the grid: `step_us` apart, out to half the grid's spacing
    on each side of the grid's best (not the best itself)."""
    return [r for r in range(refractory_us - REFINE_REACH_US, refractory_us + REFINE_REACH_US + 1, step_us)
            if r > 0 and r != refractory_us]


def main(argv: list[str] | None = None) -> int:
    from common.config import to_dict
    from simulator.aps import DN_FULL_SCALE, MOTIONS, denoise_aps, static_pixels
    from simulator.config import SimulatorConfig
    from simulator.sensor_presets import load_sensor
    from tools.tool_cli import existing_file, write_json

    p = argparse.ArgumentParser(prog="python -m tools.aps_check", description=__doc__.split("\n\n")[0])
    p.add_argument("--clip", type=existing_file, required=True,
                   help="a DAVIS AEDAT4 recording with APS frames and events (e.g. the aedat 2.3.0 package's "
                        "tests/data/test_data.aedat4, MIT)")
    p.add_argument("--fit", action="store_true", help="search the davis346 preset's values on the first half")
    p.add_argument("--wide", action="store_true", help="with --fit: the wider grid and the floor in the objective")
    p.add_argument("--motion", choices=MOTIONS, default="flow",
                   help="how the 25 fps frames are upsampled: along the optical flow between them (flow) or by "
                        "blending them (linear)")
    p.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = p.parse_args(argv)
    dn, t_us, real = read_clip(args.clip)
    den = denoise_aps(dn)
    static = static_pixels(den)
    frames = den / DN_FULL_SCALE
    configs = {"ideal": load_sensor("ideal"), "realistic": load_sensor("realistic")}
    configs.update({k: SimulatorConfig(**v) for k, v in V2E.items()})
    out = {"frames": len(dn), "static_pixels": int(static.sum()), "motion": args.motion}
    if args.fit:
        cfg, leak, target = fit(frames, t_us, real, static, wide=args.wide, motion=args.motion)
        configs["fitted"] = cfg
        out["fitted"] = {k: getattr(cfg, k) for k in ("pos_threshold", "neg_threshold", "refractory_us",
                                                      "lowpass_cutoff_hz", "leak_rate_hz", "threshold_sigma")}
        out["fit_target"] = target
    try:
        configs["davis346"] = load_sensor("davis346")
        out["sensor_values"] = to_dict(configs["davis346"])        # what the report's davis346 row was made with
    except (ValueError, OSError):      # not shipped yet (before the first --fit)
        pass
    mid = (int(t_us[0]) + int(t_us[-1])) // 2
    out["real"] = {"fit": real_figures(window(real, int(t_us[0]), mid), static),
                   "held_out": real_figures(window(real, mid, int(t_us[-1])), static)}
    out["configs"] = run(configs, frames, t_us, real, static, args.motion)
    r = out["real"]["held_out"]
    print(f"{len(dn)} APS frames, {int(static.sum())} static pixels; held-out half: the camera made {r['events']} "
          f"events (ON {r['on_fraction']:.3f}, same polarity {r['same_polarity']:.3f}, IEI min "
          f"{r['iei_min_us']:.0f} us, static-pixel noise {r['static_rate_hz']:.4f} Hz)\n")
    print("| sensor | events | ON | same polarity | IEI min / p0.1 (us) | static-pixel noise (Hz) | W1 log rate | "
          "W1 log IEI |")
    print("|---|---|---|---|---|---|---|---|")
    for name, halves in out["configs"].items():
        f = halves["held_out"]
        print(f"| {name} | {f['events']:,} | {f['on_fraction']:.3f} | {f['same_polarity']:.3f} | "
              f"{f['iei_min_us']:.0f} / {f['iei_p0_1_us']:.0f} | {f['static_rate_hz']:.4f} | {f['w1_log_rate']:.3f} | "
              f"{f['w1_log_iei']:.3f} |")
    if "davis346" in out["configs"]:
        held = {name: halves["held_out"] for name, halves in out["configs"].items()}
        verdict = goal(held, out["real"]["held_out"], "davis346", GOAL)
        out["goal"] = verdict
        print("\n" + "\n".join(goal_lines(verdict, "davis346")))
    if args.json:
        write_json(args.json, out)
    return 0


if __name__ == "__main__":
    from tools.tool_cli import run_tool

    sys.exit(run_tool(main))
