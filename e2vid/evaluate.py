"""Held-out quality of an events-to-video network on simulated sequences, against the high-pass filter.

Sequences come from seeds >= synth.VAL_SEED_BASE (never used for training), are longer than the
training sequences and at a different size. Scores are per-frame PSNR / SSIM against the sharp
frames, averaged, skipping the first `skip` frames (every method needs events before it can show
anything). The network is scored raw and after the log-intensity gain/offset fit E-4DGS is scored
with (common.color_correction); the high-pass filter, whose output has no absolute level, only after the fit.
PSNR and SSIM on low-contrast clips are dominated by the mean level (a flat grey image scores well),
so `corr`, the per-frame Pearson correlation with the ground truth, reports structure alone.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
from tqdm import tqdm

from common.metrics.image import score_pairs
from e2vid.networks import Reconstructor
from e2vid.reconstruct import hpf_display, hpf_log_frames
from e2vid.synth import VAL_SEED_BASE, SynthConfig, make_sequence
from common.color_correction import correct_colors

HELDOUT = SynthConfig(height=112, width=144, n_steps=24)


def _corrected(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    return correct_colors(pred[..., None], gt[..., None])[0][..., 0]


def correlation(pred: np.ndarray, gt: np.ndarray) -> float:
    """Pearson correlation of two images: structure regardless of gain and offset (0 for a flat image)."""
    a = pred.astype(np.float64).ravel() - pred.mean()
    b = gt.astype(np.float64).ravel() - gt.mean()
    den = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / den) if den > 1e-12 else 0.0


MONITOR_SEED_OFFSET = 1 << 20     # training-time monitor clips: held-out seeds, disjoint from the report's


def monitor_sequences(n: int, cfg: SynthConfig) -> list:
    """`n` held-out clips for tracking structure (correlation) while training."""
    return [make_sequence(VAL_SEED_BASE + MONITOR_SEED_OFFSET + i, cfg) for i in range(n)]


def mean_correlation(net: torch.nn.Module, sequences: list, skip: int = 4) -> float:
    """Mean per-frame correlation of the network's output with the ground truth, from a zero state per clip,
    skipping each clip's first `skip` frames."""
    was_training = net.training
    net.eval()
    scores = []
    with torch.no_grad():
        for seq in sequences:
            states = None
            for t in range(seq.voxels.shape[0]):
                pred, states = net(seq.voxels[t][None], states)
                if t >= skip:
                    scores.append(correlation(pred[0, 0].numpy(), seq.targets[t, 0].numpy()))
    net.train(was_training)
    return float(np.mean(scores)) if scores else 0.0


def evaluate_heldout(net: torch.nn.Module, n_sequences: int = 8, cfg: SynthConfig = HELDOUT, skip: int = 4,
                     hpf_cutoff_rad_s: float = 30.0, progress: bool = False) -> dict:
    net = net.eval()
    pairs = {"network": [], "network_corrected": [], "hpf_corrected": []}
    for i in tqdm(range(n_sequences), disable=not progress, desc="held-out"):
        seq = make_sequence(VAL_SEED_BASE + i, replace(cfg, num_bins=net.cfg.num_bins))
        recon = Reconstructor(net)
        hpf = hpf_log_frames(np.concatenate(seq.events), cfg.width, cfg.height, seq.t_end_us, hpf_cutoff_rad_s)
        for t in range(seq.voxels.shape[0]):
            img = recon(seq.voxels[t]).numpy()
            if t < skip:
                continue
            gt = seq.targets[t, 0].numpy()
            pairs["network"].append((img, gt))
            pairs["network_corrected"].append((_corrected(img, gt), gt))
            pairs["hpf_corrected"].append((_corrected(hpf_display(hpf[t]), gt), gt))
    report = {k: {**score_pairs(v, lpips_net=None), "corr": float(np.mean([correlation(p, g) for p, g in v]))}
              for k, v in pairs.items()}
    report["hpf_cutoff_rad_s"] = hpf_cutoff_rad_s
    report["sequences"] = {"n": n_sequences, "steps": cfg.n_steps, "size": [cfg.height, cfg.width], "skip": skip,
                           "seed_base": VAL_SEED_BASE}
    return report
