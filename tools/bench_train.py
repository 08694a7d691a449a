"""Training iterations per second of every method at a scene's resolution, with a per-part breakdown.

    python -m tools.bench_train [--scene data/quick/hinge] [--methods e4dgs e4dgs_rgb d3dgs]
                                    [--gaussians 20000] [--iters 12] [--threads 1] [--against REV]
                                    [--precisions auto float32 bfloat16]

Each method runs its leaderboard recipe (configs/recipes/<method>/quick.yaml) with N initial Gaussians and the
deformation on, in two states:
- early: the method's random initial model (a haze whose footprints cover the image: the slowest
  part of training for the rasterizer);
- late: that model after intensity-importance pruning (max alpha x transmittance over the training
  cameras at 5 times < 0.015), what training keeps after its first IIP round;
- or, with `--model PT`, a trained state (a run's model or snapshot): what a step costs where
  training actually is.
Learning rates are 0, so every timed iteration costs what a training one does but the model stays
the same. Each part is timed inside the real iterations: rasterizer forward and backward (the
projection included), deformation MLP forward and backward (from the first gradient reaching its
outputs until its first layer has been differentiated: autograd runs one render's nodes at a time,
so the intervals do not overlap), the trajectories' forward (their backward falls under "rest"),
data (an E-4DGS step's event window, event maps and target counts), the optimiser (Adam's step and
zeroing the gradients), and the rest (SH colours, the losses and their backward).

`--against REV` times a git revision's tree side by side: each tree runs in its own worker process
(PYTHONPATH set to that tree) and the driver alternates single iterations between them, so machine
stalls hit both alike and the speed-up ratio comes from one run. `--precisions` does the same with
this tree's deformation MLP under several `train.precision` values (one worker each; `auto` shows what
it resolved to; the precision is the MLP's, so these workers set `train.deform_field.kind: mlp`), so the
MLP's dtypes are compared on one machine in one run; `--fields trajectory` adds a
worker whose deformation is per-Gaussian trajectories; `--set KEY=VALUE` overrides every worker's
config, the revision's too (e.g. `--set train.deform_field.width=128` for a smaller MLP); `--coarse 2 4` adds trajectory workers whose renders and targets are those of a
coarse-to-fine stage at 1/2 and 1/4 resolution (train.coarse_to_fine). Medians throughout; the CPU
(model and its bf16-relevant flags) is printed above the table.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from tools.tool_cli import existing_file, int_in, nonnegative_int, positive_int, run_tool

PARTS = ("raster_fwd", "raster_bwd", "mlp_fwd", "mlp_bwd", "trajectory_fwd", "data", "optimiser")
CONFIGS = {"d3dgs": "configs/recipes/d3dgs/quick.yaml", "e4dgs": "configs/recipes/e4dgs/quick.yaml",
           "e4dgs_rgb": "configs/recipes/e4dgs/quick.yaml"}
OLD_CONFIGS = {"d3dgs": "configs/recon/bench/d3dgs_quick.yaml", "e4dgs": "configs/recon/bench/e4dgs_quick.yaml",
               "e4dgs_rgb": "configs/recon/bench/e4dgs_quick.yaml"}    # a tree from before 0.2 (--against)
REPO = Path(__file__).resolve().parents[1]


# -- worker: runs inside one source tree ------------------------------------------------------------
class Clock:
    """Per-part seconds of the current iteration, filled by the wrappers below."""

    def __init__(self):
        self.parts = dict.fromkeys(PARTS, 0.0)
        self.mlp_started: dict[int, float] = {}

    def add(self, part: str, seconds: float) -> None:
        self.parts[part] += seconds


def instrument(clock: Clock):
    """Wrap the cpu backend's autograd Functions and the deformation field with timers; returns a
    function that undoes it."""
    import torch

    import recon.raster.cpu as cpu
    from recon.deform import DeformationField

    saved = []
    for obj in list(vars(cpu).values()):
        if isinstance(obj, type) and issubclass(obj, torch.autograd.Function) and obj is not torch.autograd.Function:
            for name, part in (("forward", "raster_fwd"), ("backward", "raster_bwd")):
                saved.append((obj, name, obj.__dict__[name]))
                fn = obj.__dict__[name].__func__ if isinstance(obj.__dict__[name], staticmethod) else obj.__dict__[name]

                def timed(*a, _fn=fn, _part=part, **k):
                    t0 = time.perf_counter()
                    out = _fn(*a, **k)
                    clock.add(_part, time.perf_counter() - t0)
                    return out
                setattr(obj, name, staticmethod(timed))

    import recon.event_supervision as ev
    from recon.event_windows import WindowSampler
    from recon.trajectory import TrajectoryField

    def timer(owner, name, part):
        fn = getattr(owner, name)
        saved.append((owner, name, owner.__dict__[name]))

        def timed(*a, **k):
            t0 = time.perf_counter()
            out = fn(*a, **k)
            clock.add(part, time.perf_counter() - t0)
            return out
        setattr(owner, name, timed)
    # data: an E-4DGS step's event window, its event maps and target counts (with the ESS noise)
    for owner, name in ((WindowSampler, "sample"), (WindowSampler, "sample_views"), (ev, "event_maps"), (ev, "gt_counts")):
        timer(owner, name, "data")
    timer(TrajectoryField, "deform", "trajectory_fwd")

    def timed_field(name):
        """DeformationField.<name> (forward: one time; forward_times: several, one list of outputs per
        time) timed as mlp_fwd, and its backward from the first gradient reaching an output to the
        first layer's weight gradient as mlp_bwd."""
        fn = getattr(DeformationField, name, None)
        if fn is None:        # an older tree (--against) without it
            return
        saved.append((DeformationField, name, fn))

        def timed(self, x, t):
            t0 = time.perf_counter()
            outs = fn(self, x, t)
            clock.add("mlp_fwd", time.perf_counter() - t0)
            flat = [o for out in outs for o in out] if name == "forward_times" else list(outs)
            if torch.is_grad_enabled() and flat[0].requires_grad:
                key = id(flat[0])

                def started(grad):
                    clock.mlp_started.setdefault(key, time.perf_counter())
                for o in flat:
                    o.register_hook(started)
                first = _first_layer_node(flat[0].grad_fn, self.layers[0].weight)
                if first is not None:
                    def finished(*_):
                        begin = clock.mlp_started.pop(key, None)
                        if begin is not None:
                            clock.add("mlp_bwd", time.perf_counter() - begin)
                    first.register_hook(finished)
            return outs
        setattr(DeformationField, name, timed)
    timed_field("forward")
    timed_field("forward_times")

    def restore():
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)
    return restore


