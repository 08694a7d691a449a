"""Learning curves of one method with the deformation MLP against per-Gaussian trajectories: PSNR and
moving-pixel PSNR of each snapshot against training seconds.

    python -m tools.field_curves --scene data/quick/hinge --method e4dgs \\
        --config configs/recipes/e4dgs/quick.yaml [--fields mlp trajectory] [--scale 1] [--set KEY=VALUE]

Each field trains the same config (`train.deform_field.kind` set, `train.iterations` x --scale with
the schedule scaled along, snapshots at 10 / 25 / 50 / 75 / 100 % or at --snapshots) into --out/<method>_<field>; the
runs resume and are reused like any training folder. Every snapshot is scored as the benchmark
scores (recon.evaluate: the method's correction, whole images and the scene's dynamic masks).
Writes <out>/<scene>/<method>_curves.json and prints a Markdown table with the CPU named.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from common.argtypes import float_in
from tools.tool_cli import positive_float, run_tool

SNAPSHOTS = [0.1, 0.25, 0.5, 0.75, 1.0]


class _Stopped(Exception):
    pass


def run_overrides(method: str, config: str, field: str, scale: float, sets: dict,
                  snapshots: list[float] = SNAPSHOTS) -> dict:
    """The overrides one curve's run trains with: the field, its snapshots, the iterations x scale and
    (scale != 1) the schedule scaled along; `sets` last."""
    import recon

    base = recon.resolve_config(method, config)
    iters = max(1, int(round(base.train.iterations * scale)))
    overrides = {"train.deform_field.kind": field, "train.snapshots": sorted(set(snapshots)), "train.iterations": iters}
    if scale != 1:
        # the schedule scales along: a recipe already scaled keeps the budget its numbers are written for
        reference = base.train.schedule_reference if base.train.scale_schedule else base.train.iterations
        overrides.update({"train.scale_schedule": True, "train.schedule_reference": reference})
    return {**overrides, **sets}


def train_until(scene, method: str, config: str, overrides: dict, run_dir: Path, until_s: float | None,
                keep_initial: bool = True) -> dict:
    """Train (or resume) the run in run_dir until its training seconds reach until_s (None: to its end).
    -> {"log", "initial" (None unless keep_initial), "stop"}: "stop" is None for a finished run, else the
    iteration, seconds and size where it stopped; its model is saved as run_dir/stopped.pt and its
    checkpoint kept, so the next call resumes it exactly (the RNG states travel with the checkpoint)."""
    import recon

    stop = {}

    def budget(trainer, it):
        if until_s is not None and trainer.wall_s >= until_s and it < trainer.tcfg.iterations:
            trainer.model.save(run_dir / "stopped.pt")
            trainer._save_checkpoint()      # resumable, and its snapshots stay (a run with no checkpoint is removed)
            stop.update(iteration=it, wall_s=trainer.wall_s, n_gaussians=len(trainer.model), log=list(trainer.log),
                        initial=trainer.initial_model() if keep_initial else None)
            raise _Stopped
    try:
        result = recon.fit(scene, method, config, run_dir, overrides=overrides, progress=False,
                           keep_initial=keep_initial, on_iteration=budget if until_s is not None else None)
        return {"log": list(result.log), "initial": result.initial, "stop": None}
    except _Stopped:
        return {"log": stop.pop("log"), "initial": stop.pop("initial"), "stop": stop}


def score_run(dataset, run_dir: Path, trained: dict, initial) -> list[dict]:
    """The curve of a run trained by train_until: the untrained model at 0 s, every snapshot in its log
    and (a stopped run) its model at the stop, each scored as the benchmark scores (recon.evaluate)."""
    import recon

    points = []
    for row in trained["log"]:
        if "snapshot" in row:
            s = recon.evaluate(recon.load(run_dir / row["snapshot"]), dataset)
            points.append({"iteration": row["iteration"], "wall_s": row["wall_s"], "psnr": s["psnr"],
                           "psnr_dyn": s.get("psnr_dyn"), "n_gaussians": row["n_gaussians"]})
    stop = trained["stop"]
    if stop:
        s = recon.evaluate(recon.load(run_dir / "stopped.pt"), dataset)
        points.append({"iteration": stop["iteration"], "wall_s": round(stop["wall_s"], 3), "psnr": s["psnr"],
                       "psnr_dyn": s.get("psnr_dyn"), "n_gaussians": stop["n_gaussians"], "stopped": True})
    floor = recon.evaluate(initial, dataset)        # the untrained model the run starts from
    return [{"iteration": 0, "wall_s": 0.0, "psnr": floor["psnr"], "psnr_dyn": floor.get("psnr_dyn"),
             "n_gaussians": len(initial)}] + points


def curves_table(curves: dict[str, list[dict]], label: str) -> str:
    """Markdown: one row per scored point of every curve (a stopped run's last point marked)."""
    lines = [f"| {label} | iteration | train s | PSNR | moving-pixel PSNR | Gaussians |",
             "|---|---:|---:|---:|---:|---:|"]
    for name, points in curves.items():
        for p in points:
            dyn = "–" if p["psnr_dyn"] is None else f"{p['psnr_dyn']:.2f}"
            it = f"{p['iteration']} (stopped)" if p.get("stopped") else p["iteration"]
            lines.append(f"| {name} | {it} | {p['wall_s']:.0f} | {p['psnr']:.2f} | {dyn} | {p['n_gaussians']} |")
    return "\n".join(lines)


def curve(scene: str, method: str, config: str, field: str, scale: float, out: Path, sets: dict,
          snapshots: list[float] = SNAPSHOTS, max_train_s: float | None = None) -> list[dict]:
    """The run's curve; with max_train_s the run stops once its training seconds reach it (a model saved
    there is the last point, marked "stopped"), for a recipe compared at a time budget it overruns."""
    from scene_format.reader import SceneDataset

    run_dir = out / f"{method}_{field}"
    trained = train_until(scene, method, config, run_overrides(method, config, field, scale, sets, snapshots),
                          run_dir, max_train_s)
    return score_run(SceneDataset(scene), run_dir, trained, trained["initial"])


def main(argv=None) -> int:
    from common.config import parse_set
    from common.machine import cpu_summary

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", required=True)
    ap.add_argument("--method", required=True)
    ap.add_argument("--config", required=True)
    ap.add_argument("--fields", nargs="+", default=["mlp", "trajectory"], choices=["mlp", "trajectory"])
    ap.add_argument("--scale", type=positive_float, default=1.0, help="budget multiple of the config's iterations")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--snapshots", nargs="+", type=float_in(1e-6, 1.0, "a fraction of the run"), default=SNAPSHOTS,
                    metavar="F", help="fractions of the run scored (default 0.1 0.25 0.5 0.75 1)")
    ap.add_argument("--max-train-s", type=positive_float, default=None, metavar="S",
                    help="stop each run once its training seconds reach S (its model there is the last point)")
    ap.add_argument("--out", default="runs/field_curves")
    args = ap.parse_args(argv)
    sets = parse_set(args.set)
    out = Path(args.out) / Path(args.scene).name
    results = {field: curve(args.scene, args.method, args.config, field, args.scale, out, sets, args.snapshots,
                            args.max_train_s) for field in args.fields}
    (out / f"{args.method}_curves.json").write_text(json.dumps({"cpu": cpu_summary(), "scene": args.scene,
                                                                 "method": args.method, "curves": results}, indent=1))
    print(f"{args.method} on {Path(args.scene).name}, CPU {cpu_summary()}")
    print(curves_table(results, "field"))
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
