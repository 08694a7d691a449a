"""Differentiable 3-D Gaussian splatting (Kerbl et al. 2023) with CPU and GPU backends.

    render(means, quats, scales, opacities, colors, camera, background, backend="auto") -> RenderOutput

Backends: "torch" (readable tile-binned PyTorch reference, autograd), "dense" (every Gaussian
against every pixel; a test oracle), "cpu" (compiled numba kernels with hand-written backward;
the default without a GPU), "gsplat" (CUDA, when available). Conventions are in `types.py` and
`projection.py`: quaternions (w, x, y, z), linear scales, opacities in [0, 1], OpenCV cameras.
"""
from __future__ import annotations

import torch

from recon.raster.projection import project
from recon.raster.types import Camera, RenderOutput

BACKENDS = ("torch", "dense", "cpu", "gsplat")


def _check(means, quats, scales, opacities, colors, background):
    n = means.shape[0]
    shapes = {"means": (means, (n, 3)), "quats": (quats, (n, 4)), "scales": (scales, (n, 3)),
              "opacities": (opacities, (n,))}
    for name, (t, shape) in shapes.items():
        if tuple(t.shape) != shape:
            raise ValueError(f"render: {name} must have shape {shape}, got {tuple(t.shape)}")
    if colors.ndim != 2 or colors.shape[0] != n:
        raise ValueError(f"render: colors must have shape ({n}, C), got {tuple(colors.shape)}")
    if tuple(background.shape) != (colors.shape[1],):
        raise ValueError(f"render: background must have shape ({colors.shape[1]},), got {tuple(background.shape)}")


def default_backend() -> str:
    if torch.cuda.is_available():
        try:
            import gsplat  # noqa: F401

            return "gsplat"
        except ImportError:
            pass
    return "cpu"


def render(means, quats, scales, opacities, colors, camera: Camera, background, backend: str = "auto") -> RenderOutput:
    _check(means, quats, scales, opacities, colors, background)
    if camera.width < 1 or camera.height < 1:
        raise ValueError(f"render: image size must be positive, got {camera.width}x{camera.height}")
    backend = default_backend() if backend == "auto" else backend
    if backend not in BACKENDS:
        raise ValueError(f"render: backend must be one of {BACKENDS} or 'auto', got {backend!r}")
    camera = camera.to(means.dtype)
    if backend == "gsplat":
        from recon.raster.gsplat_backend import render_gsplat

        return render_gsplat(means, quats, scales, opacities, colors, camera, background)
    if backend == "cpu":
        from recon.raster.cpu import project_cpu, rasterize_cpu

        means2d, conics, depths, radii = project_cpu(means, quats, scales, camera)
        raster = rasterize_cpu
    else:
        from recon.raster.ref import rasterize_dense, rasterize_tiles

        means2d, conics, depths, radii = project(means, quats, scales, camera)
        raster = rasterize_tiles if backend == "torch" else rasterize_dense
    image, alpha, depth, max_w = raster(means2d, conics, depths, radii, opacities, colors, background,
                                        camera.width, camera.height)
    return RenderOutput(image, alpha, depth, radii, means2d, max_w)
