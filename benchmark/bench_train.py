"""Training iterations per second of D3DGS at a scene's resolution (default: a quick-preset scene).

    python -m benchmark.bench_train [--scene data/quick/lego] [--counts 5000 20000 50000] [--iters 20] [--threads N]

For each Gaussian count, times full iterations (render, L1 + D-SSIM, backward, Adam step) in three
modes, alternated in one run: static (warm-up: no deformation), deformed with the MLP in float32,
and deformed under bfloat16 autocast. Prints medians in ms/iteration and iterations per second.
The model is the method's initial one (random points in a cube, opacity 0.1: a fog that covers
the image, so the rasterizer's share is larger than in a trained model) or, with --model, a
trained one. Learning rates are 0, so the model stays the same across the timed iterations, and
every mode renders the same view in a round.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time

import torch

import recon
from datagen.dataset import SceneDataset
from recon.methods import get_method
from recon.trainer import Trainer


def make_trainer(scene, n: int, out: str) -> Trainer:
    cfg = recon.resolve_config("d3dgs", overrides={"train.init.n_points_object": n, "train.init.n_points_room": n})
    trainer = Trainer(get_method("d3dgs")(SceneDataset(scene), cfg), out, progress=False)
    trainer.setup()
    return trainer


def freeze(trainer: Trainer) -> None:
    """Learning rates 0: every iteration costs what a training one does, but the model stays fixed."""
    for group in trainer.optimizer.param_groups:
        group["lr"] = 0.0


def one_iteration(trainer: Trainer, deform: bool, bf16: bool, view: int) -> float:
    trainer.model.meta.deform_enabled = deform
    trainer.model.meta.deform_bf16 = bf16
    trainer._order = [view]
    t0 = time.perf_counter()
    loss, _ = trainer.method.step(trainer, 1)
    loss.backward()
    with torch.no_grad():
        trainer.optimizer.step()
        trainer.optimizer.zero_grad(set_to_none=True)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="data/quick/lego")
    ap.add_argument("--counts", type=int, nargs="+", default=[5000, 20000, 50000])
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--threads", type=int, default=0, help="torch and numba threads (0: leave as is)")
    ap.add_argument("--model", default=None, help="time a trained model (model.pt) instead of the initial fog")
    args = ap.parse_args()
    if args.threads:
        import numba

        torch.set_num_threads(args.threads)
        numba.set_num_threads(args.threads)
    modes = {"static": (False, False), "deform fp32": (True, False), "deform bf16": (True, True)}
    intr = SceneDataset(args.scene).intrinsics
    print(f"D3DGS training iteration, {intr.width}x{intr.height}, torch threads {torch.get_num_threads()}, "
          f"median of {args.iters} (ms/it, it/s)")
    print(f"| Gaussians | {' | '.join(modes)} |")
    print("|---:|" + "---:|" * len(modes))
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.counts:
            trainer = make_trainer(args.scene, n, tmp)
            if args.model:
                from recon.model import load

                trained = load(args.model)
                trainer.model.gaussians, trainer.model.deform = trained.gaussians, trained.deform
                trainer.optimizer = trainer._optimizer()
                n = len(trained)
            freeze(trainer)
            n_views = len(trainer.method.views)
            for mode in modes.values():  # compile / warm caches
                one_iteration(trainer, *mode, 0)
            times = {name: [] for name in modes}
            for i in range(args.iters):   # the same view for every mode in a round
                view = (i * 7) % n_views
                for name, mode in modes.items():
                    times[name].append(one_iteration(trainer, *mode, view))
            cells = []
            for name in modes:
                ms = 1000 * statistics.median(times[name])
                cells.append(f"{ms:.0f} ms, {1000 / ms:.1f} it/s")
            print(f"| {n:,} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
