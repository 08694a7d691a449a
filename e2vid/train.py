"""Training E2VID / FireNet on simulated sequences (`e4dgs train-e2vid`).

Loss per step t of a sequence, averaged over steps and batch:
  lambda_l1 |I_t - Y_t| + lambda_lpips LPIPS(I_t, Y_t) + lambda_tc [t >= 1] M_t |I_t - W(I_{t-1})|
where W warps the previous output by the sequence's known motion (synth.flow_grid) and
M_t = exp(-tc_alpha |Y_t - W(Y_{t-1})|^2) masks pixels the motion model does not explain
(E2VID's temporal-consistency loss, with exact flow instead of estimated flow). LPIPS uses the
AlexNet backbone (the benchmark's offline LPIPS; AlexNet rather than VGG for CPU cost), and only
from iteration `lpips_start`: LPIPS scores a sign-inverted copy of a low-contrast target far better
than a flat or blurred one (0.23 against 0.60 and 0.36 on a training clip), and from scratch it
pulled FireNet into inverted reconstructions (monitor correlation -0.55 after 200 optimiser steps,
+0.45 with L1 alone). The exported weights are those with the best monitor correlation (held-out
clips, disjoint from the report's), recorded with their iteration.

Sequences are long (32 steps by default) and trained with truncated back-propagation through time:
every `tbptt` steps the loss is back-propagated and the recurrent state carried on, detached. A
network only learns to reconstruct intensity if it sees enough events to integrate: with 8-step
sequences from a zero state FireNet learned the mean brightness and no structure (correlation with
the ground truth about 0); see e2vid/weights/README.md.

Data are a pure function of (seed, iteration), so a resumed run sees the same batches; batches are
made `data_workers` background processes ahead of the optimiser (the simulator, not the network,
dominates the cost on a CPU). The checkpoint (network, Adam state, iteration, log) is written
atomically every `checkpoint_every` iterations (sequence batches).
"""
from __future__ import annotations

import json
import math
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from e2vid.evaluate import mean_correlation, monitor_sequences
from e2vid.networks import FIRENET, NetConfig, build_network
from e2vid.official import save_checkpoint
from e2vid.synth import VAL_SEED_BASE, Sequence, SynthConfig, make_batch
from common.checkpoint import torch_load
from common.config import MAX_ITERATIONS, SEED_RANGE, ConfigError, check_positive, dump_config
from common.fileio import atomic_output


