"""The six-camera rig of a generated scene (pure NumPy): spiral centres, optional hand-held shake,
look-at poses at normalised times; the axis conventions are scene_format.cameras'."""
from __future__ import annotations

import numpy as np

from common.config import ConfigError
from scene_format.cameras import look_at_opencv


def spiral_positions(rig, tau: np.ndarray) -> np.ndarray:
    """Camera centres [n_cameras, T, 3] at normalised times tau [T] in [0, 1] (see CameraRigConfig)."""
    tau = np.asarray(tau, np.float64)
    k = np.arange(rig.n_cameras)[:, None]
    az = np.radians(rig.azimuth0_deg + 360.0 * k / rig.n_cameras + rig.sweep_deg * tau[None, :])
    r = rig.radius + rig.radius_change * tau[None, :]
    tx, ty, _ = rig.target
    return np.stack([tx + r * np.cos(az), ty + r * np.sin(az), np.full_like(az, rig.height)], axis=-1)


def axis_rotations(angles_rad: np.ndarray) -> np.ndarray:
    """Rotations [..., 3, 3] Rz(roll) @ Ry(pan) @ Rx(tilt) from angles [..., 3] = (tilt, pan, roll)."""
    a = np.asarray(angles_rad, np.float64)
    cx, sx = np.cos(a[..., 0]), np.sin(a[..., 0])
    cy, sy = np.cos(a[..., 1]), np.sin(a[..., 1])
    cz, sz = np.cos(a[..., 2]), np.sin(a[..., 2])
    one, zero = np.ones_like(cx), np.zeros_like(cx)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cx, -sx], -1), np.stack([zero, sx, cx], -1)], -2)
    ry = np.stack([np.stack([cy, zero, sy], -1), np.stack([zero, one, zero], -1), np.stack([-sy, zero, cy], -1)], -2)
    rz = np.stack([np.stack([cz, -sz, zero], -1), np.stack([sz, cz, zero], -1), np.stack([zero, zero, one], -1)], -2)
    return rz @ ry @ rx


def shake_angles(shake, t_s: np.ndarray, seed: int) -> np.ndarray:
    """Shake rotation angles [T, 3] in radians (tilt, pan, roll about the camera's x, y, z axes) at
    times t_s [T] in seconds (see ShakeConfig). Each axis is a sum of sinusoids whose amplitudes are
    normalised so that its RMS over a long time is rms_deg (roll: roll_scale * rms_deg)."""
    t_s = np.asarray(t_s, np.float64)
    rng = np.random.default_rng(seed)
    out = np.zeros((len(t_s), 3))
    for axis in range(3):  # draw for every axis whatever the amplitudes: a camera's shake depends only on its seed
        freq_hz = np.exp(rng.uniform(np.log(shake.min_hz), np.log(shake.max_hz), shake.components))
        phase = rng.uniform(0.0, 2.0 * np.pi, shake.components)
        weight = rng.uniform(0.5, 1.0, shake.components)
        amp = weight / np.sqrt(np.sum(weight ** 2) / 2.0)  # RMS of the sum = 1
        rms_rad = np.radians(shake.rms_deg) * (shake.roll_scale if axis == 2 else 1.0)
        out[:, axis] = rms_rad * np.sin(2.0 * np.pi * freq_hz[None] * t_s[:, None] + phase[None]) @ amp
    return out


def rig_poses(rig, tau: np.ndarray, duration_s: float = 1.0, seed: int = 0) -> np.ndarray:
    """c2w [n_cameras, T, 4, 4] in OpenCV axes at normalised times tau [T]: every camera on its spiral
    looking at the rig's target, then turned by its shake (times tau * duration_s seconds; camera k
    seeded with seed * 1009 + k). The target must stay within the central half of the field of view
    (a ConfigError otherwise), so every camera keeps the scene in view."""
    tau = np.asarray(tau, np.float64)
    pos = spiral_positions(rig, tau)
    out = np.empty(pos.shape[:2] + (4, 4))
    for c in range(pos.shape[0]):
        for i in range(pos.shape[1]):
            out[c, i] = look_at_opencv(pos[c, i], rig.target)
        if rig.shake.rms_deg > 0:
            out[c, :, :3, :3] = out[c, :, :3, :3] @ axis_rotations(shake_angles(rig.shake, tau * duration_s, seed * 1009 + c))
    to_target = np.asarray(rig.target, np.float64) - pos
    cos_off = np.sum(out[..., :3, 2] * to_target, -1) / np.linalg.norm(to_target, axis=-1)
    off_deg = np.degrees(np.arccos(np.clip(cos_off, -1.0, 1.0)))
    if off_deg.max() > rig.fov_x_deg / 4:
        c, i = np.unravel_index(np.argmax(off_deg), off_deg.shape)
        raise ConfigError(f"camera.shake: camera {c} at tau={tau[i]:.4f} looks {off_deg[c, i]:.1f} degrees away from "
                          f"the target, more than a quarter of the {rig.fov_x_deg:g} degree field of view")
    return out


def scene_poses(cfg, tau: np.ndarray) -> np.ndarray:
    """rig_poses of a SceneConfig: its rig, its clip length, its seed."""
    return rig_poses(cfg.camera, tau, cfg.duration_s, cfg.seed)
