"""Learning curves of several recipes on one scene, trained in alternation: each run in turn trains
for --slice-s more training seconds (resumed exactly from its checkpoint), pass after pass, until
each reaches --max-train-s or its end. A host whose speed drifts over minutes (a shared VM) then slows
every recipe alike, so their seconds compare; one recipe run after another would carry the drift.

    python -m tools.curves_alternated --scene data/quick/hinge_x26.2 --method e4dgs \\
        --recipe converged=configs/recipes/e4dgs/converged.yaml:mlp \\
        --recipe trajectory=configs/recipes/e4dgs/quick.yaml:trajectory:12 \\
        --recipe mlp=configs/recipes/e4dgs/quick.yaml:mlp:12 \\
        --max-train-s 900 --slice-s 150 --goal 36.0 --goal-moving 25.5

A --recipe is NAME=CONFIG:FIELD[:SCALE] (SCALE: multiple of the config's iterations, the schedule
scaled along, as tools.field_curves does). Each run trains into --out/<scene>/<NAME>, so a killed
comparison resumes where it stopped. After the last pass every snapshot is scored as the benchmark
scores (recon.evaluate). Writes <out>/<scene>/alternated_curves.json (curves, every slice's steps and
seconds, the CPU) and prints the curves and, with --goal, the training seconds at which each run
first reaches it (linear between scored points).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from common.argtypes import float_in
from tools.field_curves import curves_table, run_overrides, score_run, train_until
from tools.tool_cli import existing_folder, positive_float, run_tool

SNAPSHOTS = [round(0.05 * k, 2) for k in range(1, 21)]


def run_spec(text: str) -> dict:
    """NAME=CONFIG:FIELD[:SCALE] -> {name, config, field, scale}; a malformed one names what was expected."""
    name, sep, rest = text.partition("=")
    parts = rest.split(":")
    if not sep or not name or len(parts) not in (2, 3):
        raise argparse.ArgumentTypeError(f"{text!r}: expected NAME=CONFIG:FIELD[:SCALE]")
    if parts[1] not in ("mlp", "trajectory"):
        raise argparse.ArgumentTypeError(f"{text!r}: FIELD must be mlp or trajectory, not {parts[1]!r}")
    scale = positive_float(parts[2]) if len(parts) == 3 else 1.0
    return {"name": name, "config": parts[0], "field": parts[1], "scale": scale}


def crossing_s(curve: list[dict], key: str, goal: float) -> float | None:
    """The training seconds at which `key` first reaches `goal`, linear between the scored points around
    the crossing; None when no point reaches it."""
    prev = None
    for p in curve:
        v = p.get(key)
        if v is None:
            continue
        if v >= goal:
            if prev is None or prev[key] >= goal:
                return float(p["wall_s"])
            frac = (goal - prev[key]) / (v - prev[key])
            return float(prev["wall_s"] + frac * (p["wall_s"] - prev["wall_s"]))
        prev = p
    return None


def alternate(scene: str, method: str, runs: list[dict], out: Path, max_train_s: float, slice_s: float,
              snapshots: list[float] = SNAPSHOTS, sets: dict | None = None, log=print) -> dict:
    """Train the runs in passes of slice_s training seconds each, in the given order, to max_train_s;
    -> {"slices": [...], "trained": {name: train_until's last answer}, "initial": {name: model}}."""
    sets = sets or {}
    rounds = max(1, math.ceil(max_train_s / slice_s - 1e-9))
    state = {r["name"]: {"overrides": run_overrides(method, r["config"], r["field"], r["scale"], sets, snapshots),
                         "trained": None, "initial": None} for r in runs}
    slices = []
    for k in range(1, rounds + 1):
        until = min(k * slice_s, max_train_s)
        for r in runs:
            st = state[r["name"]]
            if st["trained"] is not None and st["trained"]["stop"] is None:
                continue                                   # finished its schedule in an earlier pass
            t0 = time.time()
            trained = train_until(scene, method, r["config"], st["overrides"], out / r["name"], until,
                                  keep_initial=st["initial"] is None)
            st["trained"] = trained
            if st["initial"] is None:
                st["initial"] = trained["initial"]
            last = trained["log"][-1] if trained["log"] else {"iteration": 0, "wall_s": 0.0}
            end = trained["stop"] or {"iteration": last["iteration"], "wall_s": last["wall_s"]}
            slices.append({"round": k, "run": r["name"], "until_s": until, "iteration": end["iteration"],
                           "train_s": round(end["wall_s"], 3), "elapsed_s": round(time.time() - t0, 1),
                           "finished": trained["stop"] is None})
            log(f"pass {k}/{rounds} {r['name']}: iteration {end['iteration']}, {end['wall_s']:.0f} s trained"
                f"{' (finished)' if trained['stop'] is None else ''}")
    return {"slices": slices, "trained": {n: s["trained"] for n, s in state.items()},
            "initial": {n: s["initial"] for n, s in state.items()}}


def main(argv=None) -> int:
    from common.config import parse_set
    from common.machine import cpu_summary
    from scene_format.reader import SceneDataset

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True, type=existing_folder)
    ap.add_argument("--method", required=True)
    ap.add_argument("--recipe", action="append", type=run_spec, required=True, metavar="NAME=CONFIG:FIELD[:SCALE]",
                    help="a run to compare (give two or more); SCALE multiplies the config's iterations")
    ap.add_argument("--max-train-s", type=positive_float, default=900.0, metavar="S",
                    help="training seconds each run gets in all (default 900)")
    ap.add_argument("--slice-s", type=positive_float, default=150.0, metavar="S",
                    help="training seconds each run gets per turn (default 150)")
    ap.add_argument("--snapshots", nargs="+", type=float_in(1e-6, 1.0, "a fraction of the run"), default=SNAPSHOTS,
                    metavar="F", help="fractions of each run scored (default every 5 %%)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="applied to every run")
    ap.add_argument("--goal", type=positive_float, default=None, metavar="DB", help="whole-image PSNR goal")
    ap.add_argument("--goal-moving", type=positive_float, default=None, metavar="DB", help="moving-pixel PSNR goal")
    ap.add_argument("--out", default="runs/alternated")
    args = ap.parse_args(argv)
    names = [r["name"] for r in args.recipe]
    if len(set(names)) != len(names):
        raise SystemExit(f"--recipe: names must differ, got {names}")
    out = Path(args.out) / args.scene.name
    done = alternate(str(args.scene), args.method, args.recipe, out, args.max_train_s, args.slice_s,
                     sorted(set(args.snapshots)), parse_set(args.set))
    dataset = SceneDataset(str(args.scene))
    curves = {r["name"]: score_run(dataset, out / r["name"], done["trained"][r["name"]], done["initial"][r["name"]])
              for r in args.recipe}
    goals = {k: g for k, g in (("psnr", args.goal), ("psnr_dyn", args.goal_moving)) if g is not None}
    reached = {n: {k: crossing_s(c, k, g) for k, g in goals.items()} for n, c in curves.items()}
    record = {"command": "python -m tools.curves_alternated " + " ".join(sys.argv[1:] if argv is None else argv),
              "cpu": cpu_summary(), "scene": str(args.scene), "method": args.method, "max_train_s": args.max_train_s,
              "slice_s": args.slice_s, "runs": args.recipe, "curves": curves, "goals": goals, "reached_s": reached,
              "slices": done["slices"]}
    (out / "alternated_curves.json").write_text(json.dumps(record, indent=1))
    print(f"{args.method} on {args.scene.name}, CPU {cpu_summary()}, {args.slice_s:g} s slices in turn")
    print(curves_table(curves, "run"))
    for name, r in reached.items():
        for key, s in r.items():
            what = "PSNR" if key == "psnr" else "moving-pixel PSNR"
            print(f"{name}: {what} {goals[key]:g} dB " + ("not reached" if s is None else f"at {s:.0f} s"))
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
