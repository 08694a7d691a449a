import h5py
import numpy as np
import pytest

from simulator import SimulatorConfig, simulate
from eventio.events import EventStream, make_events
from eventio.export import from_tonic, read_e2vid_txt, read_npz, to_tonic, write_e2vid_txt, write_npz
from eventio.h5io import EventFileError, EventFileWriter, read_events, read_info, read_window, write_events


def random_stream(rng, n=20000, width=40, height=30, t0=0, span_us=250_000):
    t = np.sort(rng.integers(t0, t0 + span_us, n))
    return EventStream(make_events(t, rng.integers(0, width, n), rng.integers(0, height, n),
                                   rng.choice(np.array([-1, 1], np.int8), n)), width, height)


def test_round_trip_whole_and_windows(tmp_path, rng):
    s = random_stream(rng, t0=2**33)
    path = tmp_path / "ev.h5"
    write_events(path, s, t_offset_us=2**33, attrs={"sim_pos_threshold": 0.2, "seed": 4})
    back = read_events(path)
    assert np.array_equal(back.events, s.events) and (back.width, back.height) == (40, 30)
    for t0, t1 in [(2**33, 2**33 + 1000), (2**33 + 12_345, 2**33 + 99_999), (2**33 - 50, 2**33 + 10),
                   (2**33 + 240_000, 2**33 + 10**7), (2**33 + 5000, 2**33 + 5000), (2**33 + 777, 2**33 + 778)]:
        assert np.array_equal(read_window(path, t0, t1).events, s.window(t0, t1).events)
    info = read_info(path)
    assert info["seed"] == 4 and info["sim_pos_threshold"] == 0.2 and info["n_events"] == len(s)


def test_ms_to_idx_is_first_index_at_or_after_each_millisecond(tmp_path, rng):
    s = random_stream(rng, n=5000, span_us=37_500)
    path = tmp_path / "ev.h5"
    with EventFileWriter(path, 40, 30, t_offset_us=0) as w:
        for chunk in np.array_split(s.events, 17):  # many small appends
            w.append(chunk)
        w.close(t_end_us=45_000)
    with h5py.File(path) as f:
        ms_to_idx = f["ms_to_idx"][:]
        t = f["events/t"][:]
        assert set(f["events/p"][:].tolist()) <= {0, 1}
    assert len(ms_to_idx) >= 46
    for m, idx in enumerate(ms_to_idx):
        assert idx == np.searchsorted(t, m * 1000, side="left")


def test_window_read_does_not_load_the_whole_file(tmp_path, rng, monkeypatch):
    s = random_stream(rng, n=200_000, span_us=2_000_000)
    path = tmp_path / "ev.h5"
    write_events(path, s)
    reads = []
    original = h5py.Dataset.__getitem__

    def spy(self, key):
        if self.name == "/events/t" and isinstance(key, slice):
            reads.append((key.stop or self.shape[0]) - (key.start or 0))
        return original(self, key)

    monkeypatch.setattr(h5py.Dataset, "__getitem__", spy)
    w = read_window(path, 1_000_000, 1_002_000)
    assert np.array_equal(w.events, s.window(1_000_000, 1_002_000).events)
    assert sum(reads) < 2_000  # a few milliseconds of events, not 200k


def test_failed_write_leaves_nothing(tmp_path, rng):
    path = tmp_path / "ev.h5"
    s = random_stream(rng, n=100)
    with pytest.raises(RuntimeError):
        with EventFileWriter(path, 40, 30) as w:
            w.append(s.events)
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_writer_rejects_out_of_order_and_invalid_events(tmp_path, rng):
    s = random_stream(rng, n=100)
    with EventFileWriter(tmp_path / "a.h5", 40, 30) as w:
        w.append(s.events[50:])
        with pytest.raises(EventFileError, match="before the last written event"):
            w.append(s.events[:50])
    with pytest.raises(Exception, match="out of range"):
        with EventFileWriter(tmp_path / "b.h5", 10, 10) as w:
            w.append(s.events)
    assert not (tmp_path / "b.h5").exists()


def test_reader_errors_name_the_file(tmp_path):
    with pytest.raises(EventFileError, match="no such event file"):
        read_events(tmp_path / "missing.h5")
    bad = tmp_path / "bad.h5"
    with h5py.File(bad, "w") as f:
        f.create_dataset("events/x", data=np.zeros(2))
    with pytest.raises(EventFileError, match="missing dataset 'events/y'"):
        read_events(bad)
    junk = tmp_path / "junk.h5"
    junk.write_text("not hdf5")
    with pytest.raises(EventFileError, match="not a readable HDF5"):
        read_events(junk)