def _first_layer_node(root, weight):
    """The autograd node that consumes the first layer's weight (possibly through a dtype cast)."""
    seen, stack = set(), [root]
    while stack:
        node = stack.pop()
        if node is None or id(node) in seen:
            continue
        seen.add(id(node))
        for nxt, _ in node.next_functions:
            if nxt is None:
                continue
            if getattr(nxt, "variable", None) is weight:
                return node
            if type(nxt).__name__.startswith("ToCopy") and any(getattr(n, "variable", None) is weight
                                                               for n, _ in nxt.next_functions if n is not None):
                return node
            stack.append(nxt)
    return None


def build_trainer(scene: str, method: str, n: int, phase: str, out: str, extra: dict | None = None,
                  model_path: str | None = None):
    import torch

    import recon
    from scene_format.reader import SceneDataset
    from recon.methods.e4dgs_config import E4DGSConfig
    from recon.methods import get_method
    try:
        from recon.methods.e4dgs import importance
    except ImportError:   # an older tree timed with --against: the method's own pruning importance
        from recon.methods.e4dgs import E4DGS

        def importance(model, ds, n_times):
            return E4DGS.for_evaluation(ds, E4DGSConfig()).importance(model)
    from recon.trainer import Trainer

    # the random initial haze (the slowest case; the quick E-4DGS recipe now carves its initial points
    # with the events) and the exposure renders the quick E-4DGS + RGB recipe uses
    overrides = {"train.init.n_points_object": n, "train.init.n_points_room": n, "train.init.kind": "auto",
                 **({"rgb_samples": 2} if method == "e4dgs_rgb" else {}),
                 **(extra or {})}
    path = REPO_OF_TREE / CONFIGS[method]
    cfg = recon.resolve_config(method, str(path if path.is_file() else REPO_OF_TREE / OLD_CONFIGS[method]), overrides=overrides)
    ds = SceneDataset(scene)
    trainer = Trainer(get_method(method)(ds, cfg), out, progress=False)
    trainer.setup()
    model = trainer.model
    if model_path:        # a trained state: its Gaussians (and its field where it is this worker's kind and size)
        from recon.densify import DensifyStats

        loaded = recon.load(model_path)
        g = loaded.gaussians.to(trainer.device)
        if model.deform.kind == "trajectory" and g.motion is None:
            g.enable_motion(model.deform.n_basis)
        elif model.deform.kind != "trajectory":
            g.motion = None
        model.gaussians = g
        if loaded.deform.spec() == model.deform.spec():
            model.deform = loaded.deform.to(trainer.device)
        trainer.method.setup_model(model)
        trainer.optimizer = trainer.new_optimizer()
        trainer.stats = DensifyStats(len(model), trainer.device)
    elif phase == "late":   # E-4DGS's intensity-importance pruning, whatever the method
        events = E4DGSConfig().events
        with torch.no_grad():
            model.gaussians.prune(importance(model, ds, events.iip_times) >= events.iip_threshold)
        trainer.optimizer = trainer.new_optimizer()
    for group in trainer.optimizer.param_groups:
        group["lr"] = 0.0
    model.meta.deform_enabled = True
    return trainer


