"""Per-Gaussian trajectories: a deformation with no network (Gaussian-Flow's dual-domain deformation,
Lin et al. CVPR 2024, one of the code bases the E-4DGS paper names).

Each Gaussian carries coefficients `motion` [N, B, 10] of B basis functions of the normalised time t
for its offsets (position 3, quaternion 4, log-scale 3), the same three outputs as the MLP field:

    basis(t) = [t, t^2, .., t^degree,  sin(2 pi t), 1 - cos(2 pi t), .., sin(2 pi L t), 1 - cos(2 pi L t)]
    (dx, dq, dlog_s)_i(t) = sum_b basis_b(t) motion[i, b, :]

Every basis function is 0 at t = 0, so the canonical Gaussians are the scene at the clip's start and
zero coefficients are the identity (as the MLP's zero heads are). A forward + backward costs
O(N B) instead of the MLP's 1.5 M multiply-adds per Gaussian. The coefficients are Gaussian
parameters: pruning, cloning and splitting carry them (a split child moves as its parent did) and
Adam's moments with them.

    trajectory_offsets_ref   readable loop over basis functions
    trajectory_offsets       one matrix product; same signature, tested against the reference

Temporal smoothness (`train.deform_field.smoothness`): the acceleration energy of each Gaussian's
position offset over the clip, E_i = integral_0^1 |dx_i''(t)|^2 dt, averaged over the Gaussians. It is a
quadratic form of the coefficients, E_i = sum_ab G_ab <motion[i, a, :3], motion[i, b, :3]>, with the
Gram matrix of the basis functions' second derivatives G_ab = integral_0^1 basis_a'' basis_b'' dt
(t, the linear term, costs nothing; a Fourier pair of frequency l costs (2 pi l)^4 / 2 per unit
coefficient, a t^2 term 4):

    acceleration_energy_ref  readable: x''(t) summed basis by basis at quadrature nodes
    acceleration_energy      the Gram form, O(N B^2); same signature, tested against the reference
"""
from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

OUT = 10   # dx 3, dq 4, dlog_s 3


def n_basis(degree: int, fourier: int) -> int:
    return degree + 2 * fourier


def trajectory_basis(t: torch.Tensor, degree: int, fourier: int) -> torch.Tensor:
    """t [...] in [0, 1] -> [..., degree + 2 fourier] basis values, each 0 at t = 0."""
    parts = [t ** k for k in range(1, degree + 1)]
    for l in range(1, fourier + 1):
        w = 2.0 * math.pi * l
        parts += [torch.sin(w * t), 1.0 - torch.cos(w * t)]
    return torch.stack(parts, dim=-1) if parts else t.new_zeros(t.shape + (0,))


def basis_second_derivative(t: torch.Tensor, degree: int, fourier: int) -> torch.Tensor:
    """t [...] -> [..., B]: d^2/dt^2 of each basis function of trajectory_basis."""
    parts = [k * (k - 1) * t ** (k - 2) if k >= 2 else torch.zeros_like(t) for k in range(1, degree + 1)]
    for l in range(1, fourier + 1):
        w = 2.0 * math.pi * l
        parts += [-w * w * torch.sin(w * t), w * w * torch.cos(w * t)]
    return torch.stack(parts, dim=-1)


QUADRATURE_NODES = 48   # Gauss-Legendre on [0, 1]: exact for the polynomial part, ~1e-15 for l <= 8


def _quadrature(dtype, device):
    """Gauss-Legendre nodes and weights on [0, 1]: ([Q], [Q])."""
    x, w = np.polynomial.legendre.leggauss(QUADRATURE_NODES)
    return (torch.as_tensor((x + 1) / 2, dtype=dtype, device=device),
            torch.as_tensor(w / 2, dtype=dtype, device=device))


def acceleration_gram(degree: int, fourier: int, dtype=torch.float64, device=None) -> torch.Tensor:
    """[B, B]: G_ab = integral_0^1 basis_a''(t) basis_b''(t) dt."""
    t, w = _quadrature(torch.float64, None)
    d2 = basis_second_derivative(t, degree, fourier)              # [Q, B]
    return (d2.T @ (w[:, None] * d2)).to(dtype=dtype, device=device)


