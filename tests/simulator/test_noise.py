"""Noise stages: rates within Poisson bounds, refractory period, seeding, and zero cost when off."""
import numpy as np
import pytest

from simulator import EventSimulator, SimulatorConfig, simulate
from simulator import simulator as simulator_module
from simulator.pixel import SHOT_NOISE_WHITE_FACTOR, intensity01
from tests.conftest import frame_from_log


def static_run(config, intensity, h=20, w=25, seconds=1.0, n_frames=101, seed=3):
    frames = np.full((n_frames, h, w), intensity)
    t = np.round(np.linspace(0, seconds * 1e6, n_frames)).astype(np.int64)
    return simulate(frames, t, config, seed=seed).events


def within_poisson(count, mean, k=5.0):
    return abs(count - mean) <= k * np.sqrt(mean) + 1


@pytest.mark.parametrize("intensity", [0.0, 0.5, 1.0])
def test_shot_noise_counts_match_the_configured_rate(intensity):
    rate = 40.0
    ev = static_run(SimulatorConfig(shot_noise_rate_hz=rate), intensity)
    w = min(float(intensity01(np.array(intensity))), 1.0)
    per_polarity = 0.5 * rate * ((SHOT_NOISE_WHITE_FACTOR - 1) * w + 1) * 500 * 1.0
    assert within_poisson(np.sum(ev["p"] == 1), per_polarity)
    assert within_poisson(np.sum(ev["p"] == -1), per_polarity)
    # static scene: shot noise must not leave the pixels' references moved (no follow-up events)
    assert len(ev) < 2.5 * per_polarity


def test_leak_events_are_on_events_at_the_leak_rate():
    rate = 8.0
    ev = static_run(SimulatorConfig(leak_rate_hz=rate, leak_rate_sigma_decades=0.0), 0.3)
    assert np.all(ev["p"] == 1)
    assert within_poisson(len(ev), rate * 500 * 1.0)


def test_hot_pixels_fire_on_events_only_at_hot_pixels():
    cfg = SimulatorConfig(hot_pixel_fraction=0.02, hot_pixel_rate_hz=300.0)
    ev = static_run(cfg, 0.3)
    sim = EventSimulator(cfg, 25, 20, seed=3)
    hot = set(sim.hot_pixels.tolist())
    assert len(hot) == 10
    assert {int(y) * 25 + int(x) for x, y in zip(ev["x"], ev["y"])} <= hot
    assert np.all(ev["p"] == 1) and within_poisson(len(ev), 10 * 300.0)


@pytest.mark.parametrize("extra", [{}, dict(shot_noise_rate_hz=2000.0, hot_pixel_fraction=0.1, hot_pixel_rate_hz=5000.0)])
def test_refractory_period_is_never_violated(extra, rng):
    R = 250
    frames = np.exp(np.cumsum(rng.normal(0, 0.8, size=(40, 9, 10)), axis=0))
    t = np.cumsum(rng.integers(20, 400, size=40))
    ev = simulate(frames, t, SimulatorConfig(refractory_us=R, **extra)).events
    pix = ev["y"].astype(np.int64) * 10 + ev["x"]
    order = np.lexsort((ev["t"], pix))
    same = pix[order][1:] == pix[order][:-1]
    gaps = np.diff(ev["t"][order])[same]
    assert len(gaps) > 100 and gaps.min() >= R
    # and the refractory period does remove events
    assert len(ev) < len(simulate(frames, t, SimulatorConfig(**extra)))


def test_disabled_effects_reproduce_the_noise_free_output(rng, monkeypatch):
    frames = np.exp(np.cumsum(rng.normal(0, 0.5, size=(20, 8, 9)), axis=0))
    t = np.arange(20) * 333
    ideal = simulate(frames, t, SimulatorConfig()).events
    # every effect present in the config but switched off (zero rate / fraction / cutoff / period)
    off = SimulatorConfig(leak_rate_hz=0.0, leak_rate_sigma_decades=1.0, hot_pixel_fraction=0.3,
                          hot_pixel_rate_hz=0.0, shot_noise_rate_hz=0.0, lowpass_cutoff_hz=0.0,
                          refractory_us=0, threshold_sigma=0.0)
    called = []
    monkeypatch.setattr(simulator_module, "draw_noise_events", lambda *a, **k: called.append(1))
    assert np.array_equal(simulate(frames, t, off, seed=99).events, ideal)
    assert not called  # disabled noise stages are not even run


