"""APS frames as the simulator's input (simulator.aps): the noise removal, the still pixels, the
temporal upsampling and the events of a pixel whose light doubles, by hand."""
import math

import numpy as np

from simulator.aps import denoise_aps, simulate_frames, static_pixels, upsampled
from simulator.config import SimulatorConfig


def test_deviations_within_the_threshold_vanish_and_larger_ones_shrink_by_it():
    dn = np.zeros((5, 1, 3), np.uint8)
    dn[:, 0, 0] = [10, 12, 8, 10, 11]           # read noise of 2 DN around 10: gone
    dn[:, 0, 1] = [10, 10, 30, 10, 10]          # a real change of 20 DN: kept, less 4
    dn[:, 0, 2] = [50, 50, 50, 50, 50]
    out = denoise_aps(dn, 4.0)
    assert out[:, 0, 0].tolist() == [10.0] * 5
    assert out[:, 0, 1].tolist() == [10.0, 10.0, 26.0, 10.0, 10.0]
    assert static_pixels(out).tolist() == [[True, False, True]]


def test_upsampling_interpolates_linear_intensity_between_frame_times():
    frames = np.stack([np.full((1, 1), 0.2, np.float32), np.full((1, 1), 0.6, np.float32)])
    got = list(upsampled(frames, np.array([1000, 3000]), rate_hz=1000.0, motion="linear"))
    assert [t for _, t in got] == [1000, 2000, 3000]
    np.testing.assert_allclose([f[0, 0] for f, _ in got], [0.2, 0.4, 0.6], rtol=1e-6)


def test_upsampling_along_the_flow_moves_an_edge_where_a_blend_fades_it():
    """A bright bar moving 8 px right per frame: along the flow, the frame half-way between the first
    two has the bar 4 px on (each pixel either bar or background); a blend has two half-bright bars."""
    ys, xs = np.mgrid[0:48, 0:64].astype(np.float32)
    bar = lambda x0: 0.1 + 0.8 / (1 + np.exp(-(xs - x0) * 1.5)) * (1 / (1 + np.exp((xs - x0 - 10) * 1.5))) \
        + 0.02 * np.sin(ys / 3.0)                                                      # noqa: E731
    frames = np.stack([bar(20.0), bar(28.0), bar(36.0)])
    t = np.array([0, 40_000, 80_000])
    (mid_flow, _), = [(f, tt) for f, tt in upsampled(frames, t, 50.0, "flow") if tt == 20_000]
    (mid_blend, _), = [(f, tt) for f, tt in upsampled(frames, t, 50.0, "linear") if tt == 20_000]
    truth = bar(24.0)
    inner = (slice(8, 40), slice(8, 56))
    err_flow = np.abs(mid_flow - truth)[inner].max()
    err_blend = np.abs(mid_blend - truth)[inner].max()
    assert err_flow < 0.1 < 0.3 < err_blend, (err_flow, err_blend)


def test_upsampling_names_an_unknown_motion():
    import pytest

    with pytest.raises(ValueError, match="motion must be one of flow, linear, got 'cubic'"):
        next(upsampled(np.zeros((2, 2, 2), np.float32), np.array([0, 10]), 1000.0, "cubic"))


def test_a_pixel_whose_light_doubles_fires_floor_of_ln2_over_c_on_events():
    frames = np.stack([np.full((2, 2), 0.25, np.float32), np.full((2, 2), 0.5, np.float32)])
    frames[1, 0, 0] = 0.25                       # one pixel stays still
    cfg = SimulatorConfig(pos_threshold=0.2, neg_threshold=0.2, log_eps=1e-9)
    s = simulate_frames(frames, np.array([0, 40_000]), cfg, rate_hz=2000.0, motion="linear")
    e = s.events
    per_pixel = np.bincount(e["y"].astype(int) * 2 + e["x"].astype(int), minlength=4)
    assert per_pixel.tolist() == [0] + [math.floor(math.log(2) / 0.2)] * 3
    assert np.all(e["p"] == 1) and e["t"].min() > 0 and e["t"].max() <= 40_000


def test_the_aps_check_refuses_a_recording_it_cannot_decode(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    import eventio

    path = tmp_path / "events.h5"
    eventio.write_events(path, eventio.EventStream(eventio.make_events([1, 5], [0, 1], [0, 1], [1, -1]), 4, 4))
    r = subprocess.run([sys.executable, "-m", "tools.aps_check", "--clip", str(path)], capture_output=True, text=True,
                       cwd=Path(__file__).resolve().parents[2])
    assert r.returncode == 1 and f"{path}: not an AEDAT4 recording" in r.stderr, r.stderr


def test_the_fit_objective_is_zero_at_the_camera_and_the_wide_fit_adds_the_floor():
    import math

    from tools.aps_check import FIT_GRID, WIDE_GRID, objective

    real = {"events": 1000, "static_rate_hz": 0.003, "iei_p0_1_us": 1000.0}
    same = {**real, "w1_log_rate": 0.0, "w1_log_iei": 0.0}
    assert objective(same, real) == 0 and objective(same, real, floor_term=True) == 0
    slow = {**same, "iei_p0_1_us": 2000.0, "events": 10_000}
    assert objective(slow, real) == 1.0                                  # the count's log10 ratio only
    assert objective(slow, real, floor_term=True) == 1.0 + math.log10(2)
    assert set(FIT_GRID) == set(WIDE_GRID) and FIT_GRID["threshold_sigma"] == (0.03,)


def test_the_wide_fit_refines_the_refractory_period_between_the_grids_steps():
    from tools.aps_check import REFINE_REACH_US, WIDE_GRID, refractory_refinement

    assert refractory_refinement(500) == [350, 400, 450, 550, 600, 650]
    assert refractory_refinement(100) == [50, 150, 200, 250]           # periods stay positive
    steps = np.diff(WIDE_GRID["refractory_us"])
    assert all(s / 2 <= REFINE_REACH_US for s in steps)     # it reaches halfway to each grid neighbour


def test_a_pixel_that_never_changes_stays_still_in_between_along_the_flow():
    rng = np.random.default_rng(0)
    import cv2

    tex = cv2.GaussianBlur(rng.random((40, 70)).astype(np.float32), (0, 0), 1.5)
    frames = np.stack([tex[:, k:k + 40].copy() for k in (0, 4, 8)])         # a texture moving 4 px per frame
    frames[:, :, :3] = 0.5                                                  # three columns of still pixels
    got = np.stack([f for f, _ in upsampled(frames, np.array([0, 10_000, 20_000]), 1000.0, "flow")])
    assert np.all(got[:, :, :3] == 0.5)