def one_iteration(trainer, clock: Clock) -> dict:
    import torch

    clock.parts = dict.fromkeys(PARTS, 0.0)
    clock.mlp_started.clear()
    t0 = time.perf_counter()
    loss, _ = trainer.method.step(trainer, trainer.tcfg.iterations)
    loss.backward()
    t1 = time.perf_counter()
    with torch.no_grad():
        trainer.optimizer.step()
        trainer.optimizer.zero_grad(set_to_none=True)
    clock.add("optimiser", time.perf_counter() - t1)
    total = time.perf_counter() - t0
    return {"total": total, **clock.parts}


def worker(threads: int) -> None:
    """Read commands (JSON lines) on stdin, answer on stdout: {"setup": ...} then {"iterate": k}."""
    import numba
    import torch

    torch.set_num_threads(threads)
    numba.set_num_threads(threads)
    clock = Clock()
    instrument(clock)
    trainer = None
    tmp = tempfile.TemporaryDirectory()
    for line in sys.stdin:
        cmd = json.loads(line)
        if "setup" in cmd:
            trainer = build_trainer(cmd["scene"], cmd["setup"], cmd["gaussians"], cmd["phase"],
                                    tempfile.mkdtemp(dir=tmp.name), cmd.get("overrides"), cmd.get("model"))
            if cmd.get("factor", 1) != 1:      # a coarse-to-fine stage: every render at 1/factor size
                trainer.render_factor = cmd["factor"]
            one_iteration(trainer, clock)            # compile / warm caches
            import recon
            choice = getattr(trainer, "precision", None)     # an older tree has no train.precision
            reply = {"gaussians": len(trainer.model), "recon": recon.__file__,
                     "precision": f"{choice.dtype} ({choice.source})" if choice is not None else ""}
        else:
            reply = one_iteration(trainer, clock)
        print(json.dumps(reply), flush=True)


# -- driver -----------------------------------------------------------------------------------------
def worker_specs(precisions: list[str] | None, fields: list[str], coarse: list[int]) -> list[tuple[str, dict, int]]:
    """(label, config overrides, render factor) of each worker on this tree, in the table's order.
    train.precision is the deformation MLP's dtype (trajectories compute in float32 whatever it says) and
    the configs' own field is the trajectory, so each precision worker times the MLP."""
    specs = [(f"this tree, MLP, {p}", {"train.precision": p, "train.deform_field.kind": "mlp"}, 1)
             for p in precisions] if precisions else [("this tree", {}, 1)]
    specs += [(f"this tree, {f} field", {"train.deform_field.kind": f}, 1) for f in fields]
    specs += [(f"this tree, trajectory field, 1/{f} resolution", {"train.deform_field.kind": "trajectory"}, f)
              for f in coarse]
    return specs