def test_seeded_noise_is_reproducible():
    cfg = SimulatorConfig(shot_noise_rate_hz=300.0, threshold_sigma=0.05, hot_pixel_fraction=0.05, hot_pixel_rate_hz=100.0)
    a = static_run(cfg, 0.2, seed=5)
    b = static_run(cfg, 0.2, seed=5)
    c = static_run(cfg, 0.2, seed=6)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_threshold_mismatch_is_clamped_and_spreads_counts():
    cfg = SimulatorConfig(threshold_sigma=0.2, threshold_min=0.05)
    sim = EventSimulator(cfg, 50, 40, seed=0)
    assert sim.c_pos.min() >= 0.05 and sim.c_neg.min() >= 0.05
    assert abs(np.median(sim.c_pos) - 0.2) < 0.03
    frames = np.stack([frame_from_log(np.full((40, 50), -2.0)), frame_from_log(np.full((40, 50), -1.0))])
    ev = simulate(frames, [0, 1000], cfg).events
    counts = np.bincount(ev["y"].astype(int) * 50 + ev["x"], minlength=2000)
    # each pixel: one log unit up -> floor(1 / its own C+) events
    assert np.array_equal(counts, np.floor(1.0 / sim.c_pos + 1e-9).astype(int))
    assert counts.std() > 0


def test_lowpass_delays_and_smooths_the_response():
    # a step in the dark is followed more slowly than in the light
    frames = np.concatenate([np.full((1, 1, 2), [[0.01, 1.0]]), np.full((60, 1, 2), [[0.01 * np.e**1.1, np.e**1.1]])])
    t = np.arange(61) * 100
    ev = simulate(frames, t, SimulatorConfig(lowpass_cutoff_hz=100.0)).events
    first_dark = ev["t"][ev["x"] == 0]
    first_bright = ev["t"][ev["x"] == 1]
    assert len(first_bright) == 5 and len(first_dark) >= 1
    assert first_dark.min() > first_bright.min()
    ideal = simulate(frames, t, SimulatorConfig()).events
    assert np.all(ideal["t"] <= 100)  # without the filter the step lands within one interval


def test_lowpass_step_in_place_equals_the_formula(rng):
    from simulator.pixel import lowpass_step

    lp = rng.normal(0, 1, 50)
    new = rng.normal(0, 1, 50)
    inten = rng.uniform(0, 2, 50)
    eps = np.minimum(intensity01(inten) * 1e-4 * 2 * np.pi * 300.0, 1.0)
    expected = lp + eps * (new - lp)
    np.testing.assert_allclose(lowpass_step(lp, new, inten, 1e-4, 300.0), expected, rtol=1e-12, atol=1e-12)
    buf = lp.copy()
    lowpass_step(buf, new, inten, 1e-4, 300.0, out=buf, scratch=np.empty(50))
    np.testing.assert_allclose(buf, expected, rtol=1e-12, atol=1e-12)
    # a huge step saturates the update weight at 1: the filter jumps straight to the input
    np.testing.assert_allclose(lowpass_step(lp, new, inten + 1e9, 1e-4, 300.0), new)


def _still(cfg, level, seconds=2.0, w=100, h=100, seed=0, dt_s=0.01):
    from simulator import simulate

    f = np.full((h, w), level, np.float32)
    n = int(round(seconds / dt_s))
    return simulate([f] * (n + 1), [round(k * dt_s * 1e6) for k in range(n + 1)], cfg, seed=seed).events


