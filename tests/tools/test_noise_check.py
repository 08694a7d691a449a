"""tools.noise_check's fitted values on streams made by hand: the refractory period is the shortest
interval floor the camera shows anywhere, the readout period the step the intervals are multiples of."""
import numpy as np
import pytest

import eventio
from tools.noise_check import readout_period_us, refractory_floor_us, refractory_us


def stream_of(pixel_times: dict[int, list[int]], width: int = 8, height: int = 8):
    xs, ys, ts, ps = [], [], [], []
    for pix, times in pixel_times.items():
        for t in times:
            xs.append(pix % width), ys.append(pix // width), ts.append(t), ps.append(1)
    order = np.argsort(ts, kind="stable")
    take = lambda v: np.asarray(v)[order]  # noqa: E731
    return eventio.EventStream(eventio.make_events(take(ts), take(xs), take(ys), take(ps)), width, height)


def test_the_refractory_period_is_the_shorter_floor_of_all_pixels_and_the_still_ones():
    assert refractory_us(394.0, 197.0) == 197          # still pixels fire closer together: the period bounds them
    assert refractory_us(524.0, 2418.0) == 524         # still pixels' intervals are noise, far above it
    assert refractory_us(float("nan"), 300.0) == 300 and refractory_us(float("nan"), float("nan")) == 0


def test_the_floor_of_all_pixels_leaves_hot_pixels_out():
    s = stream_of({0: list(range(0, 400_000, 1000)), 1: list(range(0, 40_000, 50))})   # pixel 1: hot, 50 us apart
    assert refractory_floor_us(s, np.array([1])) == 1000
    assert refractory_floor_us(s, np.array([], np.int64)) == 50


def test_a_semi_synchronous_readout_is_found_and_an_asynchronous_one_is_not():
    rng = np.random.default_rng(0)
    frames = {p: sorted(set((rng.integers(1, 12, 40).cumsum() * 200).tolist())) for p in range(20)}
    assert abs(readout_period_us(stream_of(frames)) - 200) <= 2     # the largest period within 0.005 of the best fit
    free = {p: sorted(set(rng.integers(0, 2_000_000, 60).tolist())) for p in range(20)}
    assert readout_period_us(stream_of(free)) == 0


def test_regularity_is_one_for_poisson_noise_and_above_for_a_leak():
    from tools.noise_check import two_event_regularity

    rng = np.random.default_rng(3)
    T = 5.0
    random_pairs = np.abs(np.diff(rng.random((20000, 2)) * T * 1e6, axis=1)).ravel()
    assert abs(two_event_regularity(random_pairs, T) - 1.0) < 0.03
    periodic = np.full(100, 0.6 * T * 1e6)             # a leak of period 0.6 T: two events 0.6 T apart
    assert two_event_regularity(periodic, T) == pytest.approx(0.6 / (1 - 2 ** -0.5))
    assert np.isnan(two_event_regularity(periodic[:5], T))


def test_the_noise_split_keeps_the_total_and_recovers_a_known_share():
    """with_diffusion_share moves noise between shot and diffusion noise without changing the total, and
    fit_diffusion_share finds back the share of a still scene made with a known one from its regularity;
    noise no more regular than Poisson gets none."""
    from dataclasses import replace

    from simulator.config import SimulatorConfig
    from tools.noise_check import fit_diffusion_share, noise_figures, still_scene, with_diffusion_share

    fitted = {"shot_noise_rate_hz": 0.3, "shot_noise_on_fraction": 0.4, "shot_noise_sigma_decades": 0.2}
    for share in (0.0, 0.3, 1.0):
        split = with_diffusion_share(fitted, share)
        assert split["shot_noise_rate_hz"] + split["diffusion_noise_rate_hz"] == pytest.approx(0.3)
        assert split["diffusion_noise_on_fraction"] == 0.4 and split["diffusion_noise_sigma_decades"] == 0.2
    side, seconds = 240, 5.0
    made = still_scene(replace(SimulatorConfig(), **with_diffusion_share(fitted, 0.6)), side, side, seconds, 0.5, seed=5)
    target = noise_figures(made, np.ones((side, side), bool), seconds)["regularity"]
    share, table = fit_diffusion_share(fitted, target, side, side, seconds, 0.5)
    assert table[1.0] > table[0.0] + 0.2                  # the walk is more regular than shot noise
    assert share == pytest.approx(0.6, abs=0.2)
    assert fit_diffusion_share(fitted, 0.9, side, side, seconds, 0.5)[0] == 0.0


def test_same_polarity_counts_each_still_pixels_consecutive_events():
    """Pixel 3 fires ON, ON, OFF and pixel 9 OFF, ON: of three consecutive pairs one keeps its polarity."""
    from tools.noise_check import noise_figures

    t = [1000, 500_000, 900_000, 2000, 700_000]
    x, y, p = [3, 3, 3, 1, 1], [0, 0, 0, 1, 1], [1, 1, -1, -1, 1]
    order = np.argsort(t, kind="stable")
    take = lambda v: np.asarray(v)[order]  # noqa: E731
    s = eventio.EventStream(eventio.make_events(take(t), take(x), take(y), take(p)), 8, 8)
    f = noise_figures(s, np.ones((8, 8), bool), 1.0)
    assert f["same_polarity"] == pytest.approx(1 / 3)
    assert f["on_fraction"] == pytest.approx(3 / 5)