@dataclass(frozen=True)
class E2VIDTrainConfig:
    arch: Literal["firenet", "e2vid"] = "firenet"
    iterations: int = 1000             # sequence batches; each gives ceil(n_steps / tbptt) optimiser steps
    batch_size: int = 4
    tbptt: int = 8                     # steps per backward pass (truncated back-propagation through time)
    lr: float = 1e-3
    lr_final: float = 1e-4             # cosine decay to this
    grad_clip: float = 1.0
    lambda_l1: float = 1.0
    lambda_lpips: float = 0.5
    lpips_start: int = 600             # iteration from which the LPIPS term counts (see the module docstring)
    lambda_tc: float = 2.0
    tc_alpha: float = 50.0
    lpips_net: Literal["alex", "vgg", "none"] = "alex"
    seed: int = 0
    checkpoint_every: int = 50
    threads: int = 1                   # torch threads; the other core makes data
    data_workers: int = 1              # background processes making batches ahead (0: inline)
    monitor_every: int = 25            # iterations between held-out correlation checks (0: never)
    monitor_sequences: int = 4
    monitor_size: tuple[int, int] = (96, 96)   # (height, width) of the monitor clips, 24 steps each
    synth: SynthConfig = field(default_factory=SynthConfig)

    def __post_init__(self):
        check_positive(self, "iterations", "batch_size", "tbptt", "lr", "checkpoint_every", "threads",
                       "monitor_sequences")
        for name in ("lpips_start", "data_workers", "monitor_every"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{name}: expected a value >= 0, got {getattr(self, name)!r}")


def net_config(arch: str) -> NetConfig:
    return FIRENET if arch == "firenet" else NetConfig()


def train_seeds(cfg: E2VIDTrainConfig, iteration: int) -> list[int]:
    base = (cfg.seed * 1_000_003 + iteration) * cfg.batch_size
    return [int(base + b) % VAL_SEED_BASE for b in range(cfg.batch_size)]


def warp(img: torch.Tensor, grid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """img [N, 1, H, W] sampled at grid [N, H, W, 2] -> (warped, valid mask [N, 1, H, W])."""
    warped = F.grid_sample(img, grid, mode="bilinear", padding_mode="border", align_corners=False)
    valid = (grid.abs() <= 1).all(-1, keepdim=True).permute(0, 3, 1, 2).to(img.dtype)
    return warped, valid


def sequence_loss(net, batch: Sequence, cfg: E2VIDTrainConfig, lpips_fn, t0: int = 0, t1: int | None = None,
                  states=None, prev: torch.Tensor | None = None):
    """Mean loss over steps [t0, t1) of `batch` ([T, N, ...] tensors), starting from recurrent `states` and
    the previous step's output `prev` (both None at a sequence's start).
    Returns (loss, parts, states, last output) so the caller can carry on with the next chunk."""
    t1 = batch.voxels.shape[0] if t1 is None else t1
    parts = {"l1": 0.0, "lpips": 0.0, "tc": 0.0}
    total = 0.0
    n = t1 - t0
    for t in range(t0, t1):
        pred, states = net(batch.voxels[t], states)
        target = batch.targets[t]
        l1 = (pred - target).abs().mean()
        loss = cfg.lambda_l1 * l1
        parts["l1"] += l1.item() / n
        if lpips_fn is not None and cfg.lambda_lpips > 0:
            lp = lpips_fn(pred, target).mean()
            loss = loss + cfg.lambda_lpips * lp
            parts["lpips"] += lp.item() / n
        if t > 0 and prev is not None and cfg.lambda_tc > 0:
            w_pred, valid = warp(prev, batch.flow[t])
            w_gt, _ = warp(batch.targets[t - 1], batch.flow[t])
            mask = valid * torch.exp(-cfg.tc_alpha * (target - w_gt) ** 2)
            tc = (mask * (pred - w_pred).abs()).mean()
            loss = loss + cfg.lambda_tc * tc
            parts["tc"] += tc.item() / n
        total = total + loss / n
        prev = pred
    return total, parts, states, prev


class _Batches:
    """Training batches by iteration, made `workers` processes ahead (inline when workers == 0)."""

    def __init__(self, cfg: E2VIDTrainConfig):
        self.cfg, self.pending = cfg, {}
        self.pool = (ProcessPoolExecutor(cfg.data_workers, mp_context=multiprocessing.get_context("spawn"))
                     if cfg.data_workers > 0 else None)

    def get(self, it: int) -> Sequence:
        if self.pool is None:
            return make_batch(train_seeds(self.cfg, it), self.cfg.synth)
        for ahead in range(it, min(it + self.cfg.data_workers + 1, self.cfg.iterations)):
            if ahead not in self.pending:
                self.pending[ahead] = self.pool.submit(make_batch, train_seeds(self.cfg, ahead), self.cfg.synth)
        return self.pending.pop(it).result()

    def close(self) -> None:
        if self.pool is not None:
            for f in self.pending.values():
                f.cancel()
            self.pool.shutdown(wait=True, cancel_futures=True)


class E2VIDTrainer:
    def __init__(self, cfg: E2VIDTrainConfig, out_dir: str | Path, progress: bool = True):
        self.cfg, self.out, self.progress = cfg, Path(out_dir), progress
        torch.manual_seed(cfg.seed)
        self.net = build_network(net_config(cfg.arch))
        self.opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr)
        self.iteration, self.wall_s, self.log = 0, 0.0, []
        self.best: dict | None = None          # {iteration, monitor_corr, net}: best by monitor correlation
        self.lpips = None
        if cfg.lpips_net != "none" and cfg.lambda_lpips > 0:
            from common.metrics.lpips import LPIPS
            self.lpips = LPIPS(cfg.lpips_net)

    @property
    def ckpt_path(self) -> Path:
        return self.out / "checkpoint.pt"

    def _lr(self, it: int) -> float:
        c = self.cfg
        return float(c.lr_final + 0.5 * (c.lr - c.lr_final) * (1 + np.cos(np.pi * min(it / max(c.iterations, 1), 1.0))))

    def _save(self) -> None:
        with atomic_output(self.ckpt_path) as tmp:
            torch.save({"config": dump_config(self.cfg), "net": self.net.state_dict(), "opt": self.opt.state_dict(),
                        "iteration": self.iteration, "wall_s": self.wall_s, "log": self.log, "best": self.best}, tmp)

    def _load(self) -> bool:
        if not self.ckpt_path.exists():
            return False
        ck = torch_load(self.ckpt_path, "an E2VID training checkpoint (delete it to start again)")
        if not isinstance(ck, dict) or ck.get("config") != dump_config(self.cfg):
            raise ValueError(f"{self.ckpt_path}: made with a different config; use another --out or delete it")
        self.net.load_state_dict(ck["net"])
        self.opt.load_state_dict(ck["opt"])
        self.iteration, self.wall_s, self.log = ck["iteration"], ck["wall_s"], ck["log"]
        self.best = ck.get("best")
        return True

    def run(self) -> torch.nn.Module:
        c = self.cfg
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "config.yaml").write_text(dump_config(c))
        self._load()
        torch.set_num_threads(c.threads)
        monitor = (monitor_sequences(c.monitor_sequences, SynthConfig(height=c.monitor_size[0], width=c.monitor_size[1],
                                                                      n_steps=24, num_bins=c.synth.num_bins))
                   if c.monitor_every > 0 else [])
        self.net.train()
        bar = tqdm(total=c.iterations, initial=self.iteration, disable=not self.progress, desc=f"train-e2vid {c.arch}")
        batches = _Batches(c)
        try:
            while self.iteration < c.iterations:
                self._step(batches, monitor)
                bar.update(1)
                bar.set_postfix(loss=f"{self.log[-1]['loss']:.4f}", corr=f"{self._last_corr():.3f}")
                if self.iteration % c.checkpoint_every == 0 or self.iteration == c.iterations:
                    self._save()
        finally:
            batches.close()
            bar.close()
        with atomic_output(self.out / "log.jsonl") as tmp:
            tmp.write_text("".join(json.dumps(r) + "\n" for r in self.log))
        self.net.eval()
        return self.net

    def _step(self, batches: _Batches, monitor: list) -> None:
        """One sequence batch: ceil(T / tbptt) optimiser steps with the state carried across them."""
        c = self.cfg
        t_start = time.perf_counter()
        batch = batches.get(self.iteration)
        t_data = time.perf_counter() - t_start
        for g in self.opt.param_groups:
            g["lr"] = self._lr(self.iteration)
        T = batch.voxels.shape[0]
        states, prev, sums = None, None, {"loss": 0.0, "l1": 0.0, "lpips": 0.0, "tc": 0.0}
        lpips_fn = self.lpips if self.iteration >= c.lpips_start else None
        for t0 in range(0, T, c.tbptt):
            t1 = min(t0 + c.tbptt, T)
            loss, parts, states, prev = sequence_loss(self.net, batch, c, lpips_fn, t0, t1, states, prev)
            if not torch.isfinite(loss):
                raise FloatingPointError(f"non-finite loss at iteration {self.iteration}, steps {t0}-{t1}")
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.net.parameters(), c.grad_clip)
            self.opt.step()
            states, prev = [s.detach() for s in states], prev.detach()
            w = (t1 - t0) / T
            sums["loss"] += loss.item() * w
            for k, v in parts.items():
                sums[k] += v * w
        self.iteration += 1
        row = {"iteration": self.iteration, **{k: round(v, 5) for k, v in sums.items()}, "data_wait_s": round(t_data, 3),
               "events_per_px": round(float(batch.n_events.mean()) / (batch.voxels.shape[-1] * batch.voxels.shape[-2]), 3)}
        if monitor and (self.iteration % c.monitor_every == 0 or self.iteration == c.iterations):
            row["monitor_corr"] = round(mean_correlation(self.net, monitor), 4)
            if self.best is None or row["monitor_corr"] > self.best["monitor_corr"]:
                self.best = {"iteration": self.iteration, "monitor_corr": row["monitor_corr"],
                             "net": {k: v.detach().clone() for k, v in self.net.state_dict().items()}}
        self.wall_s += time.perf_counter() - t_start
        self.log.append({"wall_s": round(self.wall_s, 2), **row})

    def _last_corr(self) -> float:
        return next((r["monitor_corr"] for r in reversed(self.log) if "monitor_corr" in r), math.nan)

    def use_best(self) -> dict:
        """Load the weights with the best monitor correlation (if monitored); returns {iteration, monitor_corr}."""
        if self.best is None:
            return {"iteration": self.iteration, "monitor_corr": None}
        self.net.load_state_dict(self.best["net"])
        self.net.eval()
        return {"iteration": self.best["iteration"], "monitor_corr": self.best["monitor_corr"]}

    def export(self, path: str | Path, report: dict | None = None) -> Path:
        info = {"iterations": self.iteration, "wall_s": round(self.wall_s, 1), "config": asdict(self.cfg)}
        return save_checkpoint(path, self.net, e4dgs_training=json.loads(json.dumps({**info, **(report or {})})))


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
E2VIDTrainConfig.BOUNDS = {
    "iterations": (1, MAX_ITERATIONS, "iterations"), "batch_size": (1, 4096, "sequences"), "tbptt": (1, 1024, "steps"),
    "lr": (0.0, 10.0, "a learning rate"), "lr_final": (0.0, 10.0, "a learning rate"), "grad_clip": (0.0, 1e6, "a norm"),
    "lambda_l1": (0.0, 1e6, "a loss weight"), "lambda_lpips": (0.0, 1e6, "a loss weight"),
    "lpips_start": (0, MAX_ITERATIONS, "iterations"), "lambda_tc": (0.0, 1e6, "a loss weight"),
    "tc_alpha": (0.0, 1e6, "the temporal loss's decay"), "seed": SEED_RANGE,
    "checkpoint_every": (0, MAX_ITERATIONS, "iterations"), "threads": (1, 1024, "threads"),
    "data_workers": (0, 1024, "processes"), "monitor_every": (0, MAX_ITERATIONS, "iterations"),
    "monitor_sequences": (0, 10_000, "sequences"),
}
