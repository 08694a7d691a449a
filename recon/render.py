"""Rendering a deformable Gaussian model at a time: deform, colour, rasterize."""
from __future__ import annotations

import numpy as np
import torch

from recon.deform import DeformationField
from recon.gaussians import GaussianModel
from recon.raster import Camera, RenderOutput, render


def camera_from_pose(K, c2w_opencv, width: int, height: int, dtype=torch.float32) -> Camera:
    """Raster camera from intrinsics K [3,3] and an OpenCV camera-to-world pose [4,4]."""
    c2w = np.asarray(c2w_opencv, np.float64)
    return Camera(torch.as_tensor(np.asarray(K, np.float64), dtype=dtype),
                  torch.as_tensor(np.linalg.inv(c2w), dtype=dtype), int(width), int(height))


def camera_center(camera: Camera) -> torch.Tensor:
    R, t = camera.world_to_cam[:3, :3], camera.world_to_cam[:3, 3]
    return -R.T @ t


def render_at(model: GaussianModel, field: DeformationField | None, camera: Camera, t: float,
              background: torch.Tensor, backend: str = "auto") -> RenderOutput:
    """Render the model deformed to normalised time t in [0, 1] (field None: the canonical model)."""
    means, quats, log_scales = model.means, model.quats, model.log_scales
    if field is not None:
        dx, dq, ds = field(means, t)
        means, quats, log_scales = means + dx, quats + dq, log_scales + ds
    colors = model.colors(camera_center(camera).to(means.dtype), means)
    return render(means, quats, torch.exp(log_scales), model.opacities, colors, camera, background, backend)
