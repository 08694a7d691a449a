"""The readout stage (simulator.readout): latency, jitter, semi-synchronous steps and a bandwidth
limit, each checked against its analytic answer; the compiled FIFO against the reference; the
stream's time order and content across frame intervals, checkpoints and the end of the recording."""
import math

import numpy as np
import pytest

from simulator import EventSimulator, SimulatorConfig, simulate
from simulator.readout import Readout, fifo_fast, fifo_ref, round_up_to_period

H, W = 12, 16


def frames(n=40, seed=0):
    """A bright bar sweeping across a dark field: many events at known pixels."""
    rng = np.random.default_rng(seed)
    base = 0.05 + 0.01 * rng.random((H, W))
    out = []
    for i in range(n):
        f = base.copy()
        f[:, (i * W) // n] = 0.9
        out.append(f)
    return np.array(out), [1000 * i for i in range(n)]


def keyset(ev):
    return sorted(zip(ev["x"].tolist(), ev["y"].tolist(), ev["p"].tolist()))


def test_fifo_fast_equals_reference():
    rng = np.random.default_rng(3)
    arrival = np.sort(rng.integers(0, 20_000, 5_000)).astype(np.int64)
    for period, max_delay in ((7.3, 0), (7.3, 500), (0.5, 0), (40.0, 40)):
        a = fifo_ref(arrival, -math.inf, period, max_delay)
        b = fifo_fast(arrival, -math.inf, period, max_delay)
        assert np.array_equal(a[0][a[1]], b[0][b[1]]) and np.array_equal(a[1], b[1])
        assert a[2] == pytest.approx(b[2])


def test_fifo_burst_analytic():
    """N events at once through a server of rate R: the k-th out at k / R; those waiting longer than
    the buffer's delay are dropped, the rest spaced exactly."""
    n, rate_hz = 100, 1e5                           # one event per 10 us
    out, kept, free = fifo_ref(np.zeros(n, np.int64), -math.inf, 1e6 / rate_hz, 0)
    assert kept.all() and np.array_equal(out, np.arange(n) * 10) and free == pytest.approx(1000.0)
    out, kept, _ = fifo_ref(np.zeros(n, np.int64), -math.inf, 1e6 / rate_hz, 255)
    assert kept.sum() == 26 and np.array_equal(out[kept], np.arange(26) * 10)   # waits 0 .. 250 us kept


def test_round_up_to_period():
    t = np.array([0, 1, 199, 200, 201, 1000], np.int64)
    assert round_up_to_period(t, 200).tolist() == [0, 200, 200, 200, 400, 1000]


def test_constant_latency_shifts_every_event():
    f, t = frames()
    plain = simulate(f, t, SimulatorConfig()).events
    late = simulate(f, t, SimulatorConfig(latency_us=150.0)).events
    assert len(late) == len(plain) > 100
    assert np.array_equal(late["t"], plain["t"] + 150)          # in order without a sort: the pixels' own
    assert keyset(late) == keyset(plain)


def test_jitter_bounded_and_centred():
    f, t = frames()
    plain = simulate(f, t, SimulatorConfig(), seed=1).events
    jit = simulate(f, t, SimulatorConfig(latency_us=100.0, latency_jitter_us=30.0), seed=1).events
    assert np.all(np.diff(jit["t"]) >= 0) and keyset(jit) == keyset(plain)
    # the same events: match each by pixel, polarity and order at its pixel
    order_p = np.lexsort((plain["t"], plain["p"], plain["y"], plain["x"]))
    order_j = np.lexsort((jit["t"], jit["p"], jit["y"], jit["x"]))
    delay = jit["t"][order_j].astype(float) - plain["t"][order_p]
    assert delay.min() >= 100 - 90 - 1 and delay.max() <= 100 + 90 + 1
    assert abs(delay.mean() - 100) < 5 and 20 < delay.std() < 40


def test_semi_synchronous_steps():
    f, t = frames()
    plain = simulate(f, t, SimulatorConfig()).events
    steps = simulate(f, t, SimulatorConfig(readout_period_us=200)).events
    assert np.all(steps["t"] % 200 == 0) and np.all(np.diff(steps["t"]) >= 0)
    assert np.array_equal(np.sort(steps["t"]), np.sort(-(-plain["t"] // 200) * 200))


def test_bandwidth_delays_and_drops():
    f, t = frames()
    plain = simulate(f, t, SimulatorConfig()).events
    rate = 0.3 * len(plain) / (t[-1] * 1e-6)       # a third of the mean rate the scene asks for
    slow = simulate(f, t, SimulatorConfig(max_event_rate_hz=rate)).events
    assert len(slow) == len(plain) and np.all(np.diff(slow["t"]) >= 0)
    gaps = np.diff(slow["t"])
    assert gaps.min() >= math.floor(1e6 / rate) - 1          # one event per service time
    dropped = simulate(f, t, SimulatorConfig(max_event_rate_hz=rate, max_readout_delay_us=100)).events
    assert 0 < len(dropped) < len(plain)


def test_push_across_intervals_equals_one_pass():
    """Held-back events come out later, in time order: the stream equals one pass of the readout over
    every pixel event at once; a checkpoint restored mid-way changes nothing."""
    f, t = frames(60)
    cfg = SimulatorConfig(latency_us=700.0, latency_jitter_us=200.0, readout_period_us=300, max_event_rate_hz=2e5,
                          max_readout_delay_us=3000)
    whole = simulate(f, t, cfg, seed=4).events
    assert np.all(np.diff(whole["t"]) >= 0)
    pixels = simulate(f, t, SimulatorConfig(), seed=4).events
    once = Readout(cfg, EventSimulator(cfg, W, H, seed=4).readout.rng)
    ref = np.concatenate([once.push(pixels, int(t[-1])), once.flush()])
    assert np.array_equal(whole, ref)
    sim = EventSimulator(cfg, W, H, seed=4)
    parts = [sim.push(f[i], t[i]) for i in range(30)]
    state = sim.state_dict()
    resumed = EventSimulator(cfg, W, H, seed=4)
    resumed.load_state_dict(state)
    parts += [resumed.push(f[i], t[i]) for i in range(30, 60)] + [resumed.flush()]
    assert np.array_equal(np.concatenate(parts), whole)


def test_on_off_mismatch_apart():
    sim = EventSimulator(SimulatorConfig(pos_threshold=0.3, neg_threshold=0.2, pos_threshold_sigma=0.05,
                                         neg_threshold_sigma=0.0), 200, 100)
    assert sim.c_pos.std() == pytest.approx(0.05, rel=0.05) and np.ptp(sim.c_neg) == 0
    assert sim.c_pos.mean() == pytest.approx(0.3, abs=0.002) and np.all(sim.c_neg == 0.2)


def test_off_means_the_same_stream():
    """Every readout field off: no readout stage, and the noise and mismatch streams are the ones the
    simulator drew before the readout had its own (the first two of the seed's spawned streams)."""
    cfg = SimulatorConfig(threshold_sigma=0.03, shot_noise_rate_hz=5.0)
    assert not cfg.has_readout and EventSimulator(cfg, W, H).readout is None
    two = [np.random.default_rng(s).random(4) for s in np.random.SeedSequence(7).spawn(2)]
    three = [np.random.default_rng(s).random(4) for s in np.random.SeedSequence(7).spawn(3)]
    assert all(np.array_equal(a, b) for a, b in zip(two, three[:2]))
    sim = EventSimulator(cfg, W, H, seed=7)
    expected = np.maximum(np.random.default_rng(np.random.SeedSequence(7).spawn(2)[0]).normal(0.2, 0.03, W * H), 0.01)
    assert np.array_equal(sim.c_pos, expected)


def test_checkpoint_from_before_the_later_fields_resumes():
    """A checkpoint written before the readout and shot-noise fields existed (its config without them)
    is the same sensor when they are off: it resumes; a changed field still refuses."""
    import json

    from simulator.config import LATER_FIELDS

    f, t = frames()
    cfg = SimulatorConfig(threshold_sigma=0.03)
    sim = EventSimulator(cfg, W, H, seed=1)
    for i in range(5):
        sim.push(f[i], t[i])
    state = sim.state_dict()
    old = json.loads(state["config"])
    assert not set(old) & set(LATER_FIELDS)                 # written as before those fields existed
    EventSimulator(cfg, W, H, seed=1).load_state_dict(state)
    with pytest.raises(ValueError, match="config"):
        EventSimulator(SimulatorConfig(threshold_sigma=0.03, latency_us=5.0), W, H, seed=1).load_state_dict(state)
