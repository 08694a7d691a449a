"""The realism statistics on streams with known answers, the fast background-activity test against a
readable one, the distances' analytic cases, the DAVIS346 clip against figures measured by an
independent script, and `e4dgs realism` end to end."""
import bisect
import json
import math
from pathlib import Path

import numpy as np
import pytest

from e4dgs.cli import main
from eventio.events import EventStream, make_events
from eventio.realism import distances, isolated_events, pixel_rate_hz, stream_stats

# a DAVIS346 clip beside the checkout (aedat 2.3.0's test data, MIT); the tests that read it skip without it
DAVIS346 = Path(__file__).resolve().parents[3] / "shared" / "reference" / "real-clips" / "davis346_aedat-2.3.0.aedat4"


def _davis346() -> Path:
    if not DAVIS346.is_file():
        pytest.skip(f"{DAVIS346} is absent (the real DAVIS346 clip lives beside the checkout; CI has it)")
    return DAVIS346


def _stream(t, x, y, p, w=32, h=24) -> EventStream:
    order = np.argsort(t, kind="stable")
    return EventStream(make_events(np.asarray(t)[order], np.asarray(x)[order], np.asarray(y)[order],
                                   np.asarray(p)[order]), w, h)


def isolated_events_ref(stream: EventStream, window_us: int = 5000) -> np.ndarray:
    """Readable: per event, look at each of the 8 neighbours' sorted times for one in [t - w, t]."""
    e = stream.events
    times: dict[tuple[int, int], list[int]] = {}
    for t, x, y in zip(e["t"].tolist(), e["x"].tolist(), e["y"].tolist()):
        times.setdefault((x, y), []).append(t)
    for v in times.values():
        v.sort()
    out = []
    for t, x, y in zip(e["t"].tolist(), e["x"].tolist(), e["y"].tolist()):
        near = False
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                ts = times.get((x + dx, y + dy)) if (dx, dy) != (0, 0) else None
                if ts and bisect.bisect_right(ts, t) > bisect.bisect_left(ts, t - window_us):
                    near = True
        out.append(not near)
    return np.array(out, bool)


def test_a_pixel_firing_every_millisecond_with_alternating_polarity():
    n = 101
    s = _stream(np.arange(n) * 1000, np.full(n, 5), np.full(n, 5), np.where(np.arange(n) % 2, 1, -1))
    st = stream_stats(s)
    assert st.duration_s == pytest.approx(0.1) and st.rate_ev_per_s == pytest.approx(1010.0)
    assert st.iei_min_us == st.iei_p1_us == st.iei_p50_us == 1000 and st.same_polarity_fraction == 0.0
    assert st.active_fraction == pytest.approx(1 / (32 * 24)) and st.on_fraction == pytest.approx(50 / 101)
    assert np.all(st.log_iei == 3.0) and st.ba_fraction == 1.0          # nothing fires around it
    assert st.rate_series.sum() == n and len(st.rate_series) == 11


def test_background_activity_is_causal_and_needs_a_neighbour_not_the_pixel_itself():
    # (10,10) at 0; (11,10) at 3 ms (a neighbour 3 ms before: not isolated); (10,10) at 4 ms (its
    # neighbour fired 1 ms before); (20,20) at 9 ms alone; (10,10) again at 20 ms (the last neighbour
    # event is 17 ms old)
    s = _stream([0, 3000, 4000, 9000, 20000], [10, 11, 10, 20, 10], [10, 10, 10, 20, 10], [1, 1, -1, 1, 1])
    assert isolated_events(s).tolist() == [True, False, False, True, True]
    assert isolated_events_ref(s).tolist() == [True, False, False, True, True]


def test_the_fast_background_test_equals_the_readable_one_on_a_random_stream():
    rng = np.random.default_rng(4)
    n = 3000
    s = _stream(rng.integers(0, 200_000, n), rng.integers(0, 32, n), rng.integers(0, 24, n), rng.choice([-1, 1], n))
    np.testing.assert_array_equal(isolated_events(s), isolated_events_ref(s))


