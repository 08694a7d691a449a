"""D3DGS (Yang et al., CVPR 2024): deformable 3D Gaussians trained on RGB frames.

`frames: sharp` trains on the sharp training frames (the paper's "w/o blur"); `frames: <level>` on
that blur level's frames, each posed at its exposure centre ("w/ blur"). `channels: 1` trains on
grayscale (the dataset's gray frames; blurred frames converted the same way: Rec.709 luma of linear
light, sRGB-encoded). Loss: (1 - lambda) L1 + lambda D-SSIM with lambda = 0.2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from datagen.dataset import DatasetError, FrameRecord, SceneDataset
from recon.config import D3DGSConfig
from recon.losses import photometric_loss
from recon.methods import register
from recon.model import DynamicGaussians
from recon.raster import Camera
from recon.render import camera_from_pose
from recon.trainer import Method
from simulator.pixel import linear_to_srgb, rec709_luma, srgb_to_linear


def gray_from_srgb(rgb: np.ndarray) -> np.ndarray:
    """[H, W, 3] sRGB in [0, 1] -> [H, W] sRGB-encoded luma of the linear light."""
    return linear_to_srgb(rec709_luma(srgb_to_linear(rgb))).astype(np.float32)


def load_frame(dataset: SceneDataset, rec: FrameRecord, channels: int) -> np.ndarray:
    """Frame [H, W, channels] in [0, 1] (sRGB-encoded as stored)."""
    if channels == 3:
        img = dataset.load_image(rec.path)
        if img.ndim != 3:
            raise DatasetError(f"{rec.path}: expected an RGB image")
        return img
    img = dataset.load_image(rec.gray_path) if rec.gray_path is not None else dataset.load_image(rec.path)
    return (gray_from_srgb(img) if img.ndim == 3 else img)[..., None]


def record_camera(dataset: SceneDataset, rec: FrameRecord) -> Camera:
    intr = dataset.intrinsics
    return camera_from_pose(intr.K, dataset.pose(rec.camera, rec.t_us), intr.width, intr.height)


@dataclass
class TrainView:
    camera: Camera
    time: float            # normalised clip time in [0, 1]
    image: torch.Tensor    # [H, W, C]


@register
class D3DGS(Method):
    name = "d3dgs"
    config_cls = D3DGSConfig

    def __init__(self, dataset: SceneDataset, cfg: D3DGSConfig):
        super().__init__(dataset, cfg)
        self.views = self.training_views()
        if not self.views:
            raise DatasetError(f"{dataset.dir}: no training frames for frames={cfg.frames!r}")

    def channels(self) -> int:
        return self.cfg.channels

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
        out = trainer.model.render_output(view.camera, view.time, trainer.tcfg.backend)
        if out.means2d.requires_grad:
            out.means2d.retain_grad()
        loss = photometric_loss(out.image, view.image, self.cfg.lambda_dssim)
        return loss, [(out, view.camera)]

    def eval_pairs(self, model: DynamicGaussians, records):
        pairs = []
        for rec in records:
            pred = model.render(record_camera(self.dataset, rec), rec.time).numpy()
            pairs.append((pred, load_frame(self.dataset, rec, self.channels())))
        return pairs
