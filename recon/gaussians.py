"""Canonical Gaussians: parameters, activations, and the densification edits (3DGS / D3DGS).

Stored (optimised) quantities and their activations, as in the public 3DGS / D3DGS code:
means [N,3] (identity), log_scales [N,3] (exp), quats [N,4] (normalised by the rasterizer),
opacity_logits [N] (sigmoid), SH coefficients sh_dc [N,1,C] and sh_rest [N,(deg+1)^2-1,C].
Densification edits the parameters and the Adam state together: `prune` drops rows, `clone`
appends copies, `split` replaces each selected Gaussian by `n` children sampled inside it with
scales divided by 0.8 n; children inherit every other parameter of their parent.

Optional `motion` [N, B, 10] (a parameter when set): per-Gaussian trajectory coefficients
(recon.trajectory), edited with the others: a clone or split child inherits its parent's.

Optional `anchors` [N, 3] (a buffer, not optimised): the deformation field's per-Gaussian input when
set (E-4DGS: children inherit their parent's deformation input, so a split child moves as its
parent did). None means the field reads the canonical means (D3DGS).
"""
from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from recon.sh import n_coeffs, rgb_to_dc, sh_to_color

PARAM_NAMES = ("means", "log_scales", "quats", "opacity_logits", "sh_dc", "sh_rest")


def inverse_sigmoid(x: torch.Tensor) -> torch.Tensor:
    return torch.log(x / (1 - x))


def nearest_neighbour_scale(points: np.ndarray, k: int = 3) -> np.ndarray:
    """sqrt of the mean squared distance to the k nearest other points, per point (>= 1e-7)."""
    from scipy.spatial import cKDTree

    if len(points) < 2:
        return np.full(len(points), 0.01, np.float32)
    k = min(k, len(points) - 1)
    dist, _ = cKDTree(points).query(points, k=k + 1)
    return np.sqrt(np.maximum((dist[:, 1:] ** 2).mean(axis=1), 1e-14)).astype(np.float32)


