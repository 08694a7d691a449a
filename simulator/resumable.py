"""Crash-safe event output for long jobs: spool, checkpoint, resume, then one HDF5 file.

HDF5 files are not safe to reopen after a process is killed mid-write, so a long job appends its
events to a raw spool file (`.<name>.spool`, EVENT_DTYPE records) and, at checkpoints, records how
many events the spool holds together with the job's own state (`.<name>.ckpt.npz`, written
atomically). After a kill, the next run with the same fingerprint truncates the spool to the last
checkpoint and hands the job its state back; `finish` converts the spool into the final HDF5 file
(temporary name, then rename) and removes the spool and checkpoint. The final file therefore
appears only when complete, and a resumed run produces the same file as an uninterrupted one.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from e4dgs.fileio import atomic_output
from simulator.events import EVENT_DTYPE, validate_events
from simulator.h5io import EventFileWriter

_CHUNK_EVENTS = 1 << 21
_KEY = "writer__"  # prefix of the writer's own entries in the checkpoint


class ResumableEventWriter:
    """Event output of one sensor for a job that may be killed and restarted.

    After construction, `resumed_state` is the job state saved at the last checkpoint (a dict), or
    None for a fresh start. `fingerprint` identifies the job's inputs: a checkpoint made with a
    different fingerprint is discarded.
    """

    def __init__(self, path: str | os.PathLike, width: int, height: int, fingerprint: str,
                 t_offset_us: int = 0, attrs: Mapping[str, Any] | None = None):
        self.path = Path(path)
        self.width, self.height, self.t_offset_us = int(width), int(height), int(t_offset_us)
        self.attrs = dict(attrs or {})
        self.fingerprint = str(fingerprint)
        self.spool_path = self.path.with_name(f".{self.path.name}.spool")
        self.ckpt_path = self.path.with_name(f".{self.path.name}.ckpt.npz")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.resumed_state: dict[str, Any] | None = None
        n_kept = 0
        if self.ckpt_path.exists() and self.spool_path.exists():
            with np.load(self.ckpt_path, allow_pickle=False) as z:
                if str(z[_KEY + "fingerprint"]) == self.fingerprint:
                    n_kept = int(z[_KEY + "n_events"])
                    self._last_t = int(z[_KEY + "last_t"])
                    self.resumed_state = {k: z[k] for k in z.files if not k.startswith(_KEY)}
        if self.resumed_state is None:
            self.ckpt_path.unlink(missing_ok=True)
            self._last_t = np.iinfo(np.int64).min
        self._spool = open(self.spool_path, "r+b" if n_kept else "w+b")
        self._spool.truncate(n_kept * EVENT_DTYPE.itemsize)
        self._spool.seek(0, os.SEEK_END)
        self.n_events = n_kept

    def append(self, events: np.ndarray) -> None:
        if len(events) == 0:
            return
        validate_events(events, self.width, self.height)
        if events["t"][0] < self._last_t:
            raise ValueError(f"{self.path}: events appended out of time order")
        self._spool.write(np.ascontiguousarray(events).tobytes())
        self.n_events += len(events)
        self._last_t = int(events["t"][-1])

    def checkpoint(self, state: Mapping[str, Any]) -> None:
        """Make everything appended so far durable, together with the job's `state`."""
        self._spool.flush()
        os.fsync(self._spool.fileno())
        arrays = {k: np.asarray(v) for k, v in state.items()}
        arrays.update({_KEY + "fingerprint": np.asarray(self.fingerprint),
                       _KEY + "n_events": np.int64(self.n_events), _KEY + "last_t": np.int64(self._last_t)})
        with atomic_output(self.ckpt_path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

    def finish(self, t_end_us: int | None = None) -> Path:
        """Write the final HDF5 file from the spool, then remove spool and checkpoint."""
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
        self.ckpt_path.unlink(missing_ok=True)
        return self.path

    def close(self) -> None:
        """Release the spool file, keeping spool and checkpoint for a later resume."""
        if not self._spool.closed:
            self._spool.close()
