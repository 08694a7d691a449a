"""E2VID's recurrent UNet and FireNet, with the official parameter names.

Module attribute names follow the official implementations (rpg_e2vid `E2VIDRecurrent` /
`UNetRecurrent`; event_cnn_minimal `FireNet`), so an official state dict loads key for key:

  E2VIDRecurrent: unetrecurrent.head.conv2d.*, unetrecurrent.encoders.{i}.conv.conv2d.*,
                  unetrecurrent.encoders.{i}.recurrent_block.Gates.* (ConvLSTM),
                  unetrecurrent.resblocks.{j}.conv{1,2}.*, unetrecurrent.decoders.{i}.transposed_conv2d.*
                  (or .conv2d.* with upsample-conv decoders), unetrecurrent.pred.conv2d.*,
                  and .norm_layer.* / .bn{1,2}.* when norm is "BN".
  FireNet:        head.conv2d.*, G1.{reset,update,out}_gate.*, R1.conv{1,2}.*, G2.*, R2.*, pred.conv2d.*

Both take a normalised voxel grid [N, num_bins, H, W] and the previous recurrent states (None at
the start) and return (image [N, 1, H, W], states). E2VID ends in a sigmoid; FireNet's output is
linear, as in the official code (clamp it to [0, 1] for display).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import torch
import torch.nn.functional as F
from torch import nn


@dataclass(frozen=True)
class NetConfig:
    """Architecture. Defaults: E2VID_lightweight (3 encoders, 32 base channels, ConvLSTM, sum skips,
    transposed-conv decoders). `arch: firenet` uses base_num_channels 16 and kernel 3."""
    arch: Literal["e2vid", "firenet"] = "e2vid"
    num_bins: int = 5
    base_num_channels: int = 32
    num_encoders: int = 3
    num_residual_blocks: int = 2
    recurrent_block_type: Literal["convlstm", "convgru"] = "convlstm"
    skip_type: Literal["sum", "concat"] = "sum"
    use_upsample_conv: bool = False
    norm: Literal["none", "BN"] = "none"
    kernel_size: int = 3      # FireNet only


FIRENET = NetConfig(arch="firenet", base_num_channels=16, num_encoders=0, recurrent_block_type="convgru")


class ConvLayer(nn.Module):
    def __init__(self, cin, cout, kernel, stride=1, padding=0, activation: str | None = "relu", norm="none"):
        super().__init__()
        self.conv2d = nn.Conv2d(cin, cout, kernel, stride, padding, bias=norm != "BN")
        self.norm_layer = nn.BatchNorm2d(cout) if norm == "BN" else None
        self.activation = activation

    def forward(self, x):
        x = self.conv2d(x)
        if self.norm_layer is not None:
            x = self.norm_layer(x)
        return torch.relu(x) if self.activation == "relu" else x


class TransposedConvLayer(nn.Module):
    """x2 upsampling by a stride-2 transposed convolution (E2VID_lightweight's decoders)."""
    def __init__(self, cin, cout, kernel, padding, norm="none"):
        super().__init__()
        self.transposed_conv2d = nn.ConvTranspose2d(cin, cout, kernel, stride=2, padding=padding,
                                                    output_padding=1, bias=norm != "BN")
        self.norm_layer = nn.BatchNorm2d(cout) if norm == "BN" else None

    def forward(self, x):
        x = self.transposed_conv2d(x)
        if self.norm_layer is not None:
            x = self.norm_layer(x)
        return torch.relu(x)


class UpsampleConvLayer(nn.Module):
    """x2 bilinear upsampling, then a convolution (no checkerboard artefacts, slower)."""
    def __init__(self, cin, cout, kernel, padding, norm="none"):
        super().__init__()
        self.conv2d = nn.Conv2d(cin, cout, kernel, 1, padding, bias=norm != "BN")
        self.norm_layer = nn.BatchNorm2d(cout) if norm == "BN" else None

    def forward(self, x):
        x = self.conv2d(F.interpolate(x, scale_factor=2, mode="bilinear", align_corners=False))
        if self.norm_layer is not None:
            x = self.norm_layer(x)
        return torch.relu(x)


class ResidualBlock(nn.Module):
    def __init__(self, channels, norm="none"):
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, 1, 1, bias=norm != "BN")
        self.conv2 = nn.Conv2d(channels, channels, 3, 1, 1, bias=norm != "BN")
        self.bn1 = nn.BatchNorm2d(channels) if norm == "BN" else None
        self.bn2 = nn.BatchNorm2d(channels) if norm == "BN" else None

    def forward(self, x):
        out = self.conv1(x)
        out = torch.relu(self.bn1(out) if self.bn1 is not None else out)
        out = self.conv2(out)
        out = self.bn2(out) if self.bn2 is not None else out
        return torch.relu(out + x)


