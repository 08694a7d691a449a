"""The geometric blur measurement (pure NumPy): analytic paths, exposure choice, statistics."""
import math

import numpy as np
import pytest

from datagen.blur import exposure_window
from datagen.blur_geometry import (LogHistogram, candidate_windows, choose_exposures, cumulative_path_px, measure_blur,
                                   project_tracks, track_world, window_path_px)
from scene_format.cameras import intrinsics_from_fov, look_at_opencv
from datagen.rig import axis_rotations
from scene_format.config import BlurConfig
from common.config import ConfigError

FPS = 3000.0
K = intrinsics_from_fov(346, 260, 50.0).K


def fixed_camera(T, distance=4.0):
    """A camera at (distance, 0, 0) looking at the origin along -x, for T timestamps: [T, 4, 4]."""
    return np.tile(look_at_opencv((distance, 0.0, 0.0), (0.0, 0.0, 0.0)), (T, 1, 1))


def sliding_plane(T, speed_m_s, n_points=50, seed=0):
    """Points on the plane x = 0 (|y|, |z| < 1) translating along y at speed_m_s: local points, parts, matrices."""
    rng = np.random.default_rng(seed)
    local = np.c_[np.zeros(n_points), rng.uniform(-1, 1, (n_points, 2))]
    mats = np.tile(np.eye(4), (T, 1, 1, 1))
    mats[:, 0, 1, 3] = speed_m_s * np.arange(T) / FPS
    return local, np.zeros(n_points, np.int64), mats


def test_plane_translating_parallel_to_the_image_gives_f_v_t_over_z():
    T, v, Z = 61, 30.0, 4.0
    local, obj, mats = sliding_plane(T, v)
    uv, depth = project_tracks(K, fixed_camera(T, Z), track_world(local, obj, mats))
    np.testing.assert_allclose(depth, Z)
    cum = cumulative_path_px(uv)
    for n in (1, 2, 7, 30):
        first, last = exposure_window(30, n, T)
        expected = K[0, 0] * v * (n - 1) / FPS / Z      # fx * distance travelled / depth
        np.testing.assert_allclose(window_path_px(cum, [first], [last])[0], expected, rtol=1e-9)
    assert expected == pytest.approx(30 * 29 / 3000 / 4 * 346 / 2 / math.tan(math.radians(25)))


def test_panning_camera_moves_the_axis_point_by_f_tan_angle():
    # a point on the optical axis at t = 0; the camera pans at omega rad/s about its own y axis
    T, omega = 31, 2.0
    c2w = fixed_camera(T)
    c2w[:, :3, :3] = c2w[:, :3, :3] @ axis_rotations(np.c_[np.zeros(T), omega * np.arange(T) / FPS, np.zeros(T)])
    world = np.zeros((T, 1, 3))
    uv, _ = project_tracks(K, c2w, world)
    u = uv[:, 0, 0] - K[0, 2]
    np.testing.assert_allclose(np.abs(u), K[0, 0] * np.tan(omega * np.arange(T) / FPS), rtol=1e-9, atol=1e-9)
    cum = cumulative_path_px(uv)
    assert cum[-1, 0] == pytest.approx(K[0, 0] * math.tan(omega * (T - 1) / FPS), rel=1e-9)


def test_points_behind_the_camera_have_no_path():
    T = 5
    world = np.zeros((T, 2, 3))
    world[:, 1, 0] = np.linspace(-1, 8, T)      # second point passes behind the camera at x = 4
    uv, _ = project_tracks(K, fixed_camera(T), world)
    cum = cumulative_path_px(uv)
    assert np.all(cum[:, 0] == 0) and np.isnan(cum[-1, 1])


def test_candidate_windows_match_the_generator_windows():
    first, last = candidate_windows(5, 12, 40, offset=0)
    for n in range(1, 13):
        assert (first[n - 1], last[n - 1]) == exposure_window(5, n, 40)
        assert last[n - 1] - first[n - 1] + 1 == n


