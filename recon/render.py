"""Rendering a deformable Gaussian model at a time: deform, colour, rasterize."""
from __future__ import annotations

import numpy as np
import torch

from recon.deform import DeformationField
from scene_format.cameras import rigid_pose_problem
from recon.gaussians import GaussianModel
from recon.precision import autocast
from recon.raster import Camera, RenderOutput, render


def check_camera(K, c2w_opencv, width, height) -> tuple[np.ndarray, np.ndarray]:
    """(K [3, 3], c2w [4, 4]) as float64 arrays; ValueError saying what was expected otherwise."""
    try:
        K = np.asarray(K, np.float64)
        c2w = np.asarray(c2w_opencv, np.float64)
    except (TypeError, ValueError):
        raise ValueError("camera: expected K as a 3x3 array of numbers and c2w as a 4x4 array of numbers") from None
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or not (K[0, 0] > 0 and K[1, 1] > 0):
        raise ValueError(f"camera: K must be a finite 3x3 matrix with positive fx, fy; got shape {K.shape}"
                         + (f", fx={K[0, 0]:g}, fy={K[1, 1]:g}" if K.shape == (3, 3) else ""))
    if c2w.shape != (4, 4) or not np.all(np.isfinite(c2w)):
        raise ValueError(f"camera: the pose must be a finite 4x4 camera-to-world matrix, got shape {c2w.shape}"
                         + (" with NaN or inf" if c2w.shape == (4, 4) else ""))
    problem = rigid_pose_problem(c2w)
    if problem:
        raise ValueError(f"camera: the pose (c2w_opencv): {problem}")
    if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer)) and width > 0 and height > 0):
        raise ValueError(f"camera: width and height must be positive integers, got {width!r} x {height!r}")
    return K, c2w


def camera_from_pose(K, c2w_opencv, width: int, height: int, dtype=torch.float32, device="cpu") -> Camera:
    """Raster camera from intrinsics K [3,3] and an OpenCV camera-to-world pose [4,4] (ValueError saying
    what was expected for anything else)."""
    K, c2w = check_camera(K, c2w_opencv, width, height)
    return Camera(torch.as_tensor(np.asarray(K, np.float64), dtype=dtype, device=device),
                  torch.as_tensor(np.linalg.inv(c2w), dtype=dtype, device=device), int(width), int(height))


def camera_center(camera: Camera) -> torch.Tensor:
    R, t = camera.world_to_cam[:3, :3], camera.world_to_cam[:3, 3]
    return -R.T @ t


def check_time(t: float) -> float:
    if isinstance(t, (str, bytes)) or (np.ndim(t) != 0 if not isinstance(t, torch.Tensor) else t.numel() != 1):
        raise ValueError(f"time: expected one number in [0, 1] (render one time per call), got {type(t).__name__}"
                         + (f" of shape {tuple(np.shape(t))}" if not isinstance(t, (str, bytes)) else f" {t!r}"))
    t = float(t)
    if not 0.0 <= t <= 1.0:
        raise ValueError(f"time must lie in [0, 1] (the clip's normalised time), got {t:.6g}")
    return t


def _offset(gaussians: GaussianModel, dx: torch.Tensor, dq: torch.Tensor, ds: torch.Tensor):
    """(means, quats, log_scales) + a field's offsets, brought back to the parameters' dtype."""
    dtype = gaussians.means.dtype
    return gaussians.means + dx.to(dtype), gaussians.quats + dq.to(dtype), gaussians.log_scales + ds.to(dtype)


def deformed_times(gaussians: GaussianModel, field: DeformationField | None, times: list[float],
                   precision: str = "float32") -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """[deformed(gaussians, field, t, precision) for t in times], with one field call for all times."""
    if field is None or len(gaussians) == 0:
        return [(gaussians.means, gaussians.quats, gaussians.log_scales) for _ in times]
    with autocast(precision, gaussians.means.device):
        offsets = field.deform_times(gaussians, times)
    return [_offset(gaussians, *o) for o in offsets]


def deformed(gaussians: GaussianModel, field: DeformationField | None, t: float, precision: str = "float32"):
    """Means [N,3], quaternions [N,4] and log-scales [N,3] at normalised time t (field None: canonical);
    the field computes in `precision` (float32, or bfloat16 autocast; its outputs come back float32)."""
    if field is None or len(gaussians) == 0:
        return gaussians.means, gaussians.quats, gaussians.log_scales
    with autocast(precision, gaussians.means.device):
        offsets = field.deform(gaussians, t)
    return _offset(gaussians, *offsets)


def render_at(gaussians: GaussianModel, field: DeformationField | None, camera: Camera, t: float,
              background: torch.Tensor, backend: str = "auto", precision: str = "float32") -> RenderOutput:
    """Render the model deformed to normalised time t in [0, 1] (field None: the canonical model)."""
    return render_views(gaussians, field, [camera], t, background, backend, precision)[0]


def render_views(gaussians: GaussianModel, field: DeformationField | None, cameras: list[Camera], t: float,
                 background: torch.Tensor, backend: str = "auto", precision: str = "float32") -> list[RenderOutput]:
    """Render several cameras at one normalised time t: the deformation field runs once and every
    render shares its output (and its gradient)."""
    check_time(t)
    state = deformed(gaussians, field, t, precision)
    return [render_deformed(gaussians, state, camera, background, backend) for camera in cameras]


def render_views_times(gaussians: GaussianModel, field: DeformationField | None, cameras: list[list[Camera]],
                       times: list[float], background: torch.Tensor, backend: str = "auto",
                       precision: str = "float32") -> list[list[RenderOutput]]:
    """`render_views` at several times: cameras[k] rendered at times[k], the field evaluated for all
    times in one call (`deform_times`: the MLP shares the position encoding's work across them).
    Returns one list of renders per time."""
    if len(cameras) != len(times):
        raise ValueError(f"render_views_times: one camera list per time expected, got {len(cameras)} lists "
                         f"for {len(times)} times")
    states = deformed_times(gaussians, field, [check_time(t) for t in times], precision)
    return [[render_deformed(gaussians, state, c, background, backend) for c in cams]
            for state, cams in zip(states, cameras)]


def render_deformed(gaussians: GaussianModel, state: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
                    camera: Camera, background: torch.Tensor, backend: str = "auto") -> RenderOutput:
    """Render the Gaussians at a deformed state (means [N,3], quats [N,4], log-scales [N,3], as
    `deformed` returns): several views of one time (or a viewer's moving camera) deform once."""
    means, quats, log_scales = state
    camera = camera.to(means.dtype, means.device)
    colors = gaussians.colors(camera_center(camera), means)
    return render(means, quats, torch.exp(log_scales), gaussians.opacities, colors, camera, background, backend)
