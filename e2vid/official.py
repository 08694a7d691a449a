"""Checkpoints in the official layout: `{'arch': ..., 'model': {...}, 'state_dict': {...}}`.

`load_checkpoint` reads the official `E2VID_lightweight.pth.tar` (rpg_e2vid), event_cnn_minimal's
FireNet/E2VID files and this project's own weights (same layout). The architecture is read off the
state dict itself (encoder count, channels, bins, ConvLSTM vs ConvGRU, transposed vs upsample-conv
decoders, batch norm, sum vs concat skips), so a file whose config block is missing or in another
format still loads; the parameter names map one to one (a DataParallel `module.` prefix is dropped).
"""
from __future__ import annotations

import re
from dataclasses import asdict
from pathlib import Path
from typing import Any, Mapping

import torch

from common.checkpoint import torch_load

from e2vid.networks import NetConfig, build_network


class CheckpointError(ValueError):
    pass


def infer_config(state: Mapping[str, torch.Tensor]) -> NetConfig:
    """The architecture a state dict was made by (official parameter names)."""
    keys = set(state)
    if "G1.reset_gate.weight" in keys:
        head = state["head.conv2d.weight"]
        return NetConfig(arch="firenet", num_bins=head.shape[1], base_num_channels=head.shape[0],
                         num_encoders=0, recurrent_block_type="convgru", kernel_size=head.shape[-1])
    if "unetrecurrent.head.conv2d.weight" not in keys:
        raise CheckpointError("state dict has neither E2VID (unetrecurrent.*) nor FireNet (G1.*) parameters; "
                              f"first keys: {sorted(keys)[:4]}")
    head = state["unetrecurrent.head.conv2d.weight"]
    enc = {int(m.group(1)) for k in keys if (m := re.match(r"unetrecurrent\.encoders\.(\d+)\.", k))}
    res = {int(m.group(1)) for k in keys if (m := re.match(r"unetrecurrent\.resblocks\.(\d+)\.", k))}
    base = head.shape[0]
    return NetConfig(
        arch="e2vid", num_bins=head.shape[1], base_num_channels=base, num_encoders=len(enc),
        num_residual_blocks=len(res),
        recurrent_block_type="convlstm" if "unetrecurrent.encoders.0.recurrent_block.Gates.weight" in keys else "convgru",
        skip_type="concat" if state["unetrecurrent.pred.conv2d.weight"].shape[1] == 2 * base else "sum",
        use_upsample_conv="unetrecurrent.decoders.0.transposed_conv2d.weight" not in keys,
        norm="BN" if any(".norm_layer." in k or ".bn1." in k for k in keys) else "none")


def strip_prefix(state: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {k[len("module."):] if k.startswith("module.") else k: v for k, v in state.items()}


def network_from_state(state: Mapping[str, torch.Tensor]) -> torch.nn.Module:
    state = strip_prefix(state)
    cfg = infer_config(state)
    net = build_network(cfg)
    result = net.load_state_dict(state, strict=False)
    if result.missing_keys or result.unexpected_keys:
        raise CheckpointError(f"state dict does not match the inferred {cfg.arch} layout: missing "
                              f"{result.missing_keys[:4]}, unexpected {result.unexpected_keys[:4]}")
    return net.eval()


def load_checkpoint(path: str | Path) -> tuple[torch.nn.Module, dict[str, Any]]:
    """-> (network in eval mode, the file's other entries, e.g. this project's training report)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: E2VID weights file not found")
    try:
        raw = torch_load(path, "E2VID / FireNet weights (a PyTorch checkpoint)")
    except ValueError as err:
        raise CheckpointError(str(err)) from None
    state = raw.get("state_dict", raw) if isinstance(raw, dict) else None
    if not isinstance(state, Mapping):
        raise CheckpointError(f"{path}: expected a dict with 'state_dict'")
    try:
        net = network_from_state(state)
    except (CheckpointError, KeyError) as err:
        raise CheckpointError(f"{path}: {err}") from err
    extra = {k: v for k, v in raw.items() if k != "state_dict"} if "state_dict" in raw else {}
    return net, extra


def save_checkpoint(path: str | Path, net: torch.nn.Module, **extra: Any) -> Path:
    """Write `net` in the official layout (plus `extra` entries) atomically."""
    from common.fileio import atomic_output

    cfg: NetConfig = net.cfg
    arch = "FireNet" if cfg.arch == "firenet" else "E2VIDRecurrent"
    payload = {"arch": arch, "model": asdict(cfg), "state_dict": net.state_dict(), **extra}
    with atomic_output(path) as tmp:
        torch.save(payload, tmp)
    return Path(path)
