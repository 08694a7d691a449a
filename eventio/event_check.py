"""Validation of an event file's contents (the DSEC layout of `eventio.h5io`), done once per file
version by every reader, so no consumer trains on, draws or reconstructs from a malformed stream.

Checked: the datasets' dtypes (x, y uint16; t int64; p uint8 holding 0 / 1), equal lengths, a
positive integer sensor size, t non-decreasing and not before t_offset, x < width, y < height,
and ms_to_idx equal to what the events imply (entry m = the number of events with relative
t < m ms, non-decreasing, covering the last event). The scan reads the events in chunks, so memory
stays bounded for any stream length.
"""
from __future__ import annotations

import numpy as np

_SCAN = 1 << 22
EXPECTED_DTYPES = {"x": np.dtype("<u2"), "y": np.dtype("<u2"), "t": np.dtype("<i8"), "p": np.dtype("u1")}


class EventContentError(ValueError):
    """The file's events break the layout (the message names the dataset and what was expected)."""


def check_dtypes(dtypes: dict[str, np.dtype], shapes: dict[str, tuple]) -> None:
    """dtypes / shapes of events/x, y, t, p (and ms_to_idx)."""
    for name, want in EXPECTED_DTYPES.items():
        got = np.dtype(dtypes[name])
        if got.kind != want.kind or got.itemsize != want.itemsize:
            hint = ""
            if name == "p" and got.kind == "i":
                hint = " (polarity is stored as 1 = ON, 0 = OFF, not as signed +1 / -1)"
            elif name == "t" and got.kind == "f":
                hint = " (timestamps are integer microseconds)"
            raise EventContentError(f"events/{name}: expected dtype {want.name}, found {got.name}{hint}")
    lengths = {name: shapes[name] for name in EXPECTED_DTYPES}
    if any(len(s) != 1 for s in lengths.values()) or len({s[0] for s in lengths.values()}) != 1:
        raise EventContentError(f"events/x, y, t, p: expected four 1-D datasets of one length, found shapes {lengths}")
    ms = np.dtype(dtypes["ms_to_idx"])
    if ms.kind not in "ui" or len(shapes["ms_to_idx"]) != 1:
        raise EventContentError(f"ms_to_idx: expected a 1-D integer index, found {ms.name} of shape {shapes['ms_to_idx']}")


def check_chunk(t_rel: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int,
                start: int, t_before: int) -> None:
    """One chunk of events (rows start ..); t_before: the last relative t of the previous chunk (-1: none)."""
    if len(t_rel) == 0:
        return
    if t_rel[0] < max(t_before, 0):
        what = "before t_offset" if t_before < 0 else f"before the previous event ({t_before} us)"
        raise EventContentError(f"events/t: event {start} at relative t = {int(t_rel[0])} us lies {what}; "
                                "events must be sorted by time")
    down = np.flatnonzero(np.diff(t_rel) < 0)
    if down.size:
        i = int(down[0])
        raise EventContentError(f"events/t: not sorted by time: event {start + i} at {int(t_rel[i])} us is followed "
                                f"by {int(t_rel[i + 1])} us")
    for name, v, limit in (("x", x, width), ("y", y, height)):
        bad = np.flatnonzero(v >= limit)
        if bad.size:
            i = int(bad[0])
            raise EventContentError(f"events/{name}: event {start + i} has {name} = {int(v[i])}, outside the sensor "
                                    f"({'width' if name == 'x' else 'height'} {limit})")
    bad = np.flatnonzero(p > 1)
    if bad.size:
        i = int(bad[0])
        raise EventContentError(f"events/p: event {start + i} has polarity {int(p[i])}; expected 1 (ON) or 0 (OFF)")


def check_ms_index(ms: np.ndarray, counts_before_ms: np.ndarray, n: int, t_last_rel: int) -> None:
    """ms_to_idx against the counts the events imply (counts_before_ms[m] = #events with t < m ms)."""
    if n and ms.size <= t_last_rel // 1000:
        raise EventContentError(f"ms_to_idx: {ms.size} entries do not reach the last event at {t_last_rel} us "
                                f"(expected at least {t_last_rel // 1000 + 1})")
    wrong = np.flatnonzero(ms.astype(np.int64) != counts_before_ms)
    if wrong.size:
        m = int(wrong[0])
        raise EventContentError(f"ms_to_idx: entry {m} is {int(ms[m])}, but {int(counts_before_ms[m])} events come "
                                f"before {m} ms (the index does not match the events)")


def check_structure(f, width, height) -> np.ndarray:
    """The cheap checks (dtypes, lengths, sensor size, ms_to_idx non-decreasing and ending at the event
    count) on an open h5py file `f`; returns ms_to_idx. Raises EventContentError."""
    if not (isinstance(width, (int, np.integer)) and isinstance(height, (int, np.integer)) and width > 0 and height > 0):
        raise EventContentError(f"attributes width, height: expected positive integers, found {width!r}, {height!r}")
    g = f["events"]
    names = list(EXPECTED_DTYPES) + ["ms_to_idx"]
    dsets = {name: (f["ms_to_idx"] if name == "ms_to_idx" else g[name]) for name in names}
    check_dtypes({k: d.dtype for k, d in dsets.items()}, {k: d.shape for k, d in dsets.items()})
    n = g["t"].shape[0]
    ms = f["ms_to_idx"][:].astype(np.int64)
    if ms.size and (np.any(np.diff(ms) < 0) or ms[-1] != n or ms[0] < 0):
        raise EventContentError(f"ms_to_idx: expected a non-decreasing index ending at the event count {n}, found "
                                f"values from {int(ms.min())} to {int(ms.max())} ending at {int(ms[-1])}")
    return ms


def check_event_datasets(f, width, height) -> None:
    """Every check on an open h5py file `f` in the DSEC layout (a scan of all events); raises
    EventContentError."""
    ms = check_structure(f, width, height)
    g = f["events"]
    n = g["t"].shape[0]
    thresholds = np.arange(ms.size, dtype=np.int64) * 1000
    counts = np.zeros(ms.size, np.int64)
    t_before = -1
    for i0 in range(0, n, _SCAN):
        i1 = min(i0 + _SCAN, n)
        t = g["t"][i0:i1]
        check_chunk(t, g["x"][i0:i1], g["y"][i0:i1], g["p"][i0:i1], int(width), int(height), i0, t_before)
        counts += np.searchsorted(t, thresholds, side="left")
        t_before = int(t[-1])
    check_ms_index(ms, counts, n, t_before)
