"""Camera geometry (pure NumPy): intrinsics, axis conventions, pose interpolation, projection, cameras.json.
The rig that places a generated scene's cameras is datagen.rig.

Conventions, stated once:
- Recon and every file this project writes for recon use **OpenCV** camera axes: x right, y down,
  z forward (the camera looks along +z). Poses are camera-to-world 4x4 matrices `c2w`.
- Blender cameras look along -z with +y up (OpenGL axes). `c2w_opencv = c2w_blender @ FLIP_YZ` and
  back with the same matrix (it is its own inverse). D-NeRF style `transforms_*.json` keep the
  Blender/OpenGL convention, as NeRF code expects.
- Intrinsics K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with pixel (u, v) covering [u, u+1) x [v, v+1):
  its centre samples the image plane at (u + 0.5, v + 0.5), so the image centre is (W/2, H/2).
- The pose at an arbitrary time interpolates position linearly and rotation by SLERP between the
  two recorded poses around it.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])


@dataclass(frozen=True)
class Intrinsics:
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def fov_x_rad(self) -> float:
        return 2.0 * math.atan(self.width / (2.0 * self.fx))

    def to_dict(self) -> dict:
        return {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy, "width": self.width, "height": self.height}


def intrinsics_from_fov(width: int, height: int, fov_x_deg: float) -> Intrinsics:
    """Square pixels, principal point at the image centre."""
    f = width / (2.0 * math.tan(math.radians(fov_x_deg) / 2.0))
    return Intrinsics(f, f, width / 2.0, height / 2.0, int(width), int(height))


def look_at_opencv(position, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """c2w [4,4] (OpenCV axes) of a camera at `position` looking at `target`, image up ~ world `up`."""
    position, target, up = (np.asarray(v, np.float64) for v in (position, target, up))
    z = target - position
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking straight up or down: pick any horizontal x
        x = np.cross(z, [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, position
    return c2w


def opencv_to_blender(c2w: np.ndarray) -> np.ndarray:
    return c2w @ FLIP_YZ


blender_to_opencv = opencv_to_blender  # the flip is its own inverse


# -- rotations -------------------------------------------------------------------------------------
def rotmat_to_quat(R: np.ndarray) -> np.ndarray:
    """Rotation matrix [..., 3, 3] -> unit quaternion [..., 4] (w, x, y, z), w >= 0."""
    R = np.asarray(R, np.float64)
    m = R.reshape(-1, 3, 3)
    q = np.empty((m.shape[0], 4))
    for i, r in enumerate(m):
        tr = np.trace(r)
        if tr > 0:
            s = math.sqrt(tr + 1.0) * 2
            q[i] = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
        elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
            s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
            q[i] = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
        elif r[1, 1] > r[2, 2]:
            s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
            q[i] = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
        else:
            s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
            q[i] = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    return q.reshape(R.shape[:-2] + (4,))


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Quaternion [..., 4] (w, x, y, z), any norm > 0 -> rotation matrix [..., 3, 3]."""
    q = np.asarray(q, np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation of unit quaternions [..., 4] with weights w [...] in [0, 1] (shortest arc)."""
    q0, q1 = np.asarray(q0, np.float64), np.asarray(q1, np.float64)
    w = np.asarray(w, np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-8
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / np.where(small, 1.0, sin_t))
    b = np.where(small, w, np.sin(w * theta) / np.where(small, 1.0, sin_t))
    q = a * q0 + b * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def interpolate_pose(times_us: np.ndarray, c2w: np.ndarray, t_us) -> np.ndarray:
    """Pose(s) at t_us from poses c2w [T,4,4] recorded at increasing times_us [T].

    Linear interpolation of position, SLERP of rotation; times outside the recorded range are an error.
    Returns [4,4] for a scalar t_us, [N,4,4] for an array.
    """
    times_us = np.asarray(times_us, np.float64)
    t = np.atleast_1d(np.asarray(t_us, np.float64))
    if np.any(t < times_us[0]) or np.any(t > times_us[-1]):
        raise ValueError(f"pose requested at t={t.min():.0f}..{t.max():.0f} us, outside the recorded "
                         f"trajectory [{times_us[0]:.0f}, {times_us[-1]:.0f}] us")
    i1 = np.clip(np.searchsorted(times_us, t, side="right"), 1, len(times_us) - 1)
    i0 = i1 - 1
    span = times_us[i1] - times_us[i0]
    w = np.where(span > 0, (t - times_us[i0]) / np.where(span > 0, span, 1.0), 0.0)
    q = slerp(rotmat_to_quat(c2w[i0, :3, :3]), rotmat_to_quat(c2w[i1, :3, :3]), w)
    out = np.tile(np.eye(4), (len(t), 1, 1))
    out[:, :3, :3] = quat_to_rotmat(q)
    out[:, :3, 3] = (1 - w)[:, None] * c2w[i0, :3, 3] + w[:, None] * c2w[i1, :3, 3]
    return out[0] if np.ndim(t_us) == 0 else out


def project(K: np.ndarray, c2w: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points [N,3] -> pixel coordinates [N,2] (image-plane units, see module doc) and depth [N]."""
    w2c = np.linalg.inv(c2w)
    pc = points @ w2c[:3, :3].T + w2c[:3, 3]
    uv = (pc @ K.T)[:, :2] / pc[:, 2:3]
    return uv, pc[:, 2]


@dataclass
class CameraTrajectory:
    """One camera: intrinsics and its OpenCV c2w pose at every rendered timestamp."""
    intrinsics: Intrinsics
    times_us: np.ndarray   # [T] int64
    c2w: np.ndarray        # [T, 4, 4]

    def pose_at(self, t_us) -> np.ndarray:
        return interpolate_pose(self.times_us, self.c2w, t_us)


RIGID_TOL = 1e-4     # |R^T R - I|, |det R - 1| and the last row's deviation from 0 0 0 1 (poses are float32-exact)


def rigid_pose_problem(c2w: np.ndarray, tol: float = RIGID_TOL) -> str | None:
    """What makes c2w [..., 4, 4] not a rigid camera-to-world pose (orthonormal rotation with determinant
    +1, last row 0 0 0 1, within tol), or None when every pose is rigid."""
    c2w = np.asarray(c2w, np.float64)
    R = c2w[..., :3, :3]
    ortho = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
    det = np.linalg.det(R)
    row = np.abs(c2w[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=-1)
    for bad, what in ((row > tol, "its last row is not 0 0 0 1"), (ortho > tol, "its rotation is not orthonormal "
                      "(scaled or sheared)"), (det < 0, "its rotation is a reflection (determinant -1)")):
        if np.any(bad):
            where = np.argwhere(np.atleast_1d(bad))[0] if np.ndim(bad) else None
            at = f" (pose {where.tolist() if len(where) > 1 else int(where[0])})" if where is not None else ""
            return f"{what}{at}; a camera pose must be rigid to within {tol:g}"
    return None


def load_cameras(path: str | Path) -> list[CameraTrajectory]:
    """Read a dataset's cameras.json."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
        intr = Intrinsics(**data["intrinsics"])
        cams = [CameraTrajectory(intr, np.asarray(cam["timestamps_us"], np.int64),
                                 np.asarray(cam["c2w_opencv"], np.float64)) for cam in data["cameras"]]
    except FileNotFoundError:
        raise ValueError(f"{path}: missing") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a cameras file of this toolkit ({type(exc).__name__}: {exc})") from None
    for k, cam in enumerate(cams):
        if cam.c2w.shape != (len(cam.times_us), 4, 4):
            raise ValueError(f"{path}: cameras[{k}].c2w_opencv: expected one 4x4 pose per timestamp, got shape "
                             f"{cam.c2w.shape} for {len(cam.times_us)} timestamps")
        problem = rigid_pose_problem(cam.c2w)
        if problem:
            raise ValueError(f"{path}: cameras[{k}].c2w_opencv: {problem}")
    return cams