def test_shot_noise_share_light_and_spread():
    """The shot-noise ON share, its light dependence and its per-pixel spread, against their analytic
    values on a still scene (Poisson counts: tolerances of a few standard errors)."""
    from simulator import SimulatorConfig

    base = dict(pos_threshold=0.2, neg_threshold=0.2, shot_noise_rate_hz=5.0)
    reference = len(_still(SimulatorConfig(**base), 0.0))
    nominal = 5.0 * 2.0 * 100 * 100                                    # the configured rate at w = 0
    w_dark = float(intensity01(np.zeros(1))[0])                        # black maps to w slightly above 0
    assert reference / nominal == pytest.approx(1 - 0.75 * w_dark, abs=0.02)
    dark = _still(SimulatorConfig(**base, shot_noise_on_fraction=0.2), 0.0)
    assert abs(len(dark) - reference) < 5 * np.sqrt(reference)          # the same total, another split
    assert np.mean(dark["p"] > 0) == pytest.approx(0.2, abs=0.01)
    white = _still(SimulatorConfig(**base, shot_noise_white_factor=0.6), 1.0)
    v2e_white = _still(SimulatorConfig(**base), 1.0)                     # v2e's 0.25 at white
    assert len(white) / nominal == pytest.approx(0.6, abs=0.02)
    assert len(v2e_white) / nominal == pytest.approx(SHOT_NOISE_WHITE_FACTOR, abs=0.01)
    spread = _still(SimulatorConfig(**base, shot_noise_sigma_decades=0.5), 0.0, seconds=4.0)
    counts = np.bincount(spread["y"].astype(int) * 100 + spread["x"].astype(int), minlength=10_000)
    m = counts.mean()
    sigma = np.sqrt(np.log1p((counts.var() - m) / m ** 2)) / np.log(10)
    assert sigma == pytest.approx(0.5, abs=0.05)
    assert m / (2 * reference / 10_000) == pytest.approx(np.exp((0.5 * np.log(10)) ** 2 / 2), rel=0.08)  # log-normal mean


@pytest.mark.parametrize("on_fraction", [0.5, 0.2, 0.9])
def test_diffusion_walk_solves_the_exit_problem(on_fraction):
    """sigma and drift give back the rate and ON share through the closed forms of a drifted walk's exit
    from (-C, C): P(up) = 1 / (1 + exp(-2 mu C / sigma^2)), E[T] = (C / mu) tanh(mu C / sigma^2)."""
    from simulator.pixel import diffusion_walk

    c, rate = 0.25, np.array([0.01, 2.0])
    sigma, mu = diffusion_walk(rate, on_fraction, c, c)
    k = 2 * mu * c / sigma ** 2
    np.testing.assert_allclose(1 / (1 + np.exp(-k)), on_fraction, rtol=1e-12)
    mean_exit = c ** 2 / sigma ** 2 if on_fraction == 0.5 else (c / mu) * np.tanh(mu * c / sigma ** 2)
    np.testing.assert_allclose(1 / mean_exit, rate, rtol=1e-12)
    if on_fraction == 0.5:
        np.testing.assert_array_equal(mu, 0.0)


SIEGMUND = 0.5826   # a Gaussian walk's mean overshoot of a barrier, in steps' sigma (Siegmund 1979)


def _walk_run(rate, c, dt_s, side, on_fraction, seconds, seed=1):
    cfg = SimulatorConfig(pos_threshold=c, neg_threshold=c, diffusion_noise_rate_hz=rate,
                          diffusion_noise_on_fraction=on_fraction)
    ev = _still(cfg, 0.5, seconds, side, side, seed, dt_s)
    pix = ev["y"].astype(np.int64) * side + ev["x"]
    order = np.lexsort((ev["t"], pix))
    return pix[order], ev["t"][order] * 1e-6, ev["p"][order]


@pytest.mark.parametrize("on_fraction", [0.5, 0.25])
def test_diffusion_noise_intervals_are_the_walks_exit_times(on_fraction):
    """On a still scene the time from a pixel's first event to its second is the walk's exit from
    (-C, C), started at the reference: mean 1 / rate (the frame-sampled walk's barriers sit 0.58 steps
    further out), ON as often as set, and, without drift, more regular than Poisson: coefficient of
    variation sqrt(2/3) (Poisson: 1)."""
    from simulator.pixel import diffusion_walk

    rate, c, dt_s, side = 1.0, 0.2, 0.0016, 100
    pix, t_s, p = _walk_run(rate, c, dt_s, side, on_fraction, seconds=12.0)
    rank = np.arange(len(pix)) - np.searchsorted(pix, pix)           # each event's place in its pixel
    second = np.flatnonzero(rank == 1)
    assert len(second) >= 0.999 * side * side
    gaps = t_s[second] - t_s[second - 1]
    assert np.mean(p[second] > 0) == pytest.approx(on_fraction, abs=0.02)
    if on_fraction == 0.5:
        sigma = float(diffusion_walk(rate, 0.5, c, c)[0])
        expected = (c + SIEGMUND * sigma * dt_s ** 0.5) ** 2 / sigma ** 2
        assert gaps.mean() == pytest.approx(expected, rel=0.035)
        assert gaps.std() / gaps.mean() == pytest.approx(np.sqrt(2 / 3), abs=0.035)