def acceleration_energy_ref(motion: torch.Tensor, degree: int, fourier: int) -> torch.Tensor:
    """motion [N, B, 10] -> scalar: mean over Gaussians of integral_0^1 |dx''(t)|^2 dt (position only);
    reference: the acceleration built basis function by basis function at each quadrature node."""
    ts, ws = _quadrature(motion.dtype, motion.device)
    total = motion.new_zeros(())
    for t, w in zip(ts, ws):
        d2 = basis_second_derivative(t, degree, fourier)          # [B]
        acc = motion.new_zeros(motion.shape[0], 3)
        for b in range(motion.shape[1]):
            acc = acc + d2[b] * motion[:, b, 0:3]
        total = total + w * (acc ** 2).sum(1).mean()
    return total


def acceleration_energy(motion: torch.Tensor, degree: int, fourier: int,
                        gram: torch.Tensor | None = None) -> torch.Tensor:
    """Same as acceleration_energy_ref, as the Gram form (gram: acceleration_gram, passed in to reuse it)."""
    if gram is None:
        gram = acceleration_gram(degree, fourier, motion.dtype, motion.device)
    x = motion[:, :, 0:3]                                          # [N, B, 3]
    return torch.einsum("nad,ab,nbd->n", x, gram, x).mean()


def _split(out: torch.Tensor):
    return out[:, 0:3], out[:, 3:7], out[:, 7:10]


def trajectory_offsets_ref(motion: torch.Tensor, t: float, degree: int, fourier: int):
    """motion [N, B, 10], t scalar -> (dx [N, 3], dq [N, 4], dlog_s [N, 3]); reference: one basis at a time."""
    tt = torch.as_tensor(float(t), dtype=motion.dtype, device=motion.device)
    out = torch.zeros(motion.shape[0], OUT, dtype=motion.dtype, device=motion.device)
    b = 0
    for k in range(1, degree + 1):
        out = out + tt ** k * motion[:, b]
        b += 1
    for l in range(1, fourier + 1):
        w = 2.0 * math.pi * l
        out = out + torch.sin(w * tt) * motion[:, b] + (1.0 - torch.cos(w * tt)) * motion[:, b + 1]
        b += 2
    return _split(out)


def trajectory_offsets(motion: torch.Tensor, t: float, degree: int, fourier: int):
    """Same as trajectory_offsets_ref, as one weighted sum of the coefficients over the basis.

    (Not `basis @ motion`: torch runs that as N batched [1, B] x [B, 10] products, 2-3x slower
    forward + backward on a CPU than this broadcast product and sum; docs/results/training_speed.md.)"""
    basis = trajectory_basis(torch.as_tensor(float(t), dtype=motion.dtype, device=motion.device), degree, fourier)
    out = (basis[None, :, None] * motion).sum(1)      # [B] x [N, B, 10] -> [N, 10]
    return _split(out)


class TrajectoryField(nn.Module):
    """The deformation as per-Gaussian trajectories; holds only the basis sizes (the coefficients
    live on the Gaussians, `GaussianModel.motion`)."""

    kind = "trajectory"

    def __init__(self, degree: int = 3, fourier: int = 2):
        super().__init__()
        if degree < 0 or fourier < 0 or degree + fourier == 0:
            raise ValueError(f"trajectory field: degree and fourier must be >= 0, not both 0; got {degree}, {fourier}")
        self.degree, self.fourier = degree, fourier

    @property
    def n_basis(self) -> int:
        return n_basis(self.degree, self.fourier)

    def spec(self) -> dict:
        return {"kind": self.kind, "degree": self.degree, "fourier": self.fourier}

    def deform_times(self, gaussians, times: list[float]):
        """[deform(gaussians, t) for t in times] (the interface the MLP field shares work through)."""
        return [self.deform(gaussians, t) for t in times]

    def deform(self, gaussians, t: float):
        """(dx [N, 3], dq [N, 4], dlog_s [N, 3]) of `gaussians` at normalised time t."""
        if not 0.0 <= float(t) <= 1.0:
            raise ValueError(f"trajectory field: time must lie in [0, 1], got {float(t):.4g}")
        if gaussians.motion is None or gaussians.motion.shape[1:] != (self.n_basis, OUT):
            raise ValueError(f"trajectory field: the Gaussians carry no motion coefficients of shape "
                             f"[N, {self.n_basis}, {OUT}] (got {None if gaussians.motion is None else tuple(gaussians.motion.shape)})")
        return trajectory_offsets(gaussians.motion, t, self.degree, self.fourier)