def test_exporters_round_trip(tmp_path, rng):
    s = random_stream(rng, n=3000, t0=3_000_000_123)
    tonic, size = to_tonic(s)
    assert size == (40, 30, 2) and tonic.dtype.names == ("x", "y", "t", "p") and tonic["p"].dtype == bool
    assert np.array_equal(from_tonic(tonic, size).events, s.events)
    txt = write_e2vid_txt(tmp_path / "ev.txt", s)
    lines = txt.read_text().splitlines()
    assert lines[0] == "40 30"
    t_s, x, y, p = lines[1].split()
    assert float(t_s) == pytest.approx(s.events["t"][0] / 1e6, abs=1e-6) and p in ("0", "1")
    assert np.array_equal(read_e2vid_txt(txt).events, s.events)
    assert np.array_equal(read_npz(write_npz(tmp_path / "ev.npz", s)).events, s.events)


def test_simulated_stream_round_trip_with_simulator_attributes(tmp_path, rng):
    frames = np.exp(np.cumsum(rng.normal(0, 0.4, size=(12, 9, 11)), axis=0))
    cfg = SimulatorConfig(refractory_us=50)
    s = simulate(frames, np.arange(12) * 333, cfg)
    path = write_events(tmp_path / "sim.h5", s, attrs={f"sim_{k}": v for k, v in cfg.__dict__.items()})
    assert np.array_equal(read_events(path).events, s.events)
    assert read_info(path)["sim_refractory_us"] == 50


def test_the_same_events_give_the_same_bytes(tmp_path, rng):
    """Datasets are compared by SHA-256 (serial vs Ray, run vs run): the file must be a function of the
    events. Its filters are deterministic ones (gzip after a shuffle, not LZF, whose compressor reads an
    uninitialised hash table) and the last chunk's unused tail is zero-filled, not stale memory."""
    s = random_stream(rng, n=70_000)                     # more than one 65,536-event chunk
    for name in ("a.h5", "b.h5"):
        with EventFileWriter(tmp_path / name, s.width, s.height) as w:
            for i in range(0, len(s), 9_999):             # appends that cut chunks mid-way
                w.append(s.events[i:i + 9_999])
            w.close()
    assert (tmp_path / "a.h5").read_bytes() == (tmp_path / "b.h5").read_bytes()
    with h5py.File(tmp_path / "a.h5") as f:
        for name in ("events/x", "events/y", "events/t", "events/p", "ms_to_idx"):
            d = f[name]
            assert (d.compression, d.compression_opts, d.shuffle, d.fillvalue) == ("gzip", 1, True, 0), name
            assert d.id.get_create_plist().get_fill_time() == h5py.h5d.FILL_TIME_ALLOC, name


def test_e2vid_text_writes_negative_times_as_computed_by_hand(tmp_path):
    """The sign is written apart from the digits: -1939 us is -0.001939 s (divmod would give -1.998061),
    and our reader reads a correct negative time back (it used to read -0.001939 as +1939 us)."""
    from eventio.events import EventStream, make_events
    from eventio.export import parse_seconds, seconds_text

    t = [-2_000_000, -1_000_001, -1939, -5, 0, 5, 1_000_000]
    s = EventStream(make_events(t, [0, 1, 2, 3, 0, 1, 2], [0] * 7, [1, -1, 1, -1, 1, -1, 1]), 4, 2)
    lines = write_e2vid_txt(tmp_path / "neg.txt", s).read_text().splitlines()
    assert [ln.split()[0] for ln in lines[1:]] == ["-2.000000", "-1.000001", "-0.001939", "-0.000005", "0.000000",
                                                  "0.000005", "1.000000"]
    assert read_e2vid_txt(tmp_path / "neg.txt").events["t"].tolist() == t
    assert [parse_seconds(v) for v in ("-0.001939", "2", "1.5", "+0.25", ".5")] == [-1939, 2_000_000, 1_500_000,
                                                                                 250_000, 500_000]
    assert seconds_text(-1) == "-0.000001"
    assert parse_seconds("17179.869182999999") == 17_179_869_183 and parse_seconds("1.0000004") == 1_000_000
    for bad in ("abc", "-", "1e-3", "1.5.2"):
        with pytest.raises(ValueError):
            parse_seconds(bad)