def revision_factors(coarse: list[int]) -> list[int]:
    """Render factors of the --against revision's workers: full size, then each coarse factor, so
    that they pair one to one, in order, with this tree's workers when no precision or field is
    asked for (`worker_specs(None, [], coarse)`)."""
    return [1, *coarse]


def revision_specs(rev: str, coarse: list[int], sets: dict) -> list[tuple[str, dict, int]]:
    """(label, config overrides, render factor) of the --against revision's workers: one per
    `revision_factors`, each with the same --set overrides as this tree's, so the two trees differ
    in their code only."""
    return [(rev + (f", 1/{f} resolution" if f > 1 else ""), dict(sets), f) for f in revision_factors(coarse)]


class Tree:
    def __init__(self, label: str, root: Path, threads: int, overrides: dict | None = None, factor: int = 1):
        env = dict(os.environ, PYTHONPATH=str(root), OMP_NUM_THREADS=str(threads), MKL_NUM_THREADS=str(threads),
                   NUMBA_NUM_THREADS=str(max(threads, 1)), E4DGS_BENCH_TREE=str(root))
        if root != REPO:   # an older tree's compiled kernels stay in its temporary folder
            env["NUMBA_CACHE_DIR"] = str(root / ".numba-cache")
        self.label, self.root, self.overrides, self.factor = label, root, overrides or {}, factor
        self.precision = self.overrides.get("train.precision")
        # this file runs in every tree (-P: its own folder stays off sys.path, the tree's packages are found)
        self.proc = subprocess.Popen([sys.executable, "-P", __file__, "--worker", str(threads)], cwd=root, env=env,
                                     text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE)

    def ask(self, cmd: dict) -> dict:
        self.proc.stdin.write(json.dumps(cmd) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"bench_train: the worker of {self.label} ({self.root}) died")
        return json.loads(line)

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


@contextlib.contextmanager
def checkout(rev: str):
    """The tree of git revision `rev` in a temporary folder (git archive: no working-tree changes)."""
    with tempfile.TemporaryDirectory(prefix="bench_train_") as tmp:
        got = subprocess.run(["git", "-C", str(REPO), "archive", rev], capture_output=True)
        if got.returncode != 0:
            raise SystemExit(f"bench_train: --against {rev}: not a revision of {REPO} "
                             f"({got.stderr.decode(errors='replace').strip()})")
        subprocess.run(["tar", "-x", "-C", tmp], input=got.stdout, check=True)
        yield Path(tmp)


