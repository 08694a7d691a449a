"""Round-trip properties of every event writer (Hypothesis): any stream a writer accepts, its reader
returns exactly; any stream its readers would refuse (unsorted times, x or y outside the sensor,
polarity not +-1), its writer refuses before writing anything."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from eventio import EventStream, make_events
from eventio.events import EVENT_DTYPE, EventValidationError
from eventio.formats import FORMATS, SUFFIX, read_recording, same_events, write_stream

EXAMPLES = 25          # per format: 8 formats x (25 valid + 25 invalid) streams


@st.composite
def streams(draw, max_events: int = 60):
    """A valid stream: sensor up to 64 x 48 (EVT's 11-bit fields hold it), sorted non-negative times
    (microseconds, from 0 or Unix-epoch-like starts), polarities +-1."""
    w, h = draw(st.integers(1, 64)), draw(st.integers(1, 48))
    n = draw(st.integers(0, max_events))
    start = draw(st.sampled_from([0, 1, 1_700_000_000_000_000]))
    gaps = draw(st.lists(st.integers(0, 5_000), min_size=n, max_size=n))
    t = start + np.cumsum(np.array(gaps, np.int64))
    x = draw(st.lists(st.integers(0, w - 1), min_size=n, max_size=n))
    y = draw(st.lists(st.integers(0, h - 1), min_size=n, max_size=n))
    p = draw(st.lists(st.sampled_from([-1, 1]), min_size=n, max_size=n))
    return EventStream(make_events(t, x, y, p), w, h)


@st.composite
def broken_streams(draw):
    """A valid stream of at least two events with one rule broken: time order, x, y or polarity."""
    s = draw(streams().filter(lambda s: len(s) >= 2 and s.events["t"][-1] > s.events["t"][0]))
    e = s.events.copy()
    i = draw(st.integers(0, len(e) - 1))
    rule = draw(st.sampled_from(["order", "x", "y", "p"]))
    if rule == "order":
        e = e[::-1].copy()
    elif rule == "x":
        e["x"][i] = s.width + draw(st.integers(0, 3))
    elif rule == "y":
        e["y"][i] = s.height + draw(st.integers(0, 3))
    else:
        e["p"][i] = draw(st.sampled_from([0, 2, -2]))
    return EventStream(np.ascontiguousarray(e, EVENT_DTYPE), s.width, s.height)


SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.mark.parametrize("fmt", FORMATS)
@SETTINGS
@given(s=streams())
def test_what_a_writer_accepts_its_reader_returns(fmt, s, tmp_path_factory):
    out = tmp_path_factory.mktemp(fmt) / f"rec{SUFFIX[fmt]}"
    if fmt == "rosbag2":
        out = out.with_name("rec_bag")
    write_stream(out, s, fmt)
    back, found = read_recording(out)
    assert found == fmt and same_events(back, s)


@pytest.mark.parametrize("fmt", FORMATS)
@SETTINGS
@given(s=broken_streams())
def test_what_a_reader_refuses_its_writer_refuses_before_writing(fmt, s, tmp_path_factory):
    folder = tmp_path_factory.mktemp(fmt)
    out = folder / (f"rec{SUFFIX[fmt]}" if fmt != "rosbag2" else "rec_bag")
    with pytest.raises(EventValidationError):
        write_stream(out, s, fmt)
    assert list(folder.iterdir()) == []                     # nothing written, no temporary left


def test_api_samples_refuse_clearly(tmp_path):
    """make_events with columns of different lengths or fractional times, read_window with a text or
    an inverted window, and a header-only E2VID text file (an empty recording, without NumPy's warning)."""
    import warnings

    from eventio import read_window, write_events
    from eventio.export import read_e2vid_txt

    with pytest.raises(EventValidationError, match="different lengths"):
        make_events([1, 2], [1], [1], [1])
    with pytest.raises(EventValidationError, match="whole numbers"):
        make_events([1.7, 2.2], [1, 1], [1, 1], [1, 1])
    with pytest.raises(EventValidationError, match="outside -128 .. 127"):
        make_events([1], [1], [1], [300])
    assert make_events(np.array([1.0, 2.0]), [1, 1], [1, 1], [1, -1])["t"].tolist() == [1, 2]
    write_events(tmp_path / "e.h5", EventStream(make_events([1, 5], [1, 1], [1, 1], [1, -1]), 4, 4))
    with pytest.raises(ValueError, match="t0_us must be an integer"):
        read_window(tmp_path / "e.h5", "1ms", 5)
    with pytest.raises(ValueError, match="ends .* before it starts"):
        read_window(tmp_path / "e.h5", 500, 100)
    (tmp_path / "h.txt").write_text("4 4\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = read_e2vid_txt(tmp_path / "h.txt")
    assert len(s) == 0 and (s.width, s.height) == (4, 4)
