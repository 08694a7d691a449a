"""The compiled kernel reproduces the per-pixel reference exactly, in every configuration."""
import numpy as np
import pytest

from simulator import EventSimulator, SimulatorConfig
from simulator.kernel_ref import emit_events_ref
from simulator.kernels import Workspace, emit_events

NOISE_FREE = {
    "ideal": {},
    "mismatch": dict(threshold_sigma=0.05),
    "asymmetric": dict(pos_threshold=0.25, neg_threshold=0.15),
    "lowpass": dict(lowpass_cutoff_hz=300.0),
    "refractory": dict(refractory_us=150),
    "leak": dict(leak_rate_hz=200.0),
    "linlog": dict(log_mode="linlog"),
    "everything": dict(threshold_sigma=0.03, lowpass_cutoff_hz=500.0, refractory_us=90, leak_rate_hz=50.0,
                       log_mode="linlog"),
}
NOISY = {
    "shot": dict(shot_noise_rate_hz=400.0),
    "hot": dict(hot_pixel_fraction=0.05, hot_pixel_rate_hz=3000.0),
    "noise+refractory": dict(shot_noise_rate_hz=500.0, hot_pixel_fraction=0.05, hot_pixel_rate_hz=2000.0,
                             refractory_us=120, threshold_sigma=0.03, leak_rate_hz=30.0),
    "diffusion": dict(diffusion_noise_rate_hz=300.0, diffusion_noise_on_fraction=0.3,
                      diffusion_noise_sigma_decades=0.3, refractory_us=60, leak_rate_hz=20.0),
}


def random_sequence(rng, n_frames=14, h=11, w=13, dtype=np.float64):
    """Random walks of log intensity with irregular frame intervals, dark and bright pixels."""
    log_i = np.cumsum(rng.normal(0, 0.35, size=(n_frames, h, w)), axis=0) + rng.uniform(-6, 1, size=(1, h, w))
    frames = np.exp(log_i).astype(dtype)
    frames[:, 0, 0] = 0.0  # a black pixel
    t = np.cumsum(rng.integers(1, 700, size=n_frames)) + 10**6
    return frames, t


def run(config, frames, t, backend, seed=7, **kw):
    sim = EventSimulator(config, frames.shape[2], frames.shape[1], seed=seed, backend=backend)
    if kw:
        sim._emit_kwargs.update(kw)
    return np.concatenate([sim.push(f, int(ts)) for f, ts in zip(frames, t)])


@pytest.mark.parametrize("name", sorted(NOISE_FREE) + sorted(NOISY))
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_fast_equals_reference(name, dtype, rng):
    config = SimulatorConfig(**{**NOISE_FREE, **NOISY}[name])
    for _ in range(3):
        frames, t = random_sequence(rng, dtype=dtype)
        ref = run(config, frames, t, "ref")
        fast = run(config, frames, t, "fast")
        assert len(ref) > 0
        assert np.array_equal(ref, fast)


@pytest.mark.parametrize("n_chunks, capacity", [(1, 1), (3, 4), (5, 1 << 12)])
def test_chunking_and_buffer_growth_do_not_change_events(n_chunks, capacity, rng):
    frames, t = random_sequence(rng, n_frames=10, h=17, w=19)
    for config in (SimulatorConfig(), SimulatorConfig(**NOISE_FREE["everything"]), SimulatorConfig(**NOISY["noise+refractory"])):
        ref = run(config, frames, t, "ref")
        fast = run(config, frames, t, "fast", workspace=Workspace(n_chunks=n_chunks, capacity=capacity))
        assert np.array_equal(ref, fast)


def test_kernel_state_updates_match(rng):
    P = 300
    L0, L1 = rng.normal(0, 1, P), rng.normal(0, 1, P)
    args = dict(c_pos=np.full(P, 0.2), c_neg=rng.uniform(0.1, 0.3, P), t0_us=5000, t1_us=5400,
                refractory_us=40, noise_pix=np.empty(0, np.int64), noise_t=np.empty(0, np.int64),
                noise_p=np.empty(0, np.int8), width=20)
    base0 = L0 + rng.uniform(-0.19, 0.19, P)
    ready0 = np.where(rng.random(P) < 0.3, 5000 + rng.integers(0, 500, P), -1)
    states = []
    for fn in (emit_events_ref, emit_events):
        base, ready = base0.copy(), ready0.copy()
        ev = fn(L0, L1, base, ready, **args)
        states.append((ev, base, ready))
    assert np.array_equal(states[0][0], states[1][0])
    assert np.array_equal(states[0][1], states[1][1]) and np.array_equal(states[0][2], states[1][2])


def test_long_frame_interval_uses_the_merge_sort_path(rng):
    # an interval far longer than the event count: sorted without a per-microsecond histogram
    frames, _ = random_sequence(rng, n_frames=3, h=5, w=6)
    t = np.array([0, 50_000_000, 100_000_000])
    ref = run(SimulatorConfig(), frames, t, "ref")
    assert np.array_equal(ref, run(SimulatorConfig(), frames, t, "fast"))


@pytest.mark.parametrize("threshold_dn", [20.0, 2.0])      # the min form (thr > e) and the blend
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_fast_linlog_equals_the_reference(threshold_dn, dtype):
    from simulator.pixel import linlog_response, linlog_response_ref

    rng = np.random.default_rng(3)
    inten = (rng.random((26, 35)) ** 3 * 1.5).astype(dtype)
    inten[0, :5] = 0.0
    inten[1, :5] = threshold_dn / 255.0                      # on the knee
    inten[2, :5] = np.nextafter(dtype(threshold_dn / 255.0), dtype(1.0))
    ref = linlog_response_ref(inten, threshold_dn, 255.0)
    scratch = np.full((2,) + inten.shape, np.nan, dtype)
    out = np.empty_like(inten)
    fast = linlog_response(inten, threshold_dn, 255.0, out=out, scratch=scratch)
    assert fast is out and fast.dtype == dtype        # computed in out's precision, like log_response
    # float64: the min form may differ from the reference by an ulp at DN == thr, nowhere else;
    # float32: rounding of float32 arithmetic (a few ulps)
    np.testing.assert_allclose(fast, ref.astype(dtype), rtol=4 * np.finfo(dtype).eps, atol=4 * np.finfo(dtype).eps)
    if dtype == np.float64:
        assert np.count_nonzero(fast != ref) <= 5
    assert np.all(fast[0, :5] == 0.0)                        # exactly zero in the dark
    scratch64 = np.zeros((2,) + inten.shape)
    again = linlog_response(inten, threshold_dn, 255.0, scratch=scratch64)
    assert again.dtype == np.float64
    np.testing.assert_allclose(again, ref, rtol=2e-16, atol=0)
    again[...] = -1.0                                        # the result is not the caller's scratch
    assert not np.shares_memory(again, scratch64)
    np.testing.assert_allclose(linlog_response(inten, threshold_dn, 255.0), ref, rtol=2e-16, atol=0)
