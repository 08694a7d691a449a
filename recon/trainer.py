"""The training loop every method shares: model set-up, Adam groups and schedules, warm-up,
densification, checkpoints with resume, the log, evaluation points and snapshots.

A method supplies the loss (`Method.step`) and its data; the trainer does the rest:

    out_dir/run.json            method, fingerprint, resolved config, scene; `precision`: the deformation's
                                dtype of each start (fresh or resumed) and how it was chosen (recon.precision)
    out_dir/checkpoint.pt       latest resumable state (atomic; removed when training finishes)
    out_dir/log.jsonl           rows {iteration, wall_s, loss, n_gaussians[, test_psnr, test_psnr_on: what it
                                compares: rgb, or gray after the gain/offset fit]} (wall_s: training
                                time only, evaluation and file writing excluded, summed over resumes;
                                the first row of each start also has `precision`)
    out_dir/snapshots/iter_XXXXXX.pt   models at the configured fractions of the budget
    out_dir/model.pt            the finished model
"""
from __future__ import annotations

import functools
import hashlib
import math
import json
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch
from tqdm import tqdm

from common import progress

from scene_format.reader import SceneDataset
from common.config import dump_config, to_dict
from common.checkpoint import torch_load
from common.fileio import atomic_output, output_lock
from recon.initial_points import initial_points_noting_fallback
from recon.config import TrainConfig
from recon.deform import make_field
from recon.densify import DensifyStats, densify_and_prune, reset_opacity
from recon.device import run_placement
from recon.scoring import checked_pairs, evaluate_psnr
from recon.gaussians import GaussianModel, position_lr
from recon.model import DynamicGaussians, ModelMeta, load
from recon.raster import warm_up
from recon.method import Method
from recon.precision import PrecisionChoice, resolve_precision
from recon.run_folder import ForeignRunError, RunFolder
from recon.dataset_views import gray_from_srgb
from recon.trajectory import acceleration_energy, acceleration_gram
from common.color import linear_to_srgb, rec709_luma

CHECKPOINT_FORMAT = "e4dgs-train-checkpoint/1"
BUNDLED_PACKAGES = ("recon", "benchmark", "e2vid")   # a method class defined elsewhere is a plug-in


class TrainingError(RuntimeError):
    """Training cannot go on (non-finite loss, every Gaussian pruned, a foreign output folder)."""


def scene_extent(dataset: SceneDataset) -> float:
    """3DGS's cameras_extent: 1.1 x the largest distance of a camera centre from their mean."""
    centres = np.concatenate([traj.c2w[:, :3, 3] for traj in dataset.cameras])
    return float(1.1 * np.linalg.norm(centres - centres.mean(0), axis=1).max())


def scene_background(dataset: SceneDataset, channels: int) -> list[float]:
    """The stored (sRGB) colour of the scene's empty background."""
    linear = np.asarray(dataset.scene.background_linear)
    if channels == 1:
        return [float(linear_to_srgb(rec709_luma(linear)))]
    return [float(c) for c in linear_to_srgb(linear)]


def fingerprint(method: str, cfg: Any, dataset: SceneDataset) -> str:
    h = hashlib.sha256()
    h.update(method.encode())
    h.update(dump_config(cfg).encode())
    h.update(dataset.manifest_bytes)
    return h.hexdigest()[:16]


def warn_static_schedule(tcfg: TrainConfig, sched) -> None:
    """A ConfigWarning when the budget ends before the deformation is switched on or before
    densification starts: the run would train a static (or never densified) model without a word."""
    import warnings

    from common.config import ConfigWarning

    n = tcfg.iterations
    if tcfg.deform and sched.warm_up >= n:
        warnings.warn(ConfigWarning(
            f"train.iterations = {n} ends before the deformation is switched on (warm-up {sched.warm_up} iterations): "
            "the model stays static; train longer or lower train.warm_up"), stacklevel=3)
    if tcfg.densify.enabled and sched.densify_start >= n:
        warnings.warn(ConfigWarning(
            f"train.iterations = {n} ends before densification starts (iteration {sched.densify_start}): the "
            "initial points are never densified"), stacklevel=3)


