"""Camera geometry: intrinsics, the spiral rig, axis conventions and pose interpolation."""
import math

import numpy as np
import pytest

from scene_format.cameras import FLIP_YZ, blender_to_opencv, interpolate_pose, intrinsics_from_fov, look_at_opencv, opencv_to_blender, project, quat_to_rotmat, rotmat_to_quat, slerp
from datagen.rig import rig_poses, spiral_positions
from scene_format.config import CameraRigConfig
from common.config import ConfigError


def rot_z(deg):
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def test_intrinsics_from_fov():
    intr = intrinsics_from_fov(346, 260, 60.0)
    assert intr.fx == pytest.approx(173 / math.tan(math.radians(30))) and intr.fx == intr.fy
    assert (intr.cx, intr.cy) == (173.0, 130.0)
    assert math.degrees(intr.fov_x_rad) == pytest.approx(60.0)


def test_rig_is_uniform_in_azimuth_at_constant_height_and_spirals():
    rig = CameraRigConfig(n_cameras=6, radius=4.0, height=1.5, target=(0.2, -0.1, 0.5), sweep_deg=30.0, radius_change=0.6)
    tau = np.linspace(0, 1, 11)
    pos = spiral_positions(rig, tau)
    rel = pos[..., :2] - np.array([0.2, -0.1])
    az = np.degrees(np.arctan2(rel[..., 1], rel[..., 0]))
    np.testing.assert_allclose(np.diff(az[:, 0]) % 360, 60.0, atol=1e-9)        # uniform in azimuth
    np.testing.assert_allclose((az[:, -1] - az[:, 0]) % 360, 30.0, atol=1e-9)  # each turns by the sweep
    np.testing.assert_allclose(pos[..., 2], 1.5)                               # constant height
    np.testing.assert_allclose(np.linalg.norm(rel, axis=-1)[:, [0, -1]], [[4.0, 4.6]] * 6)


def test_scene_centre_projects_to_the_image_centre_for_every_camera_and_time():
    rig = CameraRigConfig(n_cameras=6, radius=3.0, height=2.0, target=(0.0, 0.3, 0.4), sweep_deg=45.0, radius_change=-0.5)
    intr = intrinsics_from_fov(346, 260, 50.0)
    poses = rig_poses(rig, np.linspace(0, 1, 9))
    for c2w in poses.reshape(-1, 4, 4):
        uv, depth = project(intr.K, c2w, np.array([rig.target]))
        np.testing.assert_allclose(uv[0], [173.0, 130.0], atol=1e-9)
        assert depth[0] > 0
        np.testing.assert_allclose(c2w[:3, :3] @ c2w[:3, :3].T, np.eye(3), atol=1e-12)
        assert np.linalg.det(c2w[:3, :3]) == pytest.approx(1.0)
        assert c2w[2, 1] < 0  # image "down" (+y) points down in the world (world z up)


def test_blender_opencv_round_trip_and_view_direction():
    c2w = look_at_opencv((2.0, -3.0, 1.0), (0.0, 0.0, 0.5))
    bl = opencv_to_blender(c2w)
    np.testing.assert_allclose(blender_to_opencv(bl), c2w)
    forward = np.array([-2.0, 3.0, -0.5]) / np.linalg.norm([-2.0, 3.0, -0.5])
    np.testing.assert_allclose(-bl[:3, 2], forward, atol=1e-12)     # Blender cameras look along -z
    np.testing.assert_allclose(c2w[:3, 2], forward, atol=1e-12)     # OpenCV cameras along +z
    np.testing.assert_allclose(FLIP_YZ @ FLIP_YZ, np.eye(4))


def test_quaternions_and_slerp():
    for deg in (0, 30, 179, -120):
        R = rot_z(deg) @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
        np.testing.assert_allclose(quat_to_rotmat(rotmat_to_quat(R)), R, atol=1e-12)
    q0, q1 = rotmat_to_quat(rot_z(0)), rotmat_to_quat(rot_z(90))
    np.testing.assert_allclose(quat_to_rotmat(slerp(q0, q1, 0.5)), rot_z(45), atol=1e-12)
    np.testing.assert_allclose(quat_to_rotmat(slerp(q0, q1, 0.25)), rot_z(22.5), atol=1e-12)
    np.testing.assert_allclose(slerp(q0, q0, 0.3), q0)  # identical rotations: no division by zero
    np.testing.assert_allclose(quat_to_rotmat(slerp(q0, -q1, 0.5)), rot_z(45), atol=1e-12)  # shortest arc


