"""Crash-safe event output for long jobs: spool events, resume after a kill, then one HDF5 file.

HDF5 files are not safe to reopen after a process was killed mid-write, so a long job appends its
events to a raw spool file (`.<name>.spool`, EVENT_DTYPE records). At its checkpoints the job calls
`sync()`, which makes the spool durable and returns its event count, and stores that count in its
own checkpoint (`common.checkpoint.JobCheckpoint`, together with e.g. the simulator state). After a
kill, the job reopens the spool with `resume_count` = that count: the spool is truncated to it and
the job continues. `finish` converts the spool into the final HDF5 file (temporary name, then
rename) and deletes the spool. The final file appears only when complete, and a resumed run
produces the same file as an uninterrupted one.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from eventio.events import EVENT_DTYPE, validate_events
from eventio.h5io import EventFileWriter

_CHUNK_EVENTS = 1 << 21


class SpoolResumeError(ValueError):
    """The spool a checkpoint refers to is missing or shorter than the checkpoint's event count."""


def spool_path_for(path: str | os.PathLike) -> Path:
    """The hidden spool file of event output `path`."""
    path = Path(path)
    return path.with_name(f".{path.name}.spool")


def can_resume(path: str | os.PathLike, count: int) -> bool:
    """Whether the spool of output `path` holds at least `count` events (what a checkpoint recorded)."""
    spool = spool_path_for(path)
    return count == 0 or (spool.exists() and spool.stat().st_size >= count * EVENT_DTYPE.itemsize)


class EventSpool:
    """Append-only event output of one sensor, resumable at the counts `sync()` returned."""

    def __init__(self, path: str | os.PathLike, width: int, height: int, t_offset_us: int = 0,
                 attrs: Mapping[str, Any] | None = None, resume_count: int | None = None):
        self.path = Path(path)
        self.width, self.height, self.t_offset_us = int(width), int(height), int(t_offset_us)
        self.attrs = dict(attrs or {})
        self.spool_path = spool_path_for(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        n = int(resume_count or 0)
        if not can_resume(self.path, n):
            raise SpoolResumeError(f"{self.spool_path}: cannot resume at {n} events: the spool is missing or shorter")
        self._spool = open(self.spool_path, "r+b" if n else "w+b")
        self._spool.truncate(n * EVENT_DTYPE.itemsize)
        self._last_t = np.iinfo(np.int64).min
        if n:
            self._spool.seek((n - 1) * EVENT_DTYPE.itemsize)
            self._last_t = int(np.frombuffer(self._spool.read(EVENT_DTYPE.itemsize), EVENT_DTYPE)["t"][0])
        self._spool.seek(0, os.SEEK_END)
        self.n_events = n

    def append(self, events: np.ndarray) -> None:
        if len(events) == 0:
            return
        validate_events(events, self.width, self.height)
        if events["t"][0] < self._last_t:
            raise ValueError(f"{self.path}: events appended out of time order")
        try:
            self._spool.write(np.ascontiguousarray(events).tobytes())
        except OSError as exc:          # a full disk: name the file (a write's error names none)
            raise OSError(exc.errno, exc.strerror, str(self.spool_path)) from None
        self.n_events += len(events)
        self._last_t = int(events["t"][-1])

    def sync(self) -> int:
        """Flush to disk; returns the event count to pass as `resume_count` after a kill."""
        try:
            self._spool.flush()
            os.fsync(self._spool.fileno())
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, str(self.spool_path)) from None
        return self.n_events

    def finish(self, t_end_us: int | None = None) -> Path:
        """Write the final HDF5 file from the spool, then delete the spool."""
        self._spool.flush()
        self._spool.seek(0)
        with EventFileWriter(self.path, self.width, self.height, self.t_offset_us, self.attrs) as w:
            remaining = self.n_events
            while remaining:
                n = min(remaining, _CHUNK_EVENTS)
                w.append(np.frombuffer(self._spool.read(n * EVENT_DTYPE.itemsize), EVENT_DTYPE))
                remaining -= n
            w.close(t_end_us)
        self.close()
        self.spool_path.unlink(missing_ok=True)
        return self.path

    def close(self) -> None:
        """Release the spool file, keeping it for a later resume."""
        if not self._spool.closed:
            self._spool.close()