def test_a_hot_pixel_is_found_and_the_static_pixel_rate_is_counted_on_the_mask():
    rng = np.random.default_rng(0)
    t = np.concatenate([np.arange(0, 1_000_000, 1000), rng.integers(0, 1_000_000, 400)])
    x = np.concatenate([np.full(1000, 3), rng.integers(0, 32, 400)])
    y = np.concatenate([np.full(1000, 4), rng.integers(0, 24, 400)])
    s = _stream(t, x, y, np.ones(len(t), int))
    st = stream_stats(s)
    at_hot = int(np.sum((x == 3) & (y == 4)))                  # its 1000 and any random ones
    assert st.hot_pixels == 1 and st.pixel_rate_max_hz == pytest.approx(at_hot / (t.max() - t.min()) * 1e6)
    mask = np.zeros((24, 32), bool)
    mask[4, 3] = True
    assert pixel_rate_hz(s, mask) == pytest.approx(at_hot / ((t.max() - t.min()) / 1e6))


def test_distances_are_zero_to_itself_and_log10_of_a_rate_factor():
    rng = np.random.default_rng(1)
    n = 4000
    t, x, y = rng.integers(0, 1_000_000, n), rng.integers(0, 32, n), rng.integers(0, 24, n)
    a = _stream(t, x, y, rng.choice([-1, 1], n))
    st = stream_stats(a)
    d = distances(st, st)
    assert d["w1_log_rate"] == 0 and d["w1_log_iei"] == 0 and d["rate_correlation"] == pytest.approx(1.0)
    assert all(v == 0 or math.isnan(v) for v in d["relative"].values())
    # the same events in half the time: every pixel's rate doubles, every interval halves
    b = _stream(t // 2, x, y, a.events["p"][np.argsort(np.argsort(t, kind="stable"), kind="stable")])
    d = distances(stream_stats(b), st)
    assert d["w1_log_rate"] == pytest.approx(math.log10(2), abs=1e-3)
    assert d["relative"]["rate_ev_per_s"] == pytest.approx(1.0, abs=1e-3) and d["rate_correlation"] is None


def test_the_davis346_clip_has_the_figures_an_independent_script_measured():
    from eventio.formats import read_recording

    st = stream_stats(read_recording(_davis346())[0])
    assert st.n_events == 78_830 and round(st.on_fraction, 3) == 0.523 and round(st.active_fraction, 3) == 0.086
    assert st.iei_min_us == 974 and st.iei_p1_us == 1907 and st.iei_p50_us == 10861
    assert round(st.same_polarity_fraction, 3) == 0.747 and round(st.ba_fraction, 3) == 0.172
    assert round(st.ba_rate_hz, 3) == 0.064 and round(st.pixel_rate_max_hz, 1) == 20.3 and st.hot_pixels == 0


def test_the_realism_command_prints_both_and_writes_its_files(tmp_path, capsys):
    from eventio.h5io import write_events

    rng = np.random.default_rng(2)
    n = 5000
    sim = _stream(rng.integers(0, 2_000_000, n), rng.integers(0, 346, n), rng.integers(0, 260, n),
                  rng.choice([-1, 1], n), 346, 260)
    write_events(tmp_path / "sim.h5", sim)
    real = _davis346()
    assert main(["realism", str(tmp_path / "sim.h5"), str(real), "--out", str(tmp_path / "r")]) == 0
    said = capsys.readouterr().out
    assert f"| statistic | sim.h5 | {real.name} | relative error |" in said and "Wasserstein-1" in said
    doc = json.loads((tmp_path / "r" / "realism.json").read_text())
    assert doc["recordings"][real.name]["n_events"] == 78_830 and doc["distances"]["w1_log_rate"] > 0
    assert (tmp_path / "r" / "realism.png").read_bytes()[:4] == b"\x89PNG"
    with pytest.raises(SystemExit, match="missing.h5: no such file"):
        main(["realism", str(tmp_path / "missing.h5")])


def test_recordings_of_different_sensors_are_compared_with_a_warning(tmp_path, capsys):
    from eventio.h5io import write_events

    rng = np.random.default_rng(0)
    for name, (w, h) in (("small.h5", (16, 12)), ("big.h5", (64, 48))):
        n = 500
        write_events(tmp_path / name, EventStream(make_events(np.sort(rng.integers(0, 100_000, n)), rng.integers(0, w, n),
                                                              rng.integers(0, h, n), rng.choice([-1, 1], n)), w, h))
    assert main(["realism", str(tmp_path / "small.h5"), str(tmp_path / "big.h5")]) == 0
    err = capsys.readouterr().err
    assert "small.h5 is 16x12 pixels and big.h5 64x48" in err
