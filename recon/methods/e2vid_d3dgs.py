"""E2VID + D3DGS, the paper's weakest baseline: reconstruct each camera's intensity video from its
events with a recurrent network (E2VID / FireNet, `e2vid/`), then train D3DGS on those frames.

The network runs once per camera over the whole event stream, with outputs at the sorted timestamps
of that camera's training frames (the dataset's RGB timestamps); frames are grayscale, so the model
is too. Like the events-only E-4DGS, its intensity scale is arbitrary, so by default predictions
are scored after the same colour correction (`color_correct`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from scene_format.reader import SceneDataset
from e2vid.networks import Reconstructor
from e2vid.official import load_checkpoint
from e2vid.reconstruct import reconstruct_frames
from e2vid.weights import default_weights_path
from common.color_correction import correct_colors
from recon.config import TrainConfig
from recon.methods import register
from recon.methods.d3dgs import D3DGS, TrainView
from recon.dataset_views import record_camera
from eventio.event_file import EventFile


def reconstruct_camera(dataset: SceneDataset, camera: int, t_us: np.ndarray, net: torch.nn.Module | None = None,
                       events_per_window: int = 0) -> np.ndarray:
    """Frames [K, H, W] in [0, 1] of camera `camera` at the sorted times t_us (net: the shipped one if None)."""
    if net is None:
        net, _ = load_checkpoint(default_weights_path())
    with EventFile(dataset.event_file(camera)) as ev:
        stream = ev.stream()
    return reconstruct_frames(Reconstructor(net), stream.events, stream.width, stream.height,
                              np.asarray(t_us, np.int64), events_per_window or None, net.cfg.num_bins)



@dataclass(frozen=True)
class E2VIDD3DGSConfig:
    """E2VID + D3DGS: each camera's events -> intensity frames at its training frames' timestamps
    (a recurrent network run over the whole stream), then D3DGS on those frames (grayscale).
    `weights: ""` is the network this project trained (e2vid/weights/); any official-layout file
    (e.g. E2VID_lightweight.pth.tar) works too. events_per_window 0: one window per frame interval."""
    weights: str = ""  # the E2VID network's weights file ("": the bundled one)
    events_per_window: int = 0  # events per E2VID window (0: one window per frame interval)
    lambda_dssim: float = 0.2  # D-SSIM's share of the photometric loss
    color_correct: bool = True       # score after the same log-intensity gain/offset fit as E-4DGS
    train: TrainConfig = field(default_factory=TrainConfig)

@register
class E2VIDD3DGS(D3DGS):
    name = "e2vid_d3dgs"
    config_cls = E2VIDD3DGSConfig
    blur_level_field = None        # trains on frames reconstructed from events: blur cannot change it
    inputs = ("events",)

    @classmethod
    def channels_of(cls, cfg: E2VIDD3DGSConfig) -> int:
        return 1

    @classmethod
    def input_files(cls, cfg: E2VIDD3DGSConfig) -> dict[str, Path]:
        return {"weights": Path(cfg.weights or default_weights_path())}

    def training_records(self):
        return self.dataset.frames("train")

    def training_views(self) -> list[TrainView]:
        records = self.training_records()
        views = []
        net, _ = load_checkpoint(self.cfg.weights or default_weights_path())   # once, for every camera
        with torch.no_grad():
            for cam in sorted({r.camera for r in records}):
                recs = sorted((r for r in records if r.camera == cam), key=lambda r: r.t_us)
                frames = reconstruct_camera(self.dataset, cam, np.array([r.t_us for r in recs]),
                                            net, self.cfg.events_per_window)
                views += [TrainView(record_camera(self.dataset, r), r.time, torch.from_numpy(f[..., None].copy()))
                          for r, f in zip(recs, frames)]
        return views

    @classmethod
    def correction(cls, cfg: E2VIDD3DGSConfig):
        return (lambda pred, gt: correct_colors(pred, gt)[0]) if cfg.color_correct else None


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
E2VIDD3DGSConfig.BOUNDS = {
    "events_per_window": (0, 100_000_000, "events; 0 never splits"), "lambda_dssim": (0.0, 1.0, "D-SSIM's share of the loss"),
}
