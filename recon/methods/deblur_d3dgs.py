"""Deblur-D3DGS: the blur model of Deblur4DGS (Wu et al., 2024) on the D3DGS representation, the
paper's fourth baseline ("is it the events that help, or modelling the blur?").

Trained on one blur level's frames. Each blurred frame is predicted the way the dataset made it: the
mean in linear light of `blur_samples` renders spread from the first to the last rendered frame of
its exposure (camera poses and times known), against which the D3DGS photometric loss is taken.
Deblur4DGS's multi-resolution consistency is added: the sharp render at the exposure centre,
area-averaged over 4 x 4 blocks, is held to the blurred frame averaged the same way (L1, weight 1),
which anchors the low frequencies that blur leaves intact. What of Deblur4DGS does not apply is in
docs/design/recon.md (learned exposure spans and camera motion: ours are known; flow-aligned sub-frame
consistency: needs a pretrained optical-flow network; masks from a segmentation network).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import torch
import torch.nn.functional as F

from scene_format.reader import DatasetError, SceneDataset
from recon import event_supervision as ev
from common.config import ConfigError, check_positive
from recon.config import TrainConfig
from recon.device import to_device
from recon.losses import photometric_loss
from recon.methods import register
from recon.method import Method
from recon.dataset_views import blur_views
from recon.coarse import coarse_camera, coarse_srgb


def lowres_l1(render: torch.Tensor, target: torch.Tensor, factor: int) -> torch.Tensor:
    """L1 between images [H, W, C] area-averaged over factor x factor blocks (Deblur4DGS's
    multi-resolution consistency)."""
    pool = lambda im: F.avg_pool2d(im.permute(2, 0, 1)[None], factor, ceil_mode=True)  # noqa: E731
    return (pool(render) - pool(target)).abs().mean()



@dataclass(frozen=True)
class DeblurD3DGSConfig:
    """Deblur-D3DGS (the Deblur4DGS blur model on the D3DGS representation): trained on the frames of
    blur level `frames`, each predicted as the mean in linear light of `blur_samples` renders spread
    over its exposure (recon.event_supervision.exposure_mean), plus Deblur4DGS's multi-resolution consistency:
    lambda_lowres x L1 between the render at the exposure centre and the blurred frame, both
    area-averaged over lowres_factor x lowres_factor blocks (blur moves little at that scale)."""
    frames: str = "medium"  # the blur level trained on
    blur_samples: int = 5  # renders averaged over each exposure (odd)
    lambda_dssim: float = 0.2  # D-SSIM's share of the photometric loss
    lambda_lowres: float = 1.0  # weight of the low-resolution consistency term
    lowres_factor: int = 4  # its block size, pixels
    train: TrainConfig = field(default_factory=TrainConfig)

    def __post_init__(self):
        check_positive(self, "blur_samples", "lowres_factor")
        if self.blur_samples % 2 == 0:
            raise ConfigError(f"blur_samples: expected an odd count (the middle render is the sharp frame at the "
                              f"exposure centre), got {self.blur_samples}")
        if self.frames == "sharp":
            raise ConfigError("frames: Deblur-D3DGS trains on a blur level (mild, medium, strong), not 'sharp'")
        if self.lambda_lowres < 0 or not 0 <= self.lambda_dssim <= 1:
            raise ConfigError("lambda_lowres, lambda_dssim: expected lambda_lowres >= 0 and lambda_dssim in [0, 1]")

@register
class DeblurD3DGS(Method):
    name = "deblur_d3dgs"
    config_cls = DeblurD3DGSConfig
    blur_level_field = "frames"
    inputs = ("rgb",)

    def __init__(self, dataset: SceneDataset, cfg: DeblurD3DGSConfig):
        super().__init__(dataset, cfg)
        self.views = blur_views(dataset, cfg.frames, cfg.blur_samples, "mean", 3)
        if not self.views:
            raise DatasetError(f"{dataset.dir}: no blurred training frames at level {cfg.frames!r}")

    @classmethod
    def channels_of(cls, cfg: DeblurD3DGSConfig) -> int:
        return 3

    def to_device(self, device: torch.device) -> None:
        self.views = to_device(self.views, device)

    def step(self, trainer, iteration: int):
        cfg = self.cfg
        view = self.views[trainer.next_index(len(self.views))]
        f = trainer.render_factor
        cameras = [coarse_camera(c, f) for c in view.cameras]
        target = coarse_srgb(view.image, f)
        outs = [trainer.model.render_output(c, t, trainer.backend) for c, t in zip(cameras, view.times)]
        loss = photometric_loss(ev.exposure_mean([o.image for o in outs]), target, cfg.lambda_dssim)
        if cfg.lambda_lowres > 0:   # the middle render sits at the exposure centre (blur_samples is odd)
            low = max(1, cfg.lowres_factor // f)      # the same block size in full-resolution pixels
            loss = loss + cfg.lambda_lowres * lowres_l1(outs[len(outs) // 2].image, target, low)
        for out in outs:
            if out.means2d.requires_grad:
                out.means2d.retain_grad()
        return loss, list(zip(outs, cameras))


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
DeblurD3DGSConfig.BOUNDS = {
    "blur_samples": (1, 255, "renders per blurred frame"), "lambda_dssim": (0.0, 1.0, "D-SSIM's share of the loss"),
    "lambda_lowres": (0.0, 1e6, "a loss weight"), "lowres_factor": (1, 64, "pixels a block side"),
}
