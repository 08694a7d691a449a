"""Where a run computes: one torch device for the model, optimizer state, cameras, targets and
event maps, and the rasterizer backend that renders tensors there.

    device, backend = run_placement("auto", "auto")   # (cuda, "gsplat") with CUDA + gsplat, else (cpu, "cpu")

`device: auto` means CUDA when torch sees a CUDA device and gsplat is installed (without gsplat the
only CUDA renderer would be the slow torch reference, so auto stays on the CPU); `cuda` asks for it
explicitly (backend auto then renders with gsplat, or with the torch reference when gsplat is
missing). A backend that cannot render on the chosen device is a configuration error.
"""
from __future__ import annotations

import torch

from recon.raster import gsplat_available, resolve_backend


class DeviceError(ValueError):
    """train.device / train.backend ask for something this machine cannot do."""


def run_placement(device: str, backend: str) -> tuple[torch.device, str]:
    """(torch device, concrete backend name) for train.device and train.backend."""
    if device == "auto":
        cuda = torch.cuda.is_available() and (gsplat_available() if backend == "auto" else backend != "cpu")
        device = "cuda" if cuda else "cpu"
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise DeviceError(f"train.device: {device!r} asked for, but torch {torch.__version__} sees no CUDA device "
                          "(use device: auto or cpu)")
    try:
        return dev, resolve_backend(backend, dev)
    except ValueError as exc:
        raise DeviceError(f"train.backend: {exc} (train.device is {device!r})") from None


def to_device(x, device: torch.device):
    """A tensor, or a dataclass / list / tuple / dict of them, with every tensor moved to `device`
    (other values unchanged; dataclasses are rebuilt, not modified)."""
    import dataclasses

    if isinstance(x, torch.Tensor):
        return x.to(device)
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return dataclasses.replace(x, **{f.name: to_device(getattr(x, f.name), device)
                                         for f in dataclasses.fields(x) if f.init})
    if isinstance(x, (list, tuple)):
        return type(x)(to_device(v, device) for v in x)
    if isinstance(x, dict):
        return {k: to_device(v, device) for k, v in x.items()}
    return x