class GaussianModel(nn.Module):
    def __init__(self, n: int, sh_degree: int = 3, channels: int = 3):
        super().__init__()
        self.sh_degree = sh_degree
        self.channels = channels
        self.active_sh_degree = 0
        k = n_coeffs(sh_degree)
        self.means = nn.Parameter(torch.zeros(n, 3))
        self.log_scales = nn.Parameter(torch.zeros(n, 3))
        self.quats = nn.Parameter(torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(n, 1))
        self.opacity_logits = nn.Parameter(torch.zeros(n))
        self.sh_dc = nn.Parameter(torch.zeros(n, 1, channels))
        self.sh_rest = nn.Parameter(torch.zeros(n, k - 1, channels))
        self.register_buffer("anchors", None)
        self.register_parameter("motion", None)

    def param_names(self) -> tuple[str, ...]:
        """The optimised per-Gaussian tensors (PARAM_NAMES, and `motion` when the model has trajectories)."""
        return PARAM_NAMES + (("motion",) if self.motion is not None else ())

    def enable_motion(self, n_basis: int) -> None:
        """Give every Gaussian zero trajectory coefficients [N, n_basis, 10] (the identity deformation)."""
        self.motion = nn.Parameter(torch.zeros(len(self), n_basis, 10, device=self.means.device))

    def deformation_inputs(self) -> torch.Tensor:
        """[N, 3] what the deformation field reads per Gaussian (anchors if set, else the means)."""
        return self.anchors if self.anchors is not None else self.means

    @classmethod
    def from_points(cls, points, colors=None, sh_degree: int = 3, channels: int = 3,
                    init_opacity: float = 0.1) -> "GaussianModel":
        pts = np.asarray(points, np.float32)
        model = cls(len(pts), sh_degree, channels)
        with torch.no_grad():
            model.means.copy_(torch.from_numpy(pts))
            model.log_scales.copy_(torch.log(torch.from_numpy(nearest_neighbour_scale(pts)))[:, None].expand(-1, 3))
            model.opacity_logits.fill_(math.log(init_opacity / (1 - init_opacity)))
            rgb = torch.full((len(pts), channels), 0.5) if colors is None else torch.as_tensor(colors, dtype=torch.float32)
            model.sh_dc.copy_(rgb_to_dc(rgb)[:, None, :])
        return model

    def __len__(self) -> int:
        return self.means.shape[0]

    @property
    def scales(self) -> torch.Tensor:
        return torch.exp(self.log_scales)

    @property
    def opacities(self) -> torch.Tensor:
        return torch.sigmoid(self.opacity_logits)

    def colors(self, camera_center: torch.Tensor, means: torch.Tensor | None = None) -> torch.Tensor:
        """View-dependent colours [N, C] seen from camera_center [3] (means default: canonical)."""
        m = self.means if means is None else means
        dirs = torch.nn.functional.normalize(m - camera_center[None, :], dim=-1)
        sh = torch.cat([self.sh_dc, self.sh_rest], dim=1)
        return sh_to_color(self.active_sh_degree, sh, dirs)

    # -- densification (parameters and Adam state together) ---------------------------------
    def _replace(self, optimizer, name: str, new_value: torch.Tensor, fn_state) -> None:
        """Swap parameter `name` for new_value, carrying its Adam state through fn_state."""
        old = getattr(self, name)
        new = nn.Parameter(new_value)
        if optimizer is not None:
            for group in optimizer.param_groups:
                for i, p in enumerate(group["params"]):
                    if p is old:
                        group["params"][i] = new
                        state = optimizer.state.pop(old, None)
                        if state:
                            optimizer.state[new] = {k: (fn_state(v) if torch.is_tensor(v) and v.shape == old.shape else v)
                                                    for k, v in state.items()}
        setattr(self, name, new)

    def _edit(self, optimizer, fn_param, fn_state) -> None:
        for name in self.param_names():
            self._replace(optimizer, name, fn_param(getattr(self, name).detach()), fn_state)

    def prune(self, keep: torch.Tensor, optimizer=None) -> None:
        """Keep the Gaussians where keep [N] (bool) is True."""
        self._edit(optimizer, lambda t: t[keep].clone(), lambda s: s[keep].clone())
        if self.anchors is not None:
            self.anchors = self.anchors[keep].clone()

    def clone_selected(self, mask: torch.Tensor, optimizer=None) -> None:
        """Append copies of the selected Gaussians (3DGS clone; new Adam moments are zero)."""
        n_new = int(mask.sum())
        self._edit(optimizer, lambda t: torch.cat([t, t[mask]]),
                   lambda s: torch.cat([s, torch.zeros((n_new,) + s.shape[1:], dtype=s.dtype, device=s.device)]))
        if self.anchors is not None:
            self.anchors = torch.cat([self.anchors, self.anchors[mask]])

    def split_selected(self, mask: torch.Tensor, n: int = 2, optimizer=None, generator=None) -> None:
        """Replace each selected Gaussian by n children sampled from it, scales / (0.8 n)."""
        from recon.raster.project_ref import quat_to_rotmat

        idx = torch.nonzero(mask).squeeze(1)
        with torch.no_grad():
            std = self.scales[idx].repeat(n, 1)
            # drawn where the generator lives (the trainer's is on the CPU, so a seed gives the same
            # children on every device), then moved to the model's device
            gen_device = generator.device if generator is not None else std.device
            samples = torch.normal(torch.zeros_like(std, device=gen_device), std.to(gen_device),
                                   generator=generator).to(std.device)
            R = quat_to_rotmat(self.quats[idx]).repeat(n, 1, 1)
            new_means = (R @ samples[..., None])[..., 0] + self.means[idx].repeat(n, 1)
            new_log_scales = torch.log(self.scales[idx].repeat(n, 1) / (0.8 * n))
        children = {"means": new_means, "log_scales": new_log_scales}
        n_new = len(idx) * n

        def param(t, name):
            extra = children.get(name, t[idx].repeat((n,) + (1,) * (t.ndim - 1)))
            return torch.cat([t, extra])

        for name in self.param_names():  # parameter-specific children, then drop the parents
            old = getattr(self, name)
            self._replace(optimizer, name, param(old.detach(), name),
                           lambda s: torch.cat([s, torch.zeros((n_new,) + s.shape[1:], dtype=s.dtype, device=s.device)]))
        if self.anchors is not None:  # children read their parent's deformation input
            self.anchors = torch.cat([self.anchors, self.anchors[idx].repeat(n, 1)])
        keep = torch.ones(len(self), dtype=torch.bool, device=self.means.device)
        keep[idx] = False
        self.prune(keep, optimizer)


def position_lr(step: int, lr_init: float, lr_final: float, max_steps: int, delay_steps: int = 0,
                delay_mult: float = 1.0) -> float:
    """3DGS's position learning rate: log-linear from lr_init to lr_final over max_steps, with an
    optional smooth warm-up (delay) at the start."""
    if step < 0 or (lr_init == 0.0 and lr_final == 0.0):
        return 0.0
    if delay_steps > 0:
        delay = delay_mult + (1 - delay_mult) * math.sin(0.5 * math.pi * min(max(step / delay_steps, 0.0), 1.0))
    else:
        delay = 1.0
    t = min(max(step / max_steps, 0.0), 1.0)
    return delay * math.exp(math.log(lr_init) * (1 - t) + math.log(lr_final) * t)
