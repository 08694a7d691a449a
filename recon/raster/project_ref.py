"""EWA projection of 3-D Gaussians (PyTorch reference, differentiable through autograd).

Covariance R S S^T R^T from a (w, x, y, z) quaternion (normalised here; a zero quaternion gives the
identity rotation) and linear scales; camera-space mean t = W mu + w; perspective Jacobian J with
t_x/t_z and t_y/t_z clamped to the image's extent plus 0.3 x the half field of view on each side
(`jacobian_limits`: gsplat's rule, the reference 3DGS code's 1.3 x the half field of view for a
centred principal point), so Gaussians far outside the image do not produce huge footprints; 2-D covariance J W Sigma W^T J^T
+ 0.3 I; its inverse (the conic); 3-sigma radius. Gaussians with t_z < NEAR_PLANE are culled
(radius 0).
"""
from __future__ import annotations

import torch

from recon.raster.types import LOWPASS, NEAR_PLANE, Camera

QUAT_EPS = 1e-12


def quat_to_rotmat(quats: torch.Tensor) -> torch.Tensor:
    """[N,4] (w, x, y, z), any norm -> [N,3,3]; a zero quaternion maps to the identity."""
    norm = quats.norm(dim=-1, keepdim=True)
    q = quats / norm.clamp_min(QUAT_EPS)
    w, x, y, z = q.unbind(-1)
    # zero quaternion: all terms vanish except the 1s on the diagonal -> identity
    return torch.stack([
        torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def jacobian_limits(fx, fy, cx, cy, width: int, height: int):
    """(x_neg, x_pos, y_neg, y_pos): t_x / t_z is clamped to [-x_neg, x_pos] (t_y / t_z likewise) where
    the projection's Jacobian is evaluated: the image's extent seen from the principal point plus 0.3
    of the half field of view on each side, gsplat's rule (for a centred principal point it is the
    reference 3DGS code's 1.3 x the half field of view). Off-centre principal points, which real
    calibrations have, keep the margin on each side of the image rather than about its centre."""
    gx, gy = 0.3 * (0.5 * width / fx), 0.3 * (0.5 * height / fy)
    return cx / fx + gx, (width - cx) / fx + gx, cy / fy + gy, (height - cy) / fy + gy


def project_ref(means: torch.Tensor, quats: torch.Tensor, scales: torch.Tensor, camera: Camera):
    """-> means2d [N,2], conics [N,3] (a, b, c of [[a,b],[b,c]]), depths [N], radii [N] (int32).

    Culled Gaussians get radius 0 (their other outputs are finite but meaningless).
    """
    Wr, wt = camera.world_to_cam[:3, :3], camera.world_to_cam[:3, 3]
    fx, fy, cx, cy = camera.K[0, 0], camera.K[1, 1], camera.K[0, 2], camera.K[1, 2]
    t = means @ Wr.T + wt
    tz = t[:, 2]
    valid = tz >= NEAR_PLANE
    tz_safe = torch.where(valid, tz, torch.ones_like(tz))
    x_neg, x_pos, y_neg, y_pos = jacobian_limits(fx, fy, cx, cy, camera.width, camera.height)
    ux = torch.clamp(t[:, 0] / tz_safe, min=-x_neg, max=x_pos)
    uy = torch.clamp(t[:, 1] / tz_safe, min=-y_neg, max=y_pos)
    zeros = torch.zeros_like(tz)
    J = torch.stack([torch.stack([fx / tz_safe, zeros, -fx * ux / tz_safe], -1),
                     torch.stack([zeros, fy / tz_safe, -fy * uy / tz_safe], -1)], -2)  # [N,2,3]
    R = quat_to_rotmat(quats)
    M = R * scales[:, None, :]                     # R S
    cov3 = M @ M.transpose(1, 2)                   # R S S^T R^T
    cov_cam = Wr @ cov3 @ Wr.T
    cov2 = J @ cov_cam @ J.transpose(1, 2)
    sa = cov2[:, 0, 0] + LOWPASS
    sb = cov2[:, 0, 1]
    sc = cov2[:, 1, 1] + LOWPASS
    det = sa * sc - sb * sb
    conics = torch.stack([sc / det, -sb / det, sa / det], -1)
    means2d = torch.stack([fx * t[:, 0] / tz_safe + cx, fy * t[:, 1] / tz_safe + cy], -1)
    mid = 0.5 * (sa + sc)
    lam = mid + torch.sqrt((mid * mid - det).clamp_min(0.1))
    radii = torch.ceil(3.0 * torch.sqrt(lam)).detach()
    radii = torch.where(valid & torch.isfinite(radii), radii, torch.zeros_like(radii)).to(torch.int32)
    return means2d, conics, tz, radii
