"""D3DGS (Yang et al., CVPR 2024): deformable 3D Gaussians trained on RGB frames.

`frames: sharp` trains on the sharp training frames (the paper's "w/o blur"); `frames: <level>` on
that blur level's frames, each posed at its exposure centre ("w/ blur"). `channels: 1` trains on
grayscale (the dataset's gray frames; blurred frames converted the same way: Rec.709 luma of linear
light, sRGB-encoded). Loss: (1 - lambda) L1 + lambda D-SSIM with lambda = 0.2.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import torch

from scene_format.reader import DatasetError, FrameRecord, SceneDataset
from recon.config import TrainConfig
from recon.device import to_device
from recon.losses import photometric_loss
from recon.methods import register
from recon.raster import Camera
from recon.method import Method
from recon.dataset_views import load_frame, record_camera
from recon.coarse import coarse_camera, coarse_srgb


@dataclass
class TrainView:
    camera: Camera
    time: float            # normalised clip time in [0, 1]
    image: torch.Tensor    # [H, W, C]



@dataclass(frozen=True)
class D3DGSConfig:
    """D3DGS on the dataset's RGB frames: `frames: sharp` (the paper's "w/o blur") or a blur level
    ("w/ blur": the blurred frames, each at the pose of its exposure centre)."""
    frames: str = "sharp"  # sharp, or a blur level's name
    channels: Literal[1, 3] = 3       # 1: train on the grayscale frames
    lambda_dssim: float = 0.2  # D-SSIM's share of the photometric loss (3DGS: 0.2)
    train: TrainConfig = field(default_factory=TrainConfig)  # the training shared by every method

@register
class D3DGS(Method):
    name = "d3dgs"
    config_cls = D3DGSConfig
    blur_level_field = "frames"
    inputs = ("rgb",)

    def __init__(self, dataset: SceneDataset, cfg: D3DGSConfig):
        super().__init__(dataset, cfg)
        self.views = self.training_views()
        if not self.views:
            raise DatasetError(f"{dataset.dir}: no training frames for frames={cfg.frames!r}")
        channels = type(self).channels_of(cfg)
        for k, v in enumerate(self.views):        # a frame of another size would fail deep in the loss, or broadcast
            want = (v.camera.height, v.camera.width, channels)
            if tuple(v.image.shape) != want:
                raise DatasetError(f"{dataset.dir}: training view {k} (t = {v.time:.4f}) is {tuple(v.image.shape)} "
                                   f"(height, width, channels); its camera sees {want}")

    @classmethod
    def channels_of(cls, cfg: D3DGSConfig) -> int:
        return cfg.channels

    def to_device(self, device: torch.device) -> None:
        self.views = to_device(self.views, device)

    def training_records(self) -> list[FrameRecord]:
        if self.cfg.frames == "sharp":
            return self.dataset.frames("train")
        return self.dataset.blurred_frames(self.cfg.frames)

    def training_views(self) -> list[TrainView]:
        views = []
        for rec in self.training_records():
            img = torch.from_numpy(load_frame(self.dataset, rec, self.channels()))
            views.append(TrainView(record_camera(self.dataset, rec), rec.time, img))
        return views

    def step(self, trainer, iteration: int):
        view = self.views[trainer.next_index(len(self.views))]
        f = trainer.render_factor
        camera = coarse_camera(view.camera, f)
        out = trainer.model.render_output(camera, view.time, trainer.backend)
        if out.means2d.requires_grad:
            out.means2d.retain_grad()
        loss = photometric_loss(out.image, coarse_srgb(view.image, f), self.cfg.lambda_dssim)
        return loss, [(out, camera)]


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
D3DGSConfig.BOUNDS = {"lambda_dssim": (0.0, 1.0, "D-SSIM's share of the photometric loss")}