def test_interpolate_pose_linear_position_and_slerp_rotation():
    t = np.array([0, 1000, 3000])
    c2w = np.tile(np.eye(4), (3, 1, 1))
    for i, (deg, pos) in enumerate([(0, (0, 0, 0)), (60, (1, 2, 3)), (120, (3, 2, 1))]):
        c2w[i, :3, :3] = rot_z(deg)
        c2w[i, :3, 3] = pos
    np.testing.assert_allclose(interpolate_pose(t, c2w, 1000), c2w[1], atol=1e-12)
    mid = interpolate_pose(t, c2w, 2000)
    np.testing.assert_allclose(mid[:3, 3], [2, 2, 2])
    np.testing.assert_allclose(mid[:3, :3], rot_z(90), atol=1e-12)
    batch = interpolate_pose(t, c2w, np.array([0, 500, 3000]))
    assert batch.shape == (3, 4, 4)
    np.testing.assert_allclose(batch[1][:3, :3], rot_z(30), atol=1e-12)
    with pytest.raises(ValueError, match="outside the recorded trajectory"):
        interpolate_pose(t, c2w, 3001)


def test_shake_is_seeded_has_the_declared_rms_and_keeps_the_target_in_view():
    from datagen.rig import shake_angles
    from scene_format.config import ShakeConfig

    shake = ShakeConfig(rms_deg=2.0, min_hz=4.0, max_hz=25.0, components=3, roll_scale=0.5)
    t = np.arange(0, 20.0, 1 / 3000)
    a = np.degrees(shake_angles(shake, t, seed=7))
    np.testing.assert_allclose(np.sqrt(np.mean(a ** 2, axis=0)), [2.0, 2.0, 1.0], rtol=0.05)
    np.testing.assert_allclose(np.radians(a[:100]), shake_angles(shake, t[:100], 7))     # seeded: the same again
    assert not np.allclose(shake_angles(shake, t[:100], 8), shake_angles(shake, t[:100], 7))
    # frequencies inside the band: no power above max_hz
    spec = np.abs(np.fft.rfft(a[:, 0] * np.hanning(len(t))))   # windowed: no leakage from partial periods
    freqs = np.fft.rfftfreq(len(t), 1 / 3000)
    assert spec[freqs > 30].max() < 1e-3 * spec.max() and spec[freqs < 3].max() < 1e-2 * spec.max()

    rig = CameraRigConfig(n_cameras=3, radius=4.0, height=1.5, target=(0.0, 0.0, 0.5), sweep_deg=60.0,
                          shake=ShakeConfig(rms_deg=1.5))
    tau = np.linspace(0, 1, 301)
    calm = rig_poses(CameraRigConfig(n_cameras=3, radius=4.0, height=1.5, target=(0.0, 0.0, 0.5), sweep_deg=60.0), tau)
    shaken = rig_poses(rig, tau, duration_s=0.5, seed=3)
    np.testing.assert_allclose(shaken[..., :3, 3], calm[..., :3, 3])           # shake turns, never moves, a camera
    np.testing.assert_allclose(np.linalg.det(shaken[..., :3, :3]), 1.0)
    angle = np.degrees(np.arccos(np.clip(np.sum(shaken[..., :3, 2] * calm[..., :3, 2], -1), -1, 1)))
    assert 0.5 < angle.max() < 12.5                                          # the target stays in view
    np.testing.assert_array_equal(shaken, rig_poses(rig, tau, duration_s=0.5, seed=3))
    with pytest.raises(ConfigError, match="camera.shake: camera .* looks .* away from the target"):
        rig_poses(CameraRigConfig(fov_x_deg=20.0, shake=ShakeConfig(rms_deg=8.0)), tau, duration_s=0.5)
