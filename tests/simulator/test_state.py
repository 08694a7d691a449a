"""Checkpoints: a simulator continued from its state, and the crash-safe event writer."""
import numpy as np
import pytest

from simulator import EventSimulator, SimulatorConfig
from eventio.h5io import read_events
from common.checkpoint import JobCheckpoint
from simulator.resumable import EventSpool

NOISY = SimulatorConfig(threshold_sigma=0.04, lowpass_cutoff_hz=400.0, refractory_us=60, leak_rate_hz=40.0,
                        shot_noise_rate_hz=800.0, hot_pixel_fraction=0.05, hot_pixel_rate_hz=900.0,
                        diffusion_noise_rate_hz=300.0, diffusion_noise_on_fraction=0.4)


@pytest.mark.parametrize("config", [SimulatorConfig(), NOISY])
def test_state_round_trip_continues_identically(config, rng):
    frames = np.exp(np.cumsum(rng.normal(0, 0.3, size=(20, 10, 12)), axis=0)).astype(np.float32)
    t = np.arange(20) * 333
    whole = EventSimulator(config, 12, 10, seed=3)
    expected = [whole.push(f, int(ts)) for f, ts in zip(frames, t)]
    first = EventSimulator(config, 12, 10, seed=3)
    got = [first.push(f, int(ts)) for f, ts in zip(frames[:9], t[:9])]
    state = first.state_dict()
    second = EventSimulator(config, 12, 10, seed=3)
    second.load_state_dict(state)
    got += [second.push(f, int(ts)) for f, ts in zip(frames[9:], t[9:])]
    assert np.array_equal(np.concatenate(got), np.concatenate(expected))


def test_state_of_another_sensor_is_refused():
    state = EventSimulator(SimulatorConfig(), 12, 10, seed=3).state_dict()
    for other in (EventSimulator(SimulatorConfig(), 12, 10, seed=4), EventSimulator(NOISY, 12, 10, seed=3),
                  EventSimulator(SimulatorConfig(), 10, 12, seed=3)):
        with pytest.raises(ValueError, match="does not match"):
            other.load_state_dict(state)


def test_event_spool_resumes_at_the_synced_count(tmp_path, rng):
    from eventio.events import make_events

    def batch(t0, n):
        return make_events(t0 + np.arange(n), rng.integers(0, 8, n), rng.integers(0, 6, n), np.ones(n, np.int8))

    out = tmp_path / "ev.h5"
    a, b, c = batch(0, 100), batch(100, 50), batch(150, 70)
    spool = EventSpool(out, 8, 6)
    spool.append(a)
    count = spool.sync()
    spool.append(b)          # written after the last sync: lost in the "crash"
    spool.close()
    assert not out.exists()
    spool = EventSpool(out, 8, 6, resume_count=count)
    assert spool.n_events == 100
    with pytest.raises(ValueError, match="out of time order"):
        spool.append(batch(50, 3))
    spool.append(b)
    spool.append(c)
    spool.finish(t_end_us=300)
    assert np.array_equal(read_events(out).events, np.concatenate([a, b, c]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ev.h5"]
    with pytest.raises(ValueError, match="cannot resume"):
        EventSpool(tmp_path / "other.h5", 8, 6, resume_count=5)


def test_job_checkpoint_is_tied_to_its_fingerprint(tmp_path):
    ckpt = JobCheckpoint(tmp_path / "job.npz", "inputs-1")
    assert ckpt.load() is None
    ckpt.save({"next_frame": 7, "level": np.arange(3.0), "note": "x"})
    state = JobCheckpoint(tmp_path / "job.npz", "inputs-1").load()
    assert int(state["next_frame"]) == 7 and state["level"].tolist() == [0.0, 1.0, 2.0] and str(state["note"]) == "x"
    assert JobCheckpoint(tmp_path / "job.npz", "inputs-2").load() is None
    assert not (tmp_path / "job.npz").exists()  # a stale checkpoint is dropped
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    assert JobCheckpoint(tmp_path / "bad.npz", "x").load() is None