def test_log_histogram_quantiles_match_numpy():
    rng = np.random.default_rng(1)
    values = np.exp(rng.normal(1.5, 1.0, (3, 20_000)))
    values[0, :100] = 0.0          # zero-length paths land in the first bin
    values[1, :50] = np.nan        # culled points are dropped
    h = LogHistogram(3)
    h.add(values[:, :10_000])
    h.add(values[:, 10_000:])
    for q in (0.5, 0.9):
        np.testing.assert_allclose(h.quantile(q), np.nanquantile(values, q, axis=1), rtol=5e-3)
    assert np.isnan(LogHistogram(1).quantile(0.5)[0])


def test_exposures_are_chosen_by_ratio_and_unreachable_levels_are_refused():
    medians = 1.0 * np.arange(40)               # n frames blur n - 1 px
    got = choose_exposures(medians, {"mild": 3.0, "strong": 20.2}, 0.1, FPS, "plane", "the clip")
    assert [(c.level, c.n_frames) for c in got] == [("mild", 4), ("strong", 21)]
    with pytest.raises(ConfigError, match="scene plane, blur level huge: target 80 px.*longest exposure"):
        choose_exposures(medians, {"mild": 3.0, "huge": 80.0}, 0.1, FPS, "plane", "the clip")
    with pytest.raises(ConfigError, match="scene plane, blur level tiny: target 0.2 px.*raise render.fps"):
        choose_exposures(medians, {"tiny": 0.2}, 0.1, FPS, "plane", "the clip")
    with pytest.raises(ConfigError, match="same exposure"):
        choose_exposures(medians, {"a": 3.0, "b": 3.1}, 0.1, FPS, "plane", "the clip")
    with pytest.raises(ConfigError, match="nothing in view moves"):
        choose_exposures(np.zeros(10), {"a": 3.0}, 0.1, FPS, "still", "the clip")


def test_measure_blur_on_a_sliding_plane_picks_the_analytic_exposure():
    T, v, Z = 121, 20.0, 4.0
    local, obj, mats = sliding_plane(T, v, n_points=200)
    px_per_frame = K[0, 0] * v / FPS / Z             # 0.618 px
    centers = np.array([20, 60, 100])
    poses = fixed_camera(T, Z)[None].repeat(2, 0)
    samples = {(k, j): (local, obj) for k in range(2) for j in range(3)}
    cfg = BlurConfig(target_px={"mild": 3.0, "strong": 12.0}, tolerance=0.1, max_exposure_ms=20.0)
    rep = measure_blur(samples, mats, poses, K, centers, cfg, FPS, "plane")
    for c in rep.choices:
        n_best = 1 + int(round(c.target_px / px_per_frame))
        assert c.n_frames == n_best
        lv = rep.manifest["levels"][c.level]
        assert lv["median_px"] == pytest.approx((n_best - 1) * px_per_frame, rel=1e-3)
        assert lv["p90_px"] == pytest.approx(lv["median_px"], rel=1e-3)       # uniform motion
        assert lv["exposure_ms"] == pytest.approx(1e3 * n_best / FPS, abs=1e-4)
        assert [w[1] - w[0] + 1 for w in rep.windows[c.level].values()] == [n_best] * 3
        assert len(lv["per_camera"]) == 2 and lv["per_camera"][1]["samples"] == 3 * 200
        np.testing.assert_allclose(rep.view_median_px[c.level], (n_best - 1) * px_per_frame, rtol=1e-9)
    assert rep.manifest["px_per_frame"]["median"] == pytest.approx(px_per_frame, rel=1e-3)
    # a target past max_exposure_ms (60 frames: 36 px) is refused, naming what bounds it
    with pytest.raises(ConfigError, match="blur level strong: target 50 px.*max_exposure_ms = 20"):
        measure_blur(samples, mats, poses, K, centers, BlurConfig(target_px={"strong": 50.0}, max_exposure_ms=20.0),
                     FPS, "plane")
