"""Analytic answers of the pixel model: counts, polarities and crossing times."""
import numpy as np
import pytest

from simulator import EventSimulator, FrameError, SimulatorConfig, simulate
from tests.conftest import frame_from_log


def run_pixel(log_values, t_us, config=None, backend="fast"):
    frames = [frame_from_log(np.full((1, 1), v)) for v in log_values]
    return simulate(frames, t_us, config or SimulatorConfig(), backend=backend).events


@pytest.mark.parametrize("backend", ["fast", "ref"])
def test_ramp_of_one_log_unit_gives_five_events_at_the_crossing_times(backend):
    ev = run_pixel([0.0, 1.0], [0, 1000], backend=backend)
    assert len(ev) == 5 and np.all(ev["p"] == 1)
    np.testing.assert_allclose(ev["t"], [200, 400, 600, 800, 1000], atol=1)


@pytest.mark.parametrize("backend", ["fast", "ref"])
def test_ramp_spread_over_many_frames_keeps_exact_times(backend):
    # log intensity rises linearly by 1.0 over 7 frame intervals of irregular length
    t = np.array([0, 90, 250, 333, 480, 700, 901, 1000])
    ev = run_pixel(t / 1000.0, t, backend=backend)
    assert len(ev) == 5
    np.testing.assert_allclose(ev["t"], [200, 400, 600, 800, 1000], atol=1)


def test_constant_frames_give_no_events():
    frames = np.full((50, 8, 9), 0.37)
    assert len(simulate(frames, np.arange(50) * 333)) == 0


def test_rise_then_fall_gives_matching_polarity_counts():
    ev = run_pixel([0.0, 0.9, 0.0], [0, 1000, 2000])
    on, off = ev[ev["p"] == 1], ev[ev["p"] == -1]
    assert len(on) == 4 and len(off) == 4           # floor(0.9 / 0.2) each way
    assert on["t"].max() <= 1000 < off["t"].min()
    # OFF crossings at levels 0.6, 0.4, 0.2, 0.0 on the falling line 0.9 -> 0 over (1000, 2000]
    np.testing.assert_allclose(off["t"], 1000 + (0.9 - np.array([0.6, 0.4, 0.2, 0.0])) / 0.9 * 1000, atol=1)


@pytest.mark.parametrize("backend", ["fast", "ref"])
def test_jump_of_200_thresholds_in_one_interval(backend):
    ev = run_pixel([0.0, 200 * 0.2], [10_000, 20_000], backend=backend)
    assert len(ev) == 200 and np.all(ev["p"] == 1)
    np.testing.assert_allclose(ev["t"], 10_000 + 50 * np.arange(1, 201), atol=1)


def test_negative_jump_and_asymmetric_thresholds():
    cfg = SimulatorConfig(pos_threshold=0.3, neg_threshold=0.1)
    ev = run_pixel([0.0, -1.0, 0.0], [0, 1000, 2000], cfg)
    assert np.sum(ev["p"] == -1) == 10 and np.sum(ev["p"] == 1) == 3


def test_events_are_sorted_and_inside_their_frame_interval(rng):
    frames = rng.uniform(0.01, 1.0, size=(6, 20, 30))
    t = np.array([0, 100, 333, 334, 1000, 1500])
    sim = EventSimulator(SimulatorConfig(), 30, 20)
    for k in range(len(t)):
        ev = sim.push(frames[k], t[k])
        if k:
            assert np.all(np.diff(ev["t"]) >= 0)
            assert len(ev) == 0 or (ev["t"].min() > t[k - 1] and ev["t"].max() <= t[k])


def test_rgb_frames_use_rec709_luma():
    rgb = np.zeros((2, 1, 1, 3))
    rgb[0] = [0.1, 0.1, 0.1]
    rgb[1] = [0.9, 0.1, 0.1]
    luma = np.array([0.1, 0.2126 * 0.9 + 0.7152 * 0.1 + 0.0722 * 0.1]).reshape(2, 1, 1)
    a = simulate(rgb, [0, 1000]).events
    b = simulate(luma, [0, 1000]).events
    assert len(a) > 0 and np.array_equal(a, b)


