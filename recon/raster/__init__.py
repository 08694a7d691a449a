"""Differentiable 3-D Gaussian splatting (Kerbl et al. 2023) with CPU and GPU backends.

    render(means, quats, scales, opacities, colors, camera, background, backend="auto") -> RenderOutput

Backends: "torch" (readable tile-binned PyTorch reference, autograd, any device), "dense" (every
Gaussian against every pixel; a test oracle), "cpu" (compiled numba kernels with hand-written
backward; what "auto" picks for CPU tensors), "gsplat" (CUDA; what "auto" picks for CUDA tensors
when gsplat is installed). The camera follows the Gaussians' device and dtype. Conventions are in `types.py` and
`project_ref.py`: quaternions (w, x, y, z), linear scales, opacities in [0, 1], OpenCV cameras.

The readable reference and the fast CPU implementation pair by name, as the simulator's kernels do
(`kernel_ref.emit_events_ref` / `kernels.emit_events`), and are tested against each other forward
and backward: `project_ref.project_ref` / `cpu.project_cpu`, `rasterize_ref.rasterize_ref` /
`cpu.rasterize_cpu` (`rasterize_ref.rasterize_dense_ref`: every Gaussian at every pixel, the oracle).
"""
from __future__ import annotations

import functools
import sys

import torch

from recon.raster.project_ref import project_ref
from recon.raster.types import Camera, RenderOutput

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


@functools.lru_cache(maxsize=1)
def gsplat_available() -> bool:
    """Whether gsplat renders on this machine: importable, a CUDA device, and its kernels run. gsplat
    imports without its kernels and compiles them on first use; where that fails (no compiler, a CUDA
    toolkit that does not match torch's) a run that picked it would die at its first step. So one
    Gaussian is rendered here once; on failure this says why in one line and returns False (`auto`
    then renders with the torch reference on CUDA)."""
    try:
        import gsplat  # noqa: F401
    except ImportError:
        return False
    if not torch.cuda.is_available():
        return False
    try:
        _render_one_gaussian_with_gsplat()
    except Exception as exc:                     # noqa: BLE001 -- any failure of the build or the kernel
        first = (str(exc).strip().splitlines() or [""])[0][:200]
        print(f"gsplat {getattr(gsplat, '__version__', '?')} is installed but its CUDA kernels do not run here "
              f"({type(exc).__name__}: {first}); rendering with the torch backend instead", file=sys.stderr)
        return False
    return True


def _render_one_gaussian_with_gsplat() -> None:
    from recon.raster.gsplat_backend import render_gsplat

    kw = {"dtype": torch.float32, "device": torch.device("cuda")}
    K = torch.tensor([[20.0, 0.0, 8.0], [0.0, 20.0, 8.0], [0.0, 0.0, 1.0]], **kw)
    cam = Camera(K=K, world_to_cam=torch.eye(4, **kw), width=16, height=16)
    out = render_gsplat(torch.tensor([[0.0, 0.0, 2.0]], **kw), torch.tensor([[1.0, 0.0, 0.0, 0.0]], **kw),
                        torch.full((1, 3), 0.1, **kw), torch.tensor([0.5], **kw), torch.ones(1, 3, **kw), cam,
                        torch.zeros(3, **kw))
    torch.cuda.synchronize()
    if not torch.isfinite(out.image).all() or float(out.alpha.max()) <= 0.0:
        raise RuntimeError("a test render came out empty or non-finite")


def resolve_backend(backend: str, device: torch.device | str) -> str:
    """The backend that renders tensors on `device`: "auto" is gsplat on CUDA (the torch reference
    when gsplat is not installed) and the numba "cpu" backend on the CPU; a backend that cannot run
    on the device is an error."""
    device = torch.device(device)
    if backend == "auto":
        if device.type == "cuda":
            return "gsplat" if gsplat_available() else "torch"
        return "cpu"
    if backend not in BACKENDS:
        raise ValueError(f"render: backend must be one of {BACKENDS} or 'auto', got {backend!r}")
    if backend == "cpu" and device.type != "cpu":
        raise ValueError(f"render: backend 'cpu' (numba) renders CPU tensors, these are on {device}; "
                         "use 'gsplat', 'torch' or 'auto'")
    if backend == "gsplat" and device.type != "cuda":
        raise ValueError(f"render: backend 'gsplat' renders CUDA tensors, these are on {device}; "
                         "use 'cpu', 'torch' or 'auto'")
    return backend


def _render_gsplat(means, quats, scales, opacities, colors, camera, background) -> RenderOutput:
    from recon.raster.gsplat_backend import render_gsplat

    return render_gsplat(means, quats, scales, opacities, colors, camera, background)


def _projected(project, raster):
    """A backend from a projection and a rasterizer of the same conventions."""
    def run(means, quats, scales, opacities, colors, camera, background) -> RenderOutput:
        means2d, conics, depths, radii = project(means, quats, scales, camera)
        image, alpha, depth, max_w = raster(means2d, conics, depths, radii, opacities, colors, background,
                                            camera.width, camera.height)
        return RenderOutput(image, alpha, depth, radii, means2d, max_w)
    return run


def _cpu(*args) -> RenderOutput:
    from recon.raster.cpu import project_cpu, rasterize_cpu

    return _projected(project_cpu, rasterize_cpu)(*args)


def _torch(*args) -> RenderOutput:
    from recon.raster.rasterize_ref import rasterize_ref

    return _projected(project_ref, rasterize_ref)(*args)


def _dense(*args) -> RenderOutput:
    from recon.raster.rasterize_ref import rasterize_dense_ref

    return _projected(project_ref, rasterize_dense_ref)(*args)


# backend name -> render(means, quats, scales, opacities, colors, camera, background); modules load on first use
RENDERERS = {"torch": _torch, "dense": _dense, "cpu": _cpu, "gsplat": _render_gsplat}
BACKENDS = tuple(RENDERERS)


def render(means, quats, scales, opacities, colors, camera: Camera, background, backend: str = "auto") -> RenderOutput:
    _check(means, quats, scales, opacities, colors, background)
    if camera.width < 1 or camera.height < 1:
        raise ValueError(f"render: image size must be positive, got {camera.width}x{camera.height}")
    backend = resolve_backend(backend, means.device)
    camera = camera.to(means.dtype, means.device)
    return RENDERERS[backend](means, quats, scales, opacities, colors, camera, background)


def warm_up(backend: str, device: torch.device | str = "cpu", channels: int = 3, dtype=torch.float32) -> None:
    """Render two Gaussians forward and backward once, so kernel compilation (numba's first call,
    gsplat's CUDA build) happens here and not inside a timed training step."""
    device = torch.device(device)
    backend = resolve_backend(backend, device)
    kw = {"dtype": dtype, "device": device}
    means = torch.tensor([[0.0, 0.0, 3.0], [0.1, 0.0, 3.5]], **kw).requires_grad_(True)
    quats = torch.tensor([[1.0, 0.0, 0.0, 0.0]] * 2, **kw)
    scales = torch.full((2, 3), 0.2, **kw)
    camera = Camera(torch.tensor([[8.0, 0, 4], [0, 8.0, 4], [0, 0, 1]], **kw), torch.eye(4, **kw), 8, 8)
    out = render(means, quats, scales, torch.full((2,), 0.5, **kw), torch.full((2, channels), 0.5, **kw),
                 camera, torch.zeros(channels, **kw), backend)
    out.image.sum().backward()