def fmt_row(label: str, method: str, phase: str, n: int, rows: list[dict]) -> str:
    med = {k: statistics.median(r[k] for r in rows) for k in ("total",) + PARTS}
    rest = max(med["total"] - sum(med[p] for p in PARTS), 0.0)
    parts = " | ".join(f"{1e3 * med[p]:.0f}" for p in PARTS)
    return (f"| {method} | {phase} | {label} | {n:,} | {1e3 * med['total']:.0f} | {1 / med['total']:.2f} | "
            f"{parts} | {1e3 * rest:.0f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="data/quick/hinge")
    ap.add_argument("--methods", nargs="+", default=["e4dgs", "e4dgs_rgb", "d3dgs"], choices=sorted(CONFIGS))
    ap.add_argument("--phases", nargs="+", default=["early", "late"], choices=["early", "late"])
    ap.add_argument("--gaussians", type=positive_int, default=20000, help="initial Gaussians (before pruning)")
    ap.add_argument("--iters", type=positive_int, default=12, help="timed iterations per cell and tree")
    ap.add_argument("--threads", type=int_in(1, 1024, "threads"), default=1, help="torch and numba threads of each worker")
    ap.add_argument("--against", default=None, metavar="REV", help="also time this git revision's tree")
    from recon.config import PRECISIONS

    ap.add_argument("--precisions", nargs="+", default=None, choices=list(PRECISIONS),
                    help="time this tree's deformation MLP once per train.precision value (default: the configs' own field)")
    ap.add_argument("--fields", nargs="+", default=[], choices=["mlp", "trajectory"],
                    help="also time this tree with train.deform_field.kind set to each of these")
    ap.add_argument("--coarse", nargs="+", type=int_in(1, 64, "a coarse factor"), default=[], metavar="FACTOR",
                    help="also time trajectory-field iterations of coarse-to-fine stages rendered at 1/FACTOR size")
    ap.add_argument("--model", type=existing_file, default=None, metavar="PT",
                    help="time every worker at this trained state (a run's model.pt or snapshots/iter_*.pt): its "
                         "Gaussians, and its field where a worker's is of the same kind and size (--phases is "
                         "then a label)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a config override of every worker, the --against revision's too (e.g. train.deform_field.width=128); repeatable")
    ap.add_argument("--worker", type=nonnegative_int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker is not None:
        worker(args.worker)
        return 0
    scene = str(Path(args.scene).resolve())
    if not (Path(scene) / "manifest.json").exists():
        print(f"bench_train: {args.scene}: no dataset here (make dataset SCENES={Path(scene).name})", file=sys.stderr)
        return 2
    with contextlib.ExitStack() as stack:
        from common.machine import cpu_summary

        from common.config import parse_set

        sets = parse_set(args.set)
        trees = [Tree(label, REPO, args.threads, {**sets, **overrides}, factor)
                 for label, overrides, factor in worker_specs(args.precisions, args.fields, args.coarse)]
        if args.against:   # the revision at full size and at each coarse factor asked for
            old_root = stack.enter_context(checkout(args.against))
            trees += [Tree(label, old_root, args.threads, overrides, f)
                      for label, overrides, f in revision_specs(args.against, args.coarse, sets)]
        print(f"Training iteration at the scene's resolution, {Path(scene).name}, {args.threads} thread(s), "
              f"deformation on, median of {args.iters} (ms; it/s); CPU: {cpu_summary()}")
        print("| method | model | tree | Gaussians | ms/it | it/s | raster fwd | raster bwd | MLP fwd | MLP bwd | "
              "trajectory fwd | data | optimiser | rest |")
        print("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        ratios, ratios_p = [], []
        for method in args.methods:
            for phase in args.phases:
                replies = [t.ask({"setup": method, "phase": phase, "scene": scene, "gaussians": args.gaussians,
                                  "factor": t.factor, **({"overrides": t.overrides} if t.overrides else {}),
                                  **({"model": str(Path(args.model).resolve())} if args.model else {})})
                           for t in trees]
                for t, r in zip(trees, replies):
                    if not r["recon"].startswith(str(t.root)):
                        raise RuntimeError(f"bench_train: the worker of {t.label} imported {r['recon']}")
                sizes = [r["gaussians"] for r in replies]
                rows = [[] for _ in trees]
                for _ in range(args.iters):
                    for i, t in enumerate(trees):
                        rows[i].append(t.ask({"iterate": 1}))
                for t, n, r, reply in zip(trees, sizes, rows, replies):
                    label = t.label + (f" -> {reply['precision']}" if t.precision == "auto" else "")
                    print(fmt_row(label, method, phase, n, r), flush=True)
                if args.precisions and len(args.precisions) > 1:
                    meds = {t.precision: statistics.median(x["total"] for x in r) for t, r in zip(trees, rows)
                            if t.precision}
                    base = args.precisions[0]
                    ratios_p.append((method, phase, ", ".join(f"{base} / {p} {meds[base] / meds[p]:.2f}"
                                                                for p in args.precisions[1:])))
                if args.against and not args.precisions and not args.fields:
                    med = [statistics.median(x["total"] for x in r) for r in rows]
                    half = len(trees) // 2      # this tree's workers, then the revision's, factor by factor
                    for i in range(half):
                        where = f" 1/{trees[i].factor}" if trees[i].factor > 1 else ""
                        ratios.append((method, phase + where, med[half + i] / med[i]))
        for t in trees:
            t.close()
    for method, phase, ratio in ratios:
        print(f"speed-up of this tree over {args.against}: {method} {phase}: {ratio:.2f}x")
    for method, phase, text in ratios_p:
        print(f"time per iteration, {method} {phase}: {text}")
    return 0


REPO_OF_TREE = Path(os.environ.get("E4DGS_BENCH_TREE", REPO))

if __name__ == "__main__":
    sys.exit(run_tool(main))