class ConvLSTM(nn.Module):
    """Gates = conv([x, h]) split into input, remember, output and cell gates."""
    def __init__(self, channels, hidden, kernel):
        super().__init__()
        self.hidden = hidden
        self.Gates = nn.Conv2d(channels + hidden, 4 * hidden, kernel, padding=kernel // 2)

    def forward(self, x, state):
        if state is None:
            z = x.new_zeros(x.shape[0], self.hidden, *x.shape[2:])
            state = (z, z)
        h, c = state
        i, r, o, g = self.Gates(torch.cat([x, h], 1)).chunk(4, 1)
        c = torch.sigmoid(r) * c + torch.sigmoid(i) * torch.tanh(g)
        h = torch.sigmoid(o) * torch.tanh(c)
        return h, c


class ConvGRU(nn.Module):
    def __init__(self, channels, hidden, kernel):
        super().__init__()
        self.hidden = hidden
        pad = kernel // 2
        self.reset_gate = nn.Conv2d(channels + hidden, hidden, kernel, padding=pad)
        self.update_gate = nn.Conv2d(channels + hidden, hidden, kernel, padding=pad)
        self.out_gate = nn.Conv2d(channels + hidden, hidden, kernel, padding=pad)
        for conv in (self.reset_gate, self.update_gate, self.out_gate):
            nn.init.orthogonal_(conv.weight)
            nn.init.zeros_(conv.bias)

    def forward(self, x, state):
        if state is None:
            state = x.new_zeros(x.shape[0], self.hidden, *x.shape[2:])
        xh = torch.cat([x, state], 1)
        update = torch.sigmoid(self.update_gate(xh))
        reset = torch.sigmoid(self.reset_gate(xh))
        cand = torch.tanh(self.out_gate(torch.cat([x, state * reset], 1)))
        return state * (1 - update) + cand * update


class RecurrentConvLayer(nn.Module):
    def __init__(self, cin, cout, kernel, stride, padding, block: str, norm="none"):
        super().__init__()
        self.block = block
        self.conv = ConvLayer(cin, cout, kernel, stride, padding, norm=norm)
        self.recurrent_block = (ConvLSTM if block == "convlstm" else ConvGRU)(cout, cout, 3)

    def forward(self, x, state):
        state = self.recurrent_block(self.conv(x), state)
        return (state[0] if self.block == "convlstm" else state), state


class UNetRecurrent(nn.Module):
    def __init__(self, cfg: NetConfig):
        super().__init__()
        self.cfg = cfg
        base, n_enc = cfg.base_num_channels, cfg.num_encoders
        self.head = ConvLayer(cfg.num_bins, base, 5, 1, 2)
        self.encoders = nn.ModuleList(
            RecurrentConvLayer(base * 2 ** i, base * 2 ** (i + 1), 5, 2, 2, cfg.recurrent_block_type, cfg.norm)
            for i in range(n_enc))
        top = base * 2 ** n_enc
        self.resblocks = nn.ModuleList(ResidualBlock(top, cfg.norm) for _ in range(cfg.num_residual_blocks))
        up = UpsampleConvLayer if cfg.use_upsample_conv else TransposedConvLayer
        mult = 1 if cfg.skip_type == "sum" else 2
        self.decoders = nn.ModuleList(up(mult * c, c // 2, 5, 2, cfg.norm)
                                      for c in reversed([base * 2 ** (i + 1) for i in range(n_enc)]))
        self.pred = ConvLayer(mult * base, 1, 1, activation=None, norm=cfg.norm)

    def _skip(self, a, b):
        return a + b if self.cfg.skip_type == "sum" else torch.cat([a, b], 1)

    def forward(self, x, states):
        states = states if states is not None else [None] * len(self.encoders)
        x = self.head(x)
        head = x
        blocks, new_states = [], []
        for enc, st in zip(self.encoders, states):
            x, st = enc(x, st)
            blocks.append(x)
            new_states.append(st)
        for rb in self.resblocks:
            x = rb(x)
        for i, dec in enumerate(self.decoders):
            x = dec(self._skip(x, blocks[-1 - i]))
        return torch.sigmoid(self.pred(self._skip(x, head))), new_states


class E2VIDRecurrent(nn.Module):
    def __init__(self, cfg: NetConfig = NetConfig()):
        super().__init__()
        self.cfg = cfg
        self.unetrecurrent = UNetRecurrent(cfg)

    @property
    def multiple(self) -> int:
        return 2 ** self.cfg.num_encoders

    def forward(self, voxel, states=None):
        return self.unetrecurrent(voxel, states)


class FireNet(nn.Module):
    def __init__(self, cfg: NetConfig = FIRENET):
        super().__init__()
        self.cfg = cfg
        c, k = cfg.base_num_channels, cfg.kernel_size
        self.head = ConvLayer(cfg.num_bins, c, k, 1, k // 2)
        self.G1 = ConvGRU(c, c, k)
        self.R1 = ResidualBlock(c)
        self.G2 = ConvGRU(c, c, k)
        self.R2 = ResidualBlock(c)
        self.pred = ConvLayer(c, 1, 1, activation=None)

    multiple = 1

    def forward(self, voxel, states=None):
        s1, s2 = states if states is not None else (None, None)
        x = self.head(voxel)
        s1 = self.G1(x, s1)
        x = self.R1(s1)
        s2 = self.G2(x, s2)
        return self.pred(self.R2(s2)), [s1, s2]


def build_network(cfg: NetConfig) -> nn.Module:
    return FireNet(cfg) if cfg.arch == "firenet" else E2VIDRecurrent(cfg)


def pad_to_multiple(x: torch.Tensor, multiple: int) -> tuple[torch.Tensor, tuple[int, int, int, int]]:
    """Reflection-pad [N, C, H, W] to multiples of `multiple` (split evenly, as E2VID's CropParameters)."""
    h, w = x.shape[-2:]
    ph, pw = math.ceil(h / multiple) * multiple - h, math.ceil(w / multiple) * multiple - w
    pads = (math.ceil(pw / 2), pw // 2, math.ceil(ph / 2), ph // 2)   # left, right, top, bottom
    if ph == 0 and pw == 0:
        return x, pads
    return F.pad(x, pads, mode="reflect" if min(h, w) > max(pads) else "replicate"), pads


class Reconstructor:
    """A network plus its recurrent state: `__call__(voxel [num_bins, H, W])` -> image [H, W] in [0, 1]."""

    def __init__(self, net: nn.Module):
        self.net = net.eval()
        self.states = None

    def reset(self) -> None:
        self.states = None

    @torch.no_grad()
    def __call__(self, voxel: torch.Tensor) -> torch.Tensor:
        x, (l, r, t, b) = pad_to_multiple(voxel[None].float(), self.net.multiple)
        img, self.states = self.net(x, self.states)
        h, w = voxel.shape[-2:]
        return img[0, 0, t:t + h, l:l + w].clamp(0, 1)


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
NetConfig.BOUNDS = {
    "num_bins": (1, 64, "voxel bins"), "base_num_channels": (1, 1024, "channels"), "num_encoders": (0, 8, "encoders"),
    "num_residual_blocks": (0, 64, "blocks"), "kernel_size": (1, 15, "pixels"),
}