def warn_capped_densification(tcfg: TrainConfig, n_initial: int) -> None:
    """A ConfigWarning when the run starts with at least densify.max_gaussians Gaussians: no Gaussian
    is cloned or split until pruning brings the count below the cap (a room's 20k initial points
    under a 15k cap kept garage's models at their initial, blurry Gaussians; docs/design/recon.md)."""
    import warnings

    from common.config import ConfigWarning

    cap = tcfg.densify.max_gaussians
    if tcfg.densify.enabled and n_initial >= cap:
        warnings.warn(ConfigWarning(
            f"train.densify.max_gaussians = {cap} <= the {n_initial} initial Gaussians: nothing is cloned or "
            "split until pruning brings the count below it; raise max_gaussians or lower train.init.n_points_*"),
            stacklevel=3)


class Trainer:
    def __init__(self, method: Method, out_dir: str | Path, progress: bool = True,
                 on_iteration: Callable[["Trainer", int], None] | None = None):
        self.method = method
        self.dataset = method.dataset
        self.cfg = method.cfg
        self.tcfg: TrainConfig = method.cfg.train
        self.sched = self.tcfg.schedule()
        warn_static_schedule(self.tcfg, self.sched)
        self.out = Path(out_dir)
        self.progress = progress
        self.on_iteration = on_iteration
        self.fingerprint = fingerprint(method.name, self.cfg, self.dataset)
        self.folder = RunFolder(self.out, method.name, self.fingerprint)
        self.extent = scene_extent(self.dataset)
        self._gram = None      # the trajectories' acceleration Gram matrix, built at the first smoothness term
        self.init_fallback = None  # the initialisation used instead of the configured one, and why (run.json)
        self.device, self.backend = run_placement(self.tcfg.device, self.tcfg.backend)
        self.method.to_device(self.device)
        # the torch generator (split children) stays on the CPU: a seed draws the same on every device
        self.rng = np.random.default_rng(self.tcfg.seed)
        self.torch_gen = torch.Generator().manual_seed(self.tcfg.seed)
        self.log: list[dict] = []
        self.wall_s = 0.0
        self.iteration = 0
        self._order: list[int] = []
        self._start_iteration: int | None = None
        self.render_factor = 1     # this iteration's coarse-to-fine factor (train.coarse_to_fine)
        intr = self.dataset.intrinsics
        too_coarse = [f for f in self.tcfg.coarse_to_fine.factors if f > min(intr.width, intr.height)]
        if too_coarse:
            raise TrainingError(f"train.coarse_to_fine.factors: {too_coarse[0]} would render {self.dataset.dir.name}'s "
                                f"{intr.width}x{intr.height} images at {intr.width // too_coarse[0]}x"
                                f"{intr.height // too_coarse[0]} pixels; use factors up to {min(intr.width, intr.height)}")

    @functools.cached_property
    def precision(self) -> PrecisionChoice:
        """The deformation's dtype on this machine (train.precision; `auto` measured once per machine)."""
        fc = self.tcfg.deform_field
        return resolve_precision(self.tcfg.precision, self.device, field_kind=fc.kind, size=(fc.depth, fc.width))

    # -- set-up -----------------------------------------------------------------------------------
    def _new_model(self) -> DynamicGaussians:
        channels = self.method.channels()
        pts, self.init_fallback = initial_points_noting_fallback(self.dataset, self.tcfg)
        bg = list(self.tcfg.background) if self.tcfg.background is not None else scene_background(self.dataset, channels)
        if channels == 1 and len(bg) == 3:
            bg = [float(gray_from_srgb(np.asarray(bg)))]
        colors = np.tile(np.asarray(bg, np.float32), (len(pts), 1)) \
            if self.tcfg.init.color == "background" else None
        gaussians = GaussianModel.from_points(pts, colors=colors, sh_degree=self.tcfg.sh_degree, channels=channels,
                                              init_opacity=self.tcfg.init.init_opacity)
        torch.manual_seed(self.tcfg.seed)
        deform = make_field(self.tcfg.deform_field.spec())
        if deform.kind == "trajectory":
            gaussians.enable_motion(deform.n_basis)
        meta = ModelMeta(method=self.method.name, channels=channels, sh_degree=self.tcfg.sh_degree, background=bg,
                         extent=self.extent, duration_us=self.dataset.duration_us,
                         precision=self.precision.dtype, deform_field=deform.spec(), scene=self.dataset.scene.name,
                         config=to_dict(self.cfg))
        model = DynamicGaussians(gaussians, deform, meta, self.dataset.cameras)
        self.method.setup_model(model)
        return model.to(self.device)

    def initial_model(self) -> DynamicGaussians:
        """The untrained model a fresh run starts from (deterministic: the run builds the same one)."""
        return self._new_model()

    def setup(self) -> None:
        """A fresh model, its optimizer and densification statistics (iteration 0)."""
        self.model = self._new_model()
        self.optimizer = self.new_optimizer()
        self.stats = DensifyStats(len(self.model), self.device)

    def new_optimizer(self) -> torch.optim.Adam:
        """An Adam over every parameter group of the model (and the method's extras), at the config's rates."""
        g, lr = self.model.gaussians, self.tcfg.lr
        groups = [
            {"params": [g.means], "lr": lr.position_init * self.extent, "name": "means"},
            {"params": [g.sh_dc], "lr": lr.feature, "name": "sh_dc"},
            {"params": [g.sh_rest], "lr": lr.feature / 20.0, "name": "sh_rest"},
            {"params": [g.opacity_logits], "lr": lr.opacity, "name": "opacity"},
            {"params": [g.log_scales], "lr": lr.scaling, "name": "scaling"},
            {"params": [g.quats], "lr": lr.rotation, "name": "rotation"},
        ]
        if list(self.model.deform.parameters()):
            groups.append({"params": list(self.model.deform.parameters()), "lr": lr.position_init * lr.deform_scale,
                           "name": "deform"})
        if g.motion is not None:
            groups.append({"params": [g.motion], "lr": 0.0, "name": "motion"})
        groups += self.method.extra_parameters()
        # fused: one kernel over all parameters (2.7x faster on a CPU than the per-tensor loop, same update)
        return torch.optim.Adam(groups, lr=0.0, eps=1e-15, fused=True)

    def _update_lrs(self, it: int) -> None:
        lr = self.tcfg.lr
        for group in self.optimizer.param_groups:
            if group["name"] == "means":
                group["lr"] = position_lr(it, lr.position_init * self.extent, lr.position_final * self.extent,
                                          self.sched.position_lr_steps)
            elif group["name"] == "opacity" and lr.opacity_final is not None:
                group["lr"] = position_lr(it, lr.opacity, lr.opacity_final, self.tcfg.iterations)
            elif group["name"] == "deform":  # decays over the iterations after the warm-up
                warm = self.sched.warm_up
                group["lr"] = position_lr(it - warm, lr.position_init * lr.deform_scale, lr.position_final,
                                          max(self.sched.deform_lr_steps - warm, 1))
            elif group["name"] == "motion":  # trajectory coefficients: the means' rates, after the warm-up
                warm, k = self.sched.warm_up, self.tcfg.deform_field.lr_scale * self.extent
                group["lr"] = position_lr(it - warm, lr.position_init * k, lr.position_final * k,
                                          max(self.sched.deform_lr_steps - warm, 1))

    def next_index(self, n: int) -> int:
        """Training items in random order without replacement, reshuffled every epoch (seeded)."""
        if not self._order:
            self._order = self.rng.permutation(n).tolist()
        return self._order.pop()

    # -- checkpoints --------------------------------------------------------------------------------
    def _check_out_dir(self) -> None:
        try:
            self.folder.claim(self.dataset.dir, to_dict(self.cfg), dump_config(self.cfg))
        except ForeignRunError as exc:
            raise TrainingError(str(exc)) from None

    def _save_checkpoint(self) -> None:
        state = {"format": CHECKPOINT_FORMAT, "fingerprint": self.fingerprint, "iteration": self.iteration,
                 "wall_s": self.wall_s, "model": self.model.state(), "optimizer": self.optimizer.state_dict(),
                 "stats": self.stats.state_dict(), "method": self.method.state_dict(),
                 "rng": json.dumps(self.rng.bit_generator.state), "torch_rng": self.torch_gen.get_state(),
                 "order": list(self._order), "log": json.dumps(self.log)}
        with atomic_output(self.out / "checkpoint.pt") as tmp:
            torch.save(state, tmp)
        self._write_log()

    def _load_checkpoint(self) -> bool:
        path = self.out / "checkpoint.pt"
        if not path.exists():
            return False
        state = torch_load(path, "a training checkpoint (delete it to start the run again)")
        if not isinstance(state, dict) or state.get("format") != CHECKPOINT_FORMAT or state.get("fingerprint") != self.fingerprint:
            raise TrainingError(f"{path}: checkpoint of a different run; delete it or use another output folder")
        self.model = DynamicGaussians.from_state(state["model"], str(path)).to(self.device)
        self.method.load_state_dict(state["method"])
        self.optimizer = self.new_optimizer()
        self.optimizer.load_state_dict(state["optimizer"])   # moves Adam's moments to the parameters' device
        self.stats = DensifyStats(len(self.model), self.device)
        self.stats.load_state_dict(state["stats"])
        self.rng.bit_generator.state = json.loads(state["rng"])
        self.torch_gen.set_state(state["torch_rng"])
        self._order = list(state["order"])
        self.iteration, self.wall_s = int(state["iteration"]), float(state["wall_s"])
        self.log = json.loads(state["log"])
        return True

    def _write_log(self) -> None:
        self.folder.write_log(self.log)

    # -- evaluation -------------------------------------------------------------------------------
    def evaluate(self) -> float:
        records = self.dataset.frames("test")
        if self.tcfg.eval_max_views and len(records) > self.tcfg.eval_max_views:
            pick = np.linspace(0, len(records) - 1, self.tcfg.eval_max_views).round().astype(int)
            records = [records[i] for i in pick]
        return evaluate_psnr(checked_pairs(type(self.method), self.method.eval_pairs(self.model, records, self.backend),
                                           records, f"the test views of {self.dataset.dir}"))

    def psnr_target(self) -> str:
        """What test_psnr compares, as the log and the progress bar say: colour frames, or (a method that
        sees no RGB) gray frames after the per-image log gain / offset fit, which lifts even an
        untrained model well above 0 dB."""
        gray = self.method.channels() == 1
        corrected = type(self.method).correction(self.cfg) is not None
        return ("gray, after gain/offset fit" if corrected else "gray") if gray else (
            "rgb, after gain/offset fit" if corrected else "rgb")

    def _snapshot_iterations(self) -> set[int]:
        return {max(1, int(round(f * self.tcfg.iterations))) for f in self.tcfg.snapshots}

    # -- the loop ---------------------------------------------------------------------------------
    def run(self) -> DynamicGaussians:
        """Train to the budget (resuming a checkpoint), holding a lock on the output folder so two
        runs into one folder cannot interleave their checkpoints."""
        fresh = not self.folder.run_json.exists()
        with output_lock(self.out):
            try:
                return self._run()
            except BaseException:
                if fresh:
                    self.folder.remove_unresumable()
                raise

    # -- the steps of one run --------------------------------------------------------------------
    def _start(self) -> None:
        """Resume the checkpoint (saying so) or set up a fresh model; compile the rasterizer untimed."""
        if not self._load_checkpoint():
            self.setup()
            warn_capped_densification(self.tcfg, len(self.model))
            if self.init_fallback:         # said and kept: the run did not start from what its config asked
                tqdm.write(f"{self.method.name} {self.dataset.scene.name}: {self.init_fallback}")
                self.folder.record("init_fallback", self.init_fallback)
        else:                              # said even without progress bars: a job's log shows its resumes
            tqdm.write(f"{self.method.name}: resuming {self.out} at iteration {self.iteration} of "
                       f"{self.tcfg.iterations} ({self.wall_s:.0f} s trained so far)")
        tqdm.write(f"{self.method.name} {self.dataset.scene.name}: deformation in {self.precision.describe()}")
        self.model.meta.precision = self.precision.dtype
        self.folder.record_precision(self.iteration, self.precision.to_dict())
        self._start_iteration = self.iteration
        # kernel compilation (numba's first call, gsplat's CUDA build) is not training time
        warm_up(self.backend, self.device, self.method.channels())

    def _optimise(self, it: int):
        """Schedules for iteration `it`, the method's loss and its backward -> (loss value, renders)."""
        cfg, sched = self.tcfg, self.sched
        self._update_lrs(it)
        g = self.model.gaussians
        g.active_sh_degree = min(cfg.sh_degree, it // sched.sh_interval)
        self.model.meta.active_sh_degree = g.active_sh_degree
        self.model.meta.deform_enabled = cfg.deform and it > sched.warm_up
        self.render_factor = cfg.coarse_to_fine.factor_at(it, cfg.iterations)
        cls = type(self.method)
        who = f"method {self.method.name!r} (plug-in class {cls.__module__}.{cls.__qualname__})"
        try:
            out = self.method.step(self, it)
        except (TrainingError, KeyboardInterrupt):
            raise
        except Exception as exc:      # a plug-in's own failure: name the plug-in (the bundled methods' stay as they are)
            if cls.__module__.split(".")[0] in BUNDLED_PACKAGES:
                raise
            raise TrainingError(f"{who}: its step raised {type(exc).__name__}: {exc} at iteration {it}") from exc
        if not (isinstance(out, (tuple, list)) and len(out) == 2 and isinstance(out[0], torch.Tensor)
                and out[0].numel() == 1 and out[0].requires_grad and isinstance(out[1], (list, tuple))):
            got = (f"a {type(out).__name__}" if not isinstance(out, (tuple, list)) else
                   f"({', '.join(type(v).__name__ + (f' of shape {tuple(v.shape)}' if isinstance(v, torch.Tensor) else '') for v in out)})")
            raise TrainingError(f"{who}: its step returned {got} at iteration {it}; expected (loss, renders): a "
                                "one-value loss tensor that has a gradient, and a list of (RenderOutput, Camera)")
        loss, renders = out
        loss = loss + self._smoothness_term()
        loss_value = float(loss.detach())
        if not math.isfinite(loss_value):
            raise TrainingError(f"{self.method.name}: loss is {loss.item()} at iteration {it}; stopping "
                                "(the last checkpoint is kept)")
        loss.backward()
        return loss_value, renders

    def _smoothness_term(self):
        """train.deform_field.smoothness x the trajectories' mean acceleration energy / extent^2 while the
        deformation is on (0 otherwise)."""
        fc, model = self.tcfg.deform_field, self.model
        if not (fc.smoothness > 0 and model.meta.deform_enabled and model.gaussians.motion is not None):
            return 0.0
        if self._gram is None:
            self._gram = acceleration_gram(fc.degree, fc.fourier, model.gaussians.motion.dtype, self.device)
        energy = acceleration_energy(model.gaussians.motion, fc.degree, fc.fourier, self._gram)
        return fc.smoothness * energy / self.extent ** 2

    def _adapt_density(self, it: int, renders) -> dict:
        """Densification statistics, clone / split / prune (with the method's own pruning, E-4DGS's
        IIP) and opacity resets at their iterations; returns the counts (empty if nothing changed)."""
        cfg, sched, g = self.tcfg, self.sched, self.model.gaussians
        d = cfg.densify
        info = {}
        extra = self.method.prune_mask(self, it)
        densify_now = d.enabled and sched.densify_start < it < sched.densify_stop and it % sched.densify_interval == 0
        if d.enabled and it < sched.densify_stop:
            for out, cam in renders:   # radii in full-resolution pixels, whatever the render's factor
                self.stats.add(out, cam.width, cam.height, self.render_factor)
        if densify_now:
            if g.anchors is not None:  # deformation inputs follow the means between edits
                g.anchors = g.means.detach().clone()
            info = densify_and_prune(g, self.stats, d, self.extent, self.optimizer,
                                     prune_large=it > sched.opacity_reset_interval,
                                     generator=self.torch_gen, extra_prune=extra)
        elif extra is not None and bool(extra.any()):
            g.prune(~extra, self.optimizer)
            self.stats.keep(~extra)
            info = {"pruned": int(extra.sum())}
        if d.enabled and d.opacity_reset and it < sched.densify_stop and it % sched.opacity_reset_interval == 0:
            reset_opacity(g, self.optimizer)
        if len(g) == 0:
            raise TrainingError(f"{self.method.name}: every Gaussian was pruned at iteration {it} "
                                f"({info}); nothing is left to render")
        return info

    def _record(self, it: int, loss_value: float, info: dict, snaps: set[int]) -> dict:
        """The log row of iteration `it`, with test PSNR and a snapshot at their iterations."""
        cfg = self.tcfg
        row = {"iteration": it, "wall_s": round(self.wall_s, 3), "loss": round(loss_value, 6),
               "n_gaussians": len(self.model)}
        do_eval = it in snaps or (cfg.eval_every and it % cfg.eval_every == 0)
        if do_eval:
            self.model.meta.iteration = it
            row["test_psnr"] = round(self.evaluate(), 3)
            row["test_psnr_on"] = self.psnr_target()
            if it in snaps:
                self.model.save(self.out / "snapshots" / f"iter_{it:06d}.pt")
                row["snapshot"] = f"snapshots/iter_{it:06d}.pt"
        if info:
            row["densify"] = info
        first = self._start_iteration is not None and it == self._start_iteration + 1
        if first:
            row["precision"] = self.precision.dtype
        if self.render_factor != 1:
            row["render_factor"] = self.render_factor
        if do_eval or info or first or it % 10 == 0 or it == 1:
            self.log.append(row)
        return row

    def _run(self) -> DynamicGaussians:
        final = self.out / "model.pt"
        self._check_out_dir()
        if final.exists():
            return load(final)
        self._start()
        snaps = self._snapshot_iterations()
        bar = tqdm(total=self.tcfg.iterations, initial=self.iteration, disable=not self.progress,
                   desc=f"{self.method.name} {self.dataset.scene.name}", dynamic_ncols=True)
        while self.iteration < self.tcfg.iterations:
            it = self.iteration + 1
            t0 = time.perf_counter()
            loss_value, renders = self._optimise(it)
            with torch.no_grad():
                info = self._adapt_density(it, renders)
                self.optimizer.step()
                self.optimizer.zero_grad(set_to_none=True)
            self.wall_s += time.perf_counter() - t0
            self.iteration = it
            row = self._record(it, loss_value, info, snaps)
            bar.update(1)
            progress.report(it, self.tcfg.iterations, "it")       # the driver's view of a job run elsewhere
            bar.set_postfix(loss=f"{loss_value:.4f}", n=len(self.model),
                            **({f"psnr ({row['test_psnr_on']})": row["test_psnr"]} if "test_psnr" in row else {}))
            if it % self.tcfg.checkpoint_every == 0 and it < self.tcfg.iterations:
                self._save_checkpoint()
            if self.on_iteration is not None:
                self.on_iteration(self, it)
        bar.close()
        bad = self.model.non_finite()
        if bad:
            raise TrainingError(f"{self.method.name}: training ended with non-finite values in {', '.join(bad)}; no model "
                                "is saved (a learning rate too large?)")
        self.model.meta.iteration = self.iteration
        self.model.save(final)
        self._write_log()
        (self.out / "checkpoint.pt").unlink(missing_ok=True)
        return self.model
