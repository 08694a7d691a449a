"""The D3DGS deformation field: MLP F(gamma(sg(x)), gamma(t)) -> (dx, dr, ds).

Layout as in the public Deformable-3D-Gaussians code: 8 linear layers of 256 with ReLU (`depth` x
`width`, smaller fields by choice: train.deform_field), the encoded inputs concatenated again after
layer depth // 2, positional encodings with the input included and
frequencies 2^0 .. 2^(n-1) (sin, cos per frequency; 10 for positions, 6 for time), and three linear
heads: position offset (3), quaternion offset (4, added before normalisation) and log-scale
offset (3). The heads start at zero, so an untrained field is the identity.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from recon.config import PAPER_POSITION_FREQS, PAPER_SIZE, mlp_spec  # noqa: F401  (the field's spec, written once)
from recon.deform_kernels import mlp_times


def positional_encoding(x: torch.Tensor, n_freqs: int) -> torch.Tensor:
    """[..., d] -> [..., d (1 + 2 n_freqs)]: x, then sin(2^k x), cos(2^k x) for k = 0 .. n-1."""
    parts = [x]
    for k in range(n_freqs):
        f = 2.0 ** k
        parts += [torch.sin(x * f), torch.cos(x * f)]
    return torch.cat(parts, dim=-1)


class DeformationField(nn.Module):
    kind = "mlp"

    def __init__(self, depth: int = PAPER_SIZE[0], width: int = PAPER_SIZE[1], x_freqs: int = PAPER_POSITION_FREQS,
                 t_freqs: int = 6):
        super().__init__()
        self.depth, self.width, self.x_freqs, self.t_freqs = depth, width, x_freqs, t_freqs
        self.skip = depth // 2
        in_ch = 3 * (1 + 2 * x_freqs) + (1 + 2 * t_freqs)
        layers = [nn.Linear(in_ch, width)]
        for i in range(depth - 1):
            layers.append(nn.Linear(width + in_ch if i == self.skip else width, width))
        self.layers = nn.ModuleList(layers)
        self.warp = nn.Linear(width, 3)
        self.rotation = nn.Linear(width, 4)
        self.scaling = nn.Linear(width, 3)
        for head in (self.warp, self.rotation, self.scaling):
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)

    def spec(self) -> dict:
        return mlp_spec(self.depth, self.width, self.x_freqs)

    def deform(self, gaussians, t: float):
        """(dx, dq, dlog_s) of `gaussians` at normalised time t: the MLP at their deformation inputs."""
        return self(gaussians.deformation_inputs(), t)

    def forward(self, x: torch.Tensor, t: torch.Tensor | float):
        """x [N, 3] canonical positions (gradient stopped here), t scalar or [N] in [0, 1].

        Returns (dx [N, 3], dq [N, 4], dlog_s [N, 3]).
        """
        x = x.detach()
        t = torch.as_tensor(t, dtype=x.dtype, device=x.device)
        if t.ndim == 0:
            t = t.expand(x.shape[0])
        if not torch.all((t >= 0) & (t <= 1)):
            raise ValueError(f"deformation field: time must lie in [0, 1], got {t.min().item():.4g}..{t.max().item():.4g}")
        emb = torch.cat([positional_encoding(x, self.x_freqs), positional_encoding(t[:, None], self.t_freqs)], -1)
        if torch.is_autocast_enabled(x.device.type):      # once, not at both layers that read it
            emb = emb.to(torch.get_autocast_dtype(x.device.type))
        h, n_emb = emb, emb.shape[1]
        for i, layer in enumerate(self.layers):
            if i == self.skip + 1:     # layer(cat([emb, h])) as two products: no concatenated copy
                w = layer.weight
                h = torch.relu(F.linear(emb, w[:, :n_emb]) + F.linear(h, w[:, n_emb:], layer.bias))
            else:
                h = torch.relu(layer(h))
        return self.warp(h), self.rotation(h), self.scaling(h)

    def deform_times(self, gaussians, times: list[float]):
        """[(dx, dq, dlog_s)] of `gaussians` at each normalised time: `forward_times` at their inputs."""
        return self.forward_times(gaussians.deformation_inputs(), times)

    def forward_times(self, x: torch.Tensor, times: list[float]):
        """x [N, 3] canonical positions, K scalar times in [0, 1] -> K (dx [N, 3], dq [N, 4], dlog_s [N, 3]),
        equal to [self(x, t) for t in times] to rounding: `forward_times_autograd`'s products with the
        backward written out (recon.deform_kernels; under autocast, `forward_times_autograd` itself).
        A 4 x 96 field at 5,500 points, K = 2, forward + backward: ~1.2-1.4x less time on a 2-core CPU.
        """
        if torch.is_autocast_enabled(x.device.type):
            return self.forward_times_autograd(x, times)
        ex, et = self._encodings(x, times)
        return mlp_times(self, ex, et)

    def _encodings(self, x: torch.Tensor, times: list[float]):
        """(gamma(x) [N, 3 (1 + 2 x_freqs)], gamma(t) [K, 13]) of positions (gradient stopped) and checked times."""
        x = x.detach()
        t = torch.as_tensor([float(v) for v in times], dtype=x.dtype, device=x.device)
        if t.ndim != 1 or t.numel() == 0 or not torch.all((t >= 0) & (t <= 1)):
            raise ValueError(f"deformation field: expected one or more times in [0, 1], got {list(times)}")
        return positional_encoding(x, self.x_freqs), positional_encoding(t[:, None], self.t_freqs)

    def forward_times_autograd(self, x: torch.Tensor, times: list[float]):
        """`forward_times` as layers autograd differentiates (tests/recon/test_deform_size.py checks it
        against [self(x, t) for t in times], tests/recon/test_deform_kernels.py the kernel against it).

        The time's encoding is one vector per time, so in the two layers that read the encoded input
        (the first and the one after the skip) the position columns' product gamma(x) W_x is shared by
        all K times and the time columns' product is a per-time bias: a step that renders the start and
        end of an event window computes gamma(x) and those two products once. A 4 x 96 field at 5,650
        points, K = 2, forward + backward: ~12 % less time than two calls (docs/design/recon.md).
        """
        ex, et = self._encodings(x, times)                     # [N, 3 (1 + 2 x_freqs)], [K, 13]
        if torch.is_autocast_enabled(x.device.type):
            dt = torch.get_autocast_dtype(x.device.type)
            ex, et = ex.to(dt), et.to(dt)
        n_x, n_emb = ex.shape[1], ex.shape[1] + et.shape[1]

        def split(layer):     # (gamma(x) W_x [N, w] shared, gamma(t) W_t + b [K, w] per time)
            w = layer.weight
            return F.linear(ex, w[:, :n_x]), F.linear(et, w[:, n_x:n_emb], layer.bias)

        a0, c0 = split(self.layers[0])
        has_skip = self.skip + 1 < len(self.layers)
        a_skip, c_skip = split(self.layers[self.skip + 1]) if has_skip else (None, None)
        outs = []
        for k in range(et.shape[0]):    # one time at a time: 5-10 % faster on a CPU than one [K N] product
            h = torch.relu(a0 + c0[k])
            for i in range(1, len(self.layers)):
                layer = self.layers[i]
                if i == self.skip + 1:
                    h = torch.relu(torch.addmm(a_skip + c_skip[k], h, layer.weight[:, n_emb:].t()))
                else:
                    h = torch.relu(layer(h))
            outs.append((self.warp(h), self.rotation(h), self.scaling(h)))
        return outs

    def forward_ref(self, x: torch.Tensor, t: torch.Tensor | float):
        """Same as forward, as the public D3DGS code writes it: the encoded input concatenated to the
        hidden state after layer `skip` (forward splits that layer's product instead: 20-25 % less
        time for a bf16 4 x 128 field on a CPU; equal in float32 to rounding)."""
        x = x.detach()
        t = torch.as_tensor(t, dtype=x.dtype, device=x.device)
        if t.ndim == 0:
            t = t.expand(x.shape[0])
        emb = torch.cat([positional_encoding(x, self.x_freqs), positional_encoding(t[:, None], self.t_freqs)], -1)
        h = emb
        for i, layer in enumerate(self.layers):
            h = torch.relu(layer(h))
            if i == self.skip:
                h = torch.cat([emb, h], -1)
        return self.warp(h), self.rotation(h), self.scaling(h)


def make_field(spec: dict | None = None) -> nn.Module:
    """The deformation field a spec names: {"kind": "mlp"} (the paper's MLP, the default; "depth" and
    "width" for another size, "position_freqs" for another position encoding) or {"kind": "trajectory", "degree": d, "fourier": L} (per-Gaussian
    trajectories, recon.trajectory)."""
    from recon.trajectory import TrajectoryField

    spec = dict(spec or {"kind": "mlp"})
    kind = spec.pop("kind", "mlp")
    if kind == "mlp" and set(spec) <= {"depth", "width", "position_freqs"}:
        if "position_freqs" in spec:
            spec["x_freqs"] = spec.pop("position_freqs")
        return DeformationField(**spec)
    if kind == "trajectory":
        return TrajectoryField(**spec)
    raise ValueError(f"deformation field: expected kind mlp or trajectory, got {kind!r} with {spec}")