def test_linlog_is_linear_in_the_dark():
    cfg = SimulatorConfig(log_mode="linlog", linlog_threshold_dn=20.0, linlog_dn_per_unit=255.0)
    slope = np.log(20.0) / 20.0  # response per DN below 20 DN
    # 0 -> 10 DN (linear part): response change 10 * slope, events = floor(/0.2)
    ev = simulate(np.array([0.0, 10 / 255]).reshape(2, 1, 1), [0, 1000], cfg).events
    assert len(ev) == int(np.floor(10 * slope / 0.2))
    # 40 -> 80 DN (log part): log(2) / 0.2 -> 3 events
    ev = simulate(np.array([40 / 255, 80 / 255]).reshape(2, 1, 1), [0, 1000], cfg).events
    assert len(ev) == 3


def test_timestamps_beyond_32_bits():
    t0 = 2**32 + 123
    ev = run_pixel([0.0, 1.0], [t0, t0 + 1000])
    assert ev["t"].dtype == np.int64
    np.testing.assert_allclose(ev["t"] - t0, [200, 400, 600, 800, 1000], atol=1)


def test_zero_intensity_and_saturated_frames_stay_finite():
    frames = np.zeros((4, 5, 6))
    frames[1] = 1e6      # saturated white after black
    frames[2] = 1e6
    frames[3] = 0.0
    ev = simulate(frames, [0, 1000, 2000, 3000]).events
    expected = int(np.floor((np.log(1e6 + 1e-3) - np.log(1e-3)) / 0.2))
    per_pixel_on = np.sum(ev["p"] == 1) / 30
    per_pixel_off = np.sum(ev["p"] == -1) / 30
    assert per_pixel_on == expected and per_pixel_off == expected
    assert np.all((ev["t"] > 0) & (ev["t"] <= 3000))


def test_threshold_near_the_floor():
    cfg = SimulatorConfig(pos_threshold=0.01, neg_threshold=0.01, threshold_min=0.01)
    ev = run_pixel([0.0, 2.0], [0, 1000], cfg)
    assert len(ev) == 200
    assert np.all(np.diff(ev["t"]) >= 0) and ev["t"].max() == 1000


@pytest.mark.parametrize("bad, message", [
    (np.nan, "finite"), (-0.5, ">= 0"), (np.inf, "finite"),
])
def test_bad_intensities_are_rejected_with_location(bad, message):
    sim = EventSimulator(SimulatorConfig(), 4, 3)
    frame = np.full((3, 4), 0.5)
    frame[2, 1] = bad
    with pytest.raises(FrameError, match=message) as err:
        sim.push(frame, 0)
    assert "row 2, col 1" in str(err.value)


def test_non_increasing_timestamps_are_rejected():
    sim = EventSimulator(SimulatorConfig(), 4, 3)
    sim.push(np.full((3, 4), 0.5), 100)
    for t in (100, 50):
        with pytest.raises(FrameError, match="timestamps must increase"):
            sim.push(np.full((3, 4), 0.5), t)
    with pytest.raises(FrameError, match="integer number of microseconds"):
        sim.push(np.full((3, 4), 0.5), 200.5)


def test_frame_size_change_and_integer_frames_are_rejected():
    sim = EventSimulator(SimulatorConfig(), 4, 3)
    sim.push(np.full((3, 4), 0.5), 0)
    with pytest.raises(FrameError, match="does not match the sensor"):
        sim.push(np.full((4, 3), 0.5), 10)
    with pytest.raises(FrameError, match="linear-light float frame"):
        sim.push(np.full((3, 4), 128, np.uint8), 20)


def test_simulate_checks_frame_and_timestamp_counts():
    with pytest.raises(FrameError, match="2 frames but 3 timestamps"):
        simulate(np.ones((2, 3, 3)), [0, 1, 2])
    with pytest.raises(FrameError, match="no timestamp"):
        simulate(np.ones((3, 3, 3)), [0, 1])