@pytest.mark.parametrize("on_fraction", [0.5, 0.25])
def test_diffusion_noise_starts_stationary(on_fraction):
    """A sensor switched on long before the first frame: events come at the stationary rate from the
    start (a walk started at the reference would make almost none in the first tenth of an interval:
    it needs a whole threshold of walk), and a pixel's first event comes after the forward recurrence
    time, mean E[T^2] / (2 E[T]) = (1 + CV^2) / 2 intervals without drift."""
    from simulator.pixel import diffusion_walk

    rate, c, dt_s, side = 1.0, 0.2, 0.0016, 100
    sigma = float(diffusion_walk(rate, 0.5, c, c)[0])
    sampled = c ** 2 / (c + SIEGMUND * sigma * dt_s ** 0.5) ** 2          # the frame-sampled walk's rate, / rate
    pix, t_s, p = _walk_run(rate, c, dt_s, side, on_fraction, seconds=8.0 if on_fraction == 0.5 else 0.1)
    early = np.sum(t_s <= 0.1)
    expected = 0.1 * rate * sampled * side * side
    assert abs(early - expected) < 5 * np.sqrt(expected)
    if on_fraction == 0.5:
        first = np.ones(len(pix), bool)
        first[1:] = pix[1:] != pix[:-1]
        assert t_s[first].mean() == pytest.approx((1 + 2 / 3) / 2 / (rate * sampled), rel=0.04)


def test_diffusion_noise_spread_is_log_normal_over_pixels():
    """The per-pixel rate's spread: sigma^2 of each pixel's walk is proportional to its rate."""
    cfg = SimulatorConfig(diffusion_noise_rate_hz=0.5, diffusion_noise_sigma_decades=0.4)
    sim = EventSimulator(cfg, 100, 100, seed=2)
    decades = np.log10(sim._walk_sigma ** 2)
    assert decades.std() == pytest.approx(0.4, abs=0.01)
    assert np.median(decades) == pytest.approx(np.log10(0.5 * 0.2 ** 2), abs=0.01)


def test_diffusion_noise_beside_a_leak_starts_without_a_burst():
    """Both start offsets (the leak's phase, the walk's stationary offset) together stay inside the
    thresholds: the first frame interval has no more events than any later one of the same length."""
    cfg = SimulatorConfig(leak_rate_hz=2.0, leak_rate_sigma_decades=0.0, diffusion_noise_rate_hz=2.0)
    frame = np.full((60, 60), 0.5, np.float32)
    ev = simulate([frame] * 41, [k * 5000 for k in range(41)], cfg, seed=3).events
    per_interval = np.bincount((ev["t"] - 1) // 5000, minlength=40)
    assert per_interval[0] <= per_interval[1:].max()
    assert per_interval.sum() > 200


def test_walk_start_is_the_triangle_without_drift_and_a_leak_phase_with_a_strong_one():
    from simulator.pixel import diffusion_equilibrium_offsets

    rng = np.random.default_rng(0)
    still = diffusion_equilibrium_offsets(rng, np.zeros(200_000))
    assert np.abs(still).mean() == pytest.approx(1 / 3, abs=0.005)        # density 1 - |x| on (-1, 1)
    assert abs(still.mean()) < 0.005
    leak = diffusion_equilibrium_offsets(rng, np.full(200_000, 60.0))
    assert np.mean(leak < 0) < 0.03 and leak.mean() == pytest.approx(0.5, abs=0.02)   # ~uniform on (0, 1)
    mixed = diffusion_equilibrium_offsets(rng, np.array([0.0, 60.0] * 50_000))
    assert mixed[1::2].mean() == pytest.approx(0.5, abs=0.02) and abs(mixed[::2].mean()) < 0.01
