"""Training E2VID / FireNet on simulated sequences (`e4dgs train-e2vid`).

Loss per step t of a sequence, averaged over steps and batch:
  lambda_l1 |I_t - Y_t| + lambda_lpips LPIPS(I_t, Y_t) + lambda_tc [t >= 1] M_t |I_t - W(I_{t-1})|
where W warps the previous output by the sequence's known motion (synth.flow_grid) and
M_t = exp(-tc_alpha |Y_t - W(Y_{t-1})|^2) masks pixels the motion model does not explain
(E2VID's temporal-consistency loss, with exact flow instead of estimated flow). LPIPS uses the
AlexNet backbone (the benchmark's offline LPIPS; AlexNet rather than VGG for CPU cost).

Data are a pure function of (seed, iteration), so a resumed run sees the same batches; the
checkpoint (network, Adam state, iteration, log) is written atomically every `checkpoint_every`.
"""
from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from e2vid.networks import FIRENET, NetConfig, build_network
from e2vid.official import save_checkpoint
from e2vid.synth import SynthConfig, make_batch
from e4dgs.config import dump_config
from e4dgs.fileio import atomic_output

VAL_SEED_BASE = 1 << 40            # validation sequences never overlap training seeds (< 2^40)


@dataclass(frozen=True)
class E2VIDTrainConfig:
    arch: Literal["firenet", "e2vid"] = "firenet"
    iterations: int = 1200
    batch_size: int = 4
    lr: float = 1e-3
    lr_final: float = 1e-4             # cosine decay to this
    grad_clip: float = 1.0
    lambda_l1: float = 1.0
    lambda_lpips: float = 1.0
    lambda_tc: float = 2.0
    tc_alpha: float = 50.0
    lpips_net: Literal["alex", "vgg", "none"] = "alex"
    seed: int = 0
    checkpoint_every: int = 50
    threads: int = 2
    synth: SynthConfig = field(default_factory=SynthConfig)


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


def sequence_loss(net, batch, cfg: E2VIDTrainConfig, lpips_fn) -> tuple[torch.Tensor, dict[str, float]]:
    states, prev = None, None
    parts = {"l1": 0.0, "lpips": 0.0, "tc": 0.0}
    total = 0.0
    T = batch.voxels.shape[0]
    for t in range(T):
        pred, states = net(batch.voxels[t], states)
        target = batch.targets[t]
        l1 = (pred - target).abs().mean()
        loss = cfg.lambda_l1 * l1
        parts["l1"] += l1.item() / T
        if lpips_fn is not None and cfg.lambda_lpips > 0:
            lp = lpips_fn(pred, target).mean()
            loss = loss + cfg.lambda_lpips * lp
            parts["lpips"] += lp.item() / T
        if t > 0 and cfg.lambda_tc > 0:
            w_pred, valid = warp(prev, batch.flow[t])
            w_gt, _ = warp(batch.targets[t - 1], batch.flow[t])
            mask = valid * torch.exp(-cfg.tc_alpha * (target - w_gt) ** 2)
            tc = (mask * (pred - w_pred).abs()).mean()
            loss = loss + cfg.lambda_tc * tc
            parts["tc"] += tc.item() / T
        total = total + loss / T
        prev = pred
    return total, parts


class E2VIDTrainer:
    def __init__(self, cfg: E2VIDTrainConfig, out_dir: str | Path, progress: bool = True):
        self.cfg, self.out, self.progress = cfg, Path(out_dir), progress
        torch.manual_seed(cfg.seed)
        self.net = build_network(net_config(cfg.arch))
        self.opt = torch.optim.Adam(self.net.parameters(), lr=cfg.lr)
        self.iteration, self.wall_s, self.log = 0, 0.0, []
        self.lpips = None
        if cfg.lpips_net != "none" and cfg.lambda_lpips > 0:
            from benchmark.metrics.lpips import LPIPS
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
                        "iteration": self.iteration, "wall_s": self.wall_s, "log": self.log}, tmp)

    def _load(self) -> bool:
        if not self.ckpt_path.exists():
            return False
        ck = torch.load(self.ckpt_path, map_location="cpu", weights_only=True)
        if ck["config"] != dump_config(self.cfg):
            raise ValueError(f"{self.ckpt_path}: made with a different config; use another --out or delete it")
        self.net.load_state_dict(ck["net"])
        self.opt.load_state_dict(ck["opt"])
        self.iteration, self.wall_s, self.log = ck["iteration"], ck["wall_s"], ck["log"]
        return True

    def run(self) -> torch.nn.Module:
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "config.yaml").write_text(dump_config(self.cfg))
        self._load()
        torch.set_num_threads(self.cfg.threads)
        self.net.train()
        bar = tqdm(total=self.cfg.iterations, initial=self.iteration, disable=not self.progress,
                   desc=f"train-e2vid {self.cfg.arch}")
        while self.iteration < self.cfg.iterations:
            t0 = time.perf_counter()
            batch = make_batch(train_seeds(self.cfg, self.iteration), self.cfg.synth)
            t_data = time.perf_counter() - t0
            for g in self.opt.param_groups:
                g["lr"] = self._lr(self.iteration)
            loss, parts = sequence_loss(self.net, batch, self.cfg, self.lpips)
            if not torch.isfinite(loss):
                raise FloatingPointError(f"non-finite loss at iteration {self.iteration}")
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.net.parameters(), self.cfg.grad_clip)
            self.opt.step()
            self.iteration += 1
            self.wall_s += time.perf_counter() - t0
            self.log.append({"iteration": self.iteration, "wall_s": round(self.wall_s, 2), "loss": round(loss.item(), 5),
                             **{k: round(v, 5) for k, v in parts.items()}, "data_s": round(t_data, 3),
                             "events_per_px": round(float(batch.n_events.mean()) / (batch.voxels.shape[-1] * batch.voxels.shape[-2]), 3)})
            bar.update(1)
            bar.set_postfix(loss=f"{loss.item():.4f}", l1=f"{parts['l1']:.3f}")
            if self.iteration % self.cfg.checkpoint_every == 0 or self.iteration == self.cfg.iterations:
                self._save()
        bar.close()
        with atomic_output(self.out / "log.jsonl") as tmp:
            tmp.write_text("".join(json.dumps(r) + "\n" for r in self.log))
        self.net.eval()
        return self.net

    def export(self, path: str | Path, report: dict | None = None) -> Path:
        info = {"iterations": self.iteration, "wall_s": round(self.wall_s, 1), "config": asdict(self.cfg)}
        return save_checkpoint(path, self.net, e4dgs_training=json.loads(json.dumps({**info, **(report or {})})))
