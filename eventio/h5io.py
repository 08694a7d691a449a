"""Event files in the DSEC layout (HDF5).

    events/x  uint16 [N]    events/y  uint16 [N]
    events/t  int64  [N]    microseconds relative to t_offset (DSEC uses uint32; int64 here so
                            streams longer than 71 minutes fit)
    events/p  uint8  [N]    1 = ON, 0 = OFF (DSEC convention; in memory p is +1 / -1)
    ms_to_idx uint64 [M]    ms_to_idx[m] = first index with t >= m * 1000 (relative time)
    t_offset  int64  scalar absolute time of relative t = 0, microseconds: absolute times are kept
                            (t_offset + t); a recording stamped in Unix-epoch microseconds gets its
                            first event's millisecond as t_offset, as DSEC does
    attrs: width, height, format_version, and every simulator parameter used (name = value), plus
           the resolved config as YAML text in `simulator_config`.

`EventFileWriter` appends chunks (nothing is held in memory but the current chunk), writes to a
temporary name and renames it when closed without error. `read_events` / `read_window` load the
whole stream or a time window [t0, t1) through ms_to_idx, reading only that slice.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Mapping

import h5py
import numpy as np

from common.fileio import as_disk_error, remove_stale_temps, require_free_space, temp_path_for
from common.config import dump_config, to_dict
from eventio.event_check import EventContentError, check_chunk, check_event_datasets, check_structure
from eventio.events import EVENT_DTYPE, EventStream, validate_events

FORMAT_VERSION = 1
_CHUNK = 1 << 16
_CACHE_BYTES = 8 << 20     # what HDF5's chunk caches may still hold unwritten (5 datasets, 1 MiB each)


class EventFileError(ValueError):
    """An event file is missing, incomplete or not in the expected layout."""


def _attr_value(value: Any) -> Any:
    """HDF5-storable form of a config value (None and containers become JSON text)."""
    if value is None or isinstance(value, (list, tuple, dict)):
        return json.dumps(value)
    return value


class EventFileWriter:
    """Append-only writer of one sensor's events; use as a context manager.

    Events appended must be sorted and not earlier than those already written. `close(t_end_us)`
    extends ms_to_idx to cover the stream's duration even if its last events come earlier.
    """

    def __init__(self, path: str | os.PathLike, width: int, height: int, t_offset_us: int = 0,
                 attrs: Mapping[str, Any] | None = None, compression: str | None = "gzip"):
        self.path = Path(path)
        self.width, self.height, self.t_offset_us = int(width), int(height), int(t_offset_us)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temps(self.path)
        self._tmp = temp_path_for(self.path)
        require_free_space(self.path, 0)
        self._file = h5py.File(self._tmp, "w")
        g = self._file.create_group("events")
        # Deterministic bytes: the same events always give the same file (datasets are compared by SHA-256
        # across runs, workers and machines). gzip level 1 after a byte shuffle: deterministic, and on a
        # quick scene's 1.9M events 4.1 MB against LZF's 7.9 MB, read in 0.05 s against 0.07 s (written
        # in 0.15 s against 0.11 s). LZF's compressor hashes with an uninitialised table, so its output
        # varied between runs. fill_time="alloc": the last chunk's unused tail is zeros, not stale memory.
        gz = {"compression_opts": 1, "shuffle": True} if compression == "gzip" else {}
        kw = dict(maxshape=(None,), chunks=(_CHUNK,), compression=compression, fillvalue=0, fill_time="alloc", **gz)
        self._ds = {name: g.create_dataset(name, shape=(0,), dtype=dt, **kw)
                    for name, dt in (("x", "<u2"), ("y", "<u2"), ("t", "<i8"), ("p", "u1"))}
        self._ms = self._file.create_dataset("ms_to_idx", shape=(0,), dtype="<u8", **kw)
        self._file.create_dataset("t_offset", data=np.int64(self.t_offset_us))
        a = self._file.attrs
        a["width"], a["height"], a["format_version"] = self.width, self.height, FORMAT_VERSION
        for key, value in (attrs or {}).items():
            a[key] = _attr_value(value)
        self.n_events = 0
        self._last_t_rel = -1
        self._closed = False

    def _extend_ms_index(self, t_rel_us: np.ndarray, upto_ms: int) -> None:
        """Append ms_to_idx entries for every millisecond up to `upto_ms` (inclusive) whose first
        event index is now known: the first index with t_rel >= ms * 1000 among events so far."""
        start_ms = self._ms.shape[0]
        if upto_ms < start_ms:
            return
        ms = np.arange(start_ms, upto_ms + 1, dtype=np.int64)
        base = self.n_events - len(t_rel_us)
        idx = base + np.searchsorted(t_rel_us, ms * 1000, side="left")
        self._ms.resize((upto_ms + 1,))
        self._ms[start_ms:] = idx.astype(np.uint64)

    def append(self, events: np.ndarray) -> None:
        """Add sorted events after those written (a full disk: the file is dropped, OSError names it)."""
        self._guarded(self._append, events, len(events) * (13 + 8))

    def _guarded(self, fn, arg, n_bytes: int):
        """Run a write after checking the disk can take `n_bytes` (HDF5 may crash the process on a full
        disk rather than fail); on a write error drop the unfinished file and name the output."""
        if not self._closed:
            try:
                require_free_space(self.path, n_bytes + _CACHE_BYTES)
            except OSError:
                self.abort()
                raise
        try:
            return fn(arg)
        except Exception as exc:
            disk = as_disk_error(exc, self.path)
            if disk is None:
                raise
            self.abort()
            raise disk from None

    def _append(self, events: np.ndarray) -> None:
        if self._closed:
            raise EventFileError(f"{self.path}: writer is closed")
        if len(events) == 0:
            return
        validate_events(events, self.width, self.height)
        t_rel = events["t"] - self.t_offset_us
        if t_rel[0] < 0:
            raise EventFileError(f"{self.path}: event at t={events['t'][0]} us precedes t_offset={self.t_offset_us} us")
        if t_rel[0] < self._last_t_rel:
            raise EventFileError(f"{self.path}: appended events start at {events['t'][0]} us, before the "
                                 f"last written event at {self._last_t_rel + self.t_offset_us} us")
        n0, n1 = self.n_events, self.n_events + len(events)
        for name, ds in self._ds.items():
            ds.resize((n1,))
        self._ds["x"][n0:n1] = events["x"]
        self._ds["y"][n0:n1] = events["y"]
        self._ds["t"][n0:n1] = t_rel
        self._ds["p"][n0:n1] = (events["p"] > 0).astype(np.uint8)
        self.n_events = n1
        self._last_t_rel = int(t_rel[-1])
        # milliseconds whose first index is settled: all m with m*1000 <= last t (later events
        # cannot be earlier). Index of m = first event with t_rel >= m*1000.
        self._extend_ms_index(t_rel, self._last_t_rel // 1000)

    def close(self, t_end_us: int | None = None) -> Path:
        """Finish the file: ms_to_idx covers up to the last event and `t_end_us`; rename into place."""
        if self._closed:
            return self.path
        end_rel = max(self._last_t_rel, -1 if t_end_us is None else int(t_end_us) - self.t_offset_us)
        return self._guarded(self._close, t_end_us, 8 * (max(end_rel, 0) // 1000 + 2 - self._ms.shape[0]))

    def _close(self, t_end_us: int | None) -> Path:
        end_rel = max(self._last_t_rel, -1 if t_end_us is None else int(t_end_us) - self.t_offset_us)
        # every millisecond after the last event maps to n_events; one entry past the end
        start_ms = self._ms.shape[0]
        stop_ms = max(end_rel, 0) // 1000 + 1
        if stop_ms >= start_ms:
            self._ms.resize((stop_ms + 1,))
            self._ms[start_ms:] = np.uint64(self.n_events)
        self._file.attrs["n_events"] = self.n_events
        self._file.attrs["t_end_us"] = end_rel + self.t_offset_us if end_rel >= 0 else self.t_offset_us
        self._file.close()
        os.replace(self._tmp, self.path)
        self._closed = True
        return self.path

    def abort(self) -> None:
        """Drop the unfinished file (nothing appears at `path`)."""
        if not self._closed:
            self._closed = True
            try:
                self._file.close()
            except Exception:       # noqa: BLE001 - a file that failed to write may fail to close: drop it anyway
                pass
            self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> "EventFileWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def default_offset_us(events: np.ndarray) -> int:
    """t_offset for a stream: its first event's time, floored to a whole millisecond (so ms_to_idx's
    milliseconds are absolute ones); 0 for an empty stream. A stream that starts within the first
    millisecond (the simulator's) keeps t_offset 0, a recording stamped in epoch time gets its start."""
    return int(events["t"][0]) // 1000 * 1000 if len(events) else 0


def write_events(path: str | os.PathLike, stream: EventStream, t_offset_us: int | None = None,
                 attrs: Mapping[str, Any] | None = None, t_end_us: int | None = None) -> Path:
    """Write a whole in-memory stream (in chunks) to `path`; `t_offset_us` None: `default_offset_us`."""
    if t_offset_us is None:
        t_offset_us = default_offset_us(stream.events)
    with EventFileWriter(path, stream.width, stream.height, t_offset_us, attrs) as w:
        for i in range(0, len(stream), 1 << 20):
            w.append(stream.events[i:i + (1 << 20)])
        w.close(t_end_us)
    return Path(path)


def open_checked(path: str | os.PathLike, full_check: bool = False) -> h5py.File:
    """Open an event file after checking its layout and structure (and, with full_check, every
    event: eventio.event_check), each at most once per file version and process."""
    path = Path(path)
    if not path.exists():
        raise EventFileError(f"{path}: no such event file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise EventFileError(f"{path}: not a readable HDF5 file ({exc})") from None
    for name in ("events/x", "events/y", "events/t", "events/p", "ms_to_idx", "t_offset"):
        if name not in f:
            f.close()
            raise EventFileError(f"{path}: missing dataset '{name}' (expected the DSEC layout)")
    for name in ("width", "height"):
        if name not in f.attrs:
            f.close()
            raise EventFileError(f"{path}: missing attribute '{name}'")
    try:
        _validate_once(path, f, full_check)
    except EventFileError:
        f.close()
        raise
    return f


_VALIDATED: set[tuple[str, int, int, bool]] = set()


def _validate_once(path: Path, f: h5py.File, full: bool) -> None:
    """The checks of eventio.event_check (structure, or every event when `full`), once per file
    version (path, size, mtime) and process."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key + (full,) in _VALIDATED or key + (True,) in _VALIDATED:
        return
    t_offset = f["t_offset"]
    if t_offset.shape != () or t_offset.dtype.kind not in "iu":
        raise EventFileError(f"{path}: t_offset: expected an integer scalar (microseconds), found "
                             f"{t_offset.dtype.name} of shape {t_offset.shape}")
    try:
        (check_event_datasets if full else check_structure)(f, f.attrs["width"], f.attrs["height"])
    except EventContentError as exc:
        raise EventFileError(f"{path}: {exc}") from None
    check_declared_counts(path, f)
    _VALIDATED.add(key + (full,))


def check_declared_counts(path: Path, f: h5py.File) -> None:
    """Attributes that restate the events (n_events, t_end_us) must agree with them: a reader that
    believed a wrong one would draw or train on part of the stream without a word."""
    n = int(f["events/t"].shape[0])
    if "n_events" in f.attrs and int(f.attrs["n_events"]) != n:
        raise EventFileError(f"{path}: attribute n_events = {int(f.attrs['n_events'])} but the file holds {n} events "
                             "(its attributes disagree with its events)")
    if "t_end_us" in f.attrs and n:
        last = int(f["events/t"][n - 1]) + int(f["t_offset"][()])
        if int(f.attrs["t_end_us"]) < last:
            raise EventFileError(f"{path}: attribute t_end_us = {int(f.attrs['t_end_us'])} us is before the last event "
                                 f"({last} us): its attributes disagree with its events")


def read_slice(f: h5py.File, i0: int, i1: int) -> np.ndarray:
    """Events i0 .. i1 - 1, checked as they are read (sorted, inside the sensor, polarity 0 / 1)."""
    g = f["events"]
    out = np.empty(i1 - i0, EVENT_DTYPE)
    if i1 <= i0:
        return out
    t, x, y, p = (g[name][i0:i1] for name in ("t", "x", "y", "p"))
    t_before = int(g["t"][i0 - 1]) if i0 > 0 else -1
    try:
        check_chunk(t, x, y, p, int(f.attrs["width"]), int(f.attrs["height"]), i0, t_before)
    except EventContentError as exc:
        raise EventFileError(f"{f.filename}: {exc}") from None
    out["t"] = t + int(f["t_offset"][()])
    out["x"], out["y"] = x, y
    out["p"] = p.astype(np.int8) * 2 - 1
    return out


def file_info(f: h5py.File) -> dict[str, Any]:
    """Attributes of an open event file plus n_events and t_offset_us, without reading events."""
    info = {k: (v.item() if hasattr(v, "item") else v) for k, v in f.attrs.items()}
    info["n_events"] = int(f["events/t"].shape[0])
    info["t_offset_us"] = int(f["t_offset"][()])
    return info


def read_info(path: str | os.PathLike) -> dict[str, Any]:
    """Attributes plus n_events and t_offset_us, without reading events."""
    with open_checked(path) as f:
        return file_info(f)


def read_events(path: str | os.PathLike) -> EventStream:
    """The whole stream of an event file (every event checked)."""
    with open_checked(path, full_check=True) as f:
        n = f["events/t"].shape[0]
        return EventStream(read_slice(f, 0, n), int(f.attrs["width"]), int(f.attrs["height"]))


def window_indices(f: h5py.File, t0_us: int, t1_us: int) -> tuple[int, int]:
    """Index range [i0, i1) of events with t0 <= t < t1, reading only ms_to_idx entries and the
    events of the two boundary milliseconds."""
    t_offset = int(f["t_offset"][()])
    n = f["events/t"].shape[0]
    ms_index = f["ms_to_idx"]
    n_ms = ms_index.shape[0]

    def first_at_or_after(t_us: int) -> int:
        rel = t_us - t_offset
        if rel <= 0:
            return 0
        m = rel // 1000
        if m >= n_ms - 1:
            lo = int(ms_index[n_ms - 1]) if n_ms else 0
            hi = n
        else:
            lo, hi = int(ms_index[m]), int(ms_index[m + 1])
        if lo >= hi:
            return lo
        ts = f["events/t"][lo:hi]
        return lo + int(np.searchsorted(ts, rel, side="left"))

    if t1_us <= t0_us:
        i0 = first_at_or_after(t0_us)
        return i0, i0
    return first_at_or_after(t0_us), first_at_or_after(t1_us)


def read_window(path: str | os.PathLike, t0_us: int, t1_us: int) -> EventStream:
    """Events with t0_us <= t < t1_us (absolute microseconds), read through ms_to_idx. ValueError for
    times that are not integers or a window that ends before it starts."""
    for name, v in (("t0_us", t0_us), ("t1_us", t1_us)):
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"{path}: read_window: {name} must be an integer number of microseconds, "
                             f"got {v!r} ({type(v).__name__})")
    if t1_us < t0_us:
        raise ValueError(f"{path}: read_window: the window ends ({t1_us} us) before it starts ({t0_us} us)")
    with open_checked(path) as f:
        i0, i1 = window_indices(f, int(t0_us), int(t1_us))
        return EventStream(read_slice(f, i0, i1), int(f.attrs["width"]), int(f.attrs["height"]))


def simulator_attrs(config) -> dict[str, Any]:
    """Event-file attributes of a simulator config: every parameter as `sim_<name>`, plus the YAML."""
    later = getattr(config, "LATER_FIELDS", {})   # fields added later, left out while off (files keep their bytes)
    attrs = {f"sim_{k}": v for k, v in to_dict(config).items()
             if v is not None and not (k in later and v == later[k])}
    attrs["simulator_config"] = dump_config(config)
    return attrs
