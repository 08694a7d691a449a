import numpy as np
import pytest

from eventio.events import EVENT_DTYPE, EventStream, EventValidationError, make_events, to_torch, validate_events


def ev(t, x, y, p):
    return make_events(np.array(t), np.array(x), np.array(y), np.array(p))


def test_dtype_is_the_documented_one():
    assert EVENT_DTYPE.names == ("t", "x", "y", "p")
    assert [EVENT_DTYPE[n].str for n in EVENT_DTYPE.names] == ["<i8", "<u2", "<u2", "|i1"]


@pytest.mark.parametrize("events, index, words", [
    (ev([0, 5, 3, 9], [0, 1, 2, 3], [0, 0, 0, 0], [1, -1, 1, 1]), 2, "not sorted"),
    (ev([0, 1, 2], [0, 10, 2], [0, 0, 0], [1, 1, 1]), 1, "x[1]=10 out of range"),
    (ev([0, 1, 2], [0, 1, 2], [0, 0, 8], [1, 1, 1]), 2, "y[2]=8 out of range"),
    (ev([0, 1, 2], [0, 1, 2], [0, 0, 0], [1, 0, 1]), 1, "p[1]=0"),
    # several problems: the smallest index wins
    (ev([0, 1, 0], [0, 1, 12], [0, 9, 0], [1, 1, 1]), 1, "y[1]=9"),
])
def test_validate_reports_the_first_offending_index(events, index, words):
    with pytest.raises(EventValidationError) as err:
        validate_events(events, width=10, height=8)
    assert words in str(err.value)
    assert err.value.index == index


def test_valid_and_empty_streams_pass():
    validate_events(ev([0, 0, 7], [0, 9, 3], [7, 0, 2], [1, -1, 1]), 10, 8)
    s = EventStream(np.empty(0, EVENT_DTYPE), 10, 8).validate()
    assert len(s) == 0 and len(s.window(0, 100)) == 0


def test_wrong_dtype_is_rejected():
    with pytest.raises(EventValidationError, match="EVENT_DTYPE"):
        validate_events(np.zeros(3), 4, 4)
    with pytest.raises(EventValidationError):
        EventStream(np.zeros(3), 4, 4)


def test_window_and_concatenate():
    s = EventStream(ev([1, 5, 5, 9, 12], [0] * 5, [0] * 5, [1] * 5), 2, 2)
    assert list(s.window(5, 12).t_us) == [5, 5, 9]
    joined = EventStream.concatenate([s.window(0, 6), s.window(6, 100)])
    assert np.array_equal(joined.events, s.events)
    with pytest.raises(ValueError, match="sensor sizes"):
        EventStream.concatenate([s, EventStream(s.events, 3, 2)])


def test_to_torch_boundary():
    s = EventStream(ev([2**40, 2**40 + 1], [3, 4], [1, 0], [1, -1]), 5, 2)
    t = to_torch(s)
    assert t["t"].tolist() == [2**40, 2**40 + 1] and t["p"].tolist() == [1.0, -1.0]
    assert str(t["x"].dtype) == "torch.int64"
