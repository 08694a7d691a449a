"""Camera and render-output types of the Gaussian rasterizer (OpenCV camera axes)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import torch

NEAR_PLANE = 0.01          # Gaussians with camera depth below this are culled
LOWPASS = 0.3              # screen-space dilation added to the 2-D covariance (pixels^2)
ALPHA_MIN = 1.0 / 255.0    # contributions below this alpha are skipped
ALPHA_MAX = 0.99           # alpha is capped here
T_MIN = 1e-4               # a pixel stops when its transmittance would fall below this
TILE = 16                  # tile size of the binned rasterizers (pixels)


@dataclass
class Camera:
    """Pinhole camera: K [3,3] (pixel (u, v) samples the image plane at (u + 0.5, v + 0.5)),
    world_to_cam [4,4] in OpenCV axes (x right, y down, z forward), image size."""
    K: torch.Tensor
    world_to_cam: torch.Tensor
    width: int
    height: int

    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None) -> "Camera":
        """The same camera with K and world_to_cam in `dtype` on `device` (None: unchanged)."""
        return Camera(self.K.to(device=device, dtype=dtype), self.world_to_cam.to(device=device, dtype=dtype),
                      self.width, self.height)


@dataclass
class RenderOutput:
    image: torch.Tensor        # [H, W, C] composited colour + transmittance * background
    alpha: torch.Tensor        # [H, W] 1 - final transmittance
    depth: torch.Tensor        # [H, W] sum of weight * camera depth (divide by alpha for the mean depth)
    radii: torch.Tensor        # [N] int, 3-sigma screen radius in pixels, 0 when culled
    means2d: torch.Tensor      # [N, 2] projected centres (pixels); its .grad is what densification reads
    # [N] largest alpha * transmittance the Gaussian contributed to any pixel, or a function computing
    # it on first use (the gsplat backend, where it costs an extra pass)
    max_weight_or_fn: torch.Tensor | Callable[[], torch.Tensor] | None

    @property
    def max_weight(self) -> torch.Tensor:
        if callable(self.max_weight_or_fn):
            self.max_weight_or_fn = self.max_weight_or_fn()
        return self.max_weight_or_fn
