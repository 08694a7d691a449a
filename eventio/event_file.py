"""The typed boundary to an event file: consumers (training, E2VID, views) read events through
`EventFile` and never open the HDF5 layout themselves.

    ev = EventFile("data/quick/lego/events/cam0.h5")      # validated once (eventio.event_check)
    ev.n, ev.width, ev.height, ev.t_offset_us
    ev.sensor                       # eventio.sensor.SensorRecord: thresholds, refractory period, every field
    ev.sensor_fields()              # {name: value} of the sensor model stored with the events
                                    # (the simulator's whole typed config: simulator.event_file.sensor_of)
    t = ev.times(i0, i1)            # [i1 - i0] int64 absolute microseconds
    x, y, p = ev.rows(i0, i1)       # uint16, uint16, int8 in {-1, +1}
    i0, i1 = ev.indices(t0, t1)     # index range of events with t0 <= t < t1 (through ms_to_idx)
    ev.window(t0, t1), ev.stream()  # EventStream of a time window, of the whole file
    ev.load()                       # keep the columns in memory (if they fit): times / rows slice arrays
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from eventio.events import EventStream
from eventio.h5io import EventFileError, read_slice, file_info, open_checked, window_indices
from eventio.sensor import SensorRecord


class EventFile:
    BYTES_PER_EVENT = 13        # x, y uint16, t int64, p uint8

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._f = open_checked(self.path, full_check=True)   # opened once, every event checked once
        self.info = file_info(self._f)
        self.n = int(self.info["n_events"])
        self.width, self.height = int(self.info["width"]), int(self.info["height"])
        self.t_offset_us = int(self.info["t_offset_us"])
        self._g = self._f["events"]
        self._cols: dict[str, np.ndarray] | None = None     # the columns, once `load` kept them

    def load(self, max_bytes: int = 256 << 20) -> bool:
        """Keep the t, x, y, p columns in memory when they fit in max_bytes, so `times` and `rows`
        slice arrays instead of decoding HDF5 chunks on every call (training reads a few windows a
        step: ~9 ms of a 1/4-resolution E-4DGS step on the quick scenes). Returns whether they were
        kept; a larger file is read from disk as before, with the same results."""
        if self._cols is None and self.n * self.BYTES_PER_EVENT <= max_bytes:
            self._cols = {k: self._g[k][()] for k in ("t", "x", "y", "p")}
        return self._cols is not None

    _sensor: SensorRecord | None = None

    @property
    def sensor(self) -> SensorRecord:
        """The sensor the file says made its events (read and range-checked once; an EventFileError
        naming the file when a stored value is out of range)."""
        if self._sensor is None:
            try:
                self._sensor = SensorRecord.from_fields(self.sensor_fields())
            except ValueError as exc:
                raise EventFileError(f"{self.path}: the stored sensor is not valid ({exc})") from None
        return self._sensor

    def sensor_fields(self, names: set[str] | None = None) -> dict:
        """The sensor parameters stored with the events: the YAML the writer saved, or else its
        `sim_<name>` attributes (only those in `names`, when given). Raises EventFileError when the
        stored YAML does not parse."""
        try:
            if "simulator_config" in self.info:
                data = yaml.safe_load(str(self.info["simulator_config"])) or {}
            else:
                data = {k[4:]: v for k, v in self.info.items()
                        if k.startswith("sim_") and (names is None or k[4:] in names)}
        except yaml.YAMLError as exc:
            raise EventFileError(f"{self.path}: the stored simulator config is not valid ({exc})") from None
        if not isinstance(data, dict):
            raise EventFileError(f"{self.path}: the stored simulator config is not a mapping")
        return data

    def _column(self, name: str, i0: int, i1: int, own: bool = False) -> np.ndarray:
        """Rows i0:i1 of a column: read from the file (a new array), or a view of the kept column,
        copied when `own` (the caller returns it as it is, so it must not alias the column)."""
        if self._cols is None:
            return self._g[name][i0:i1]
        view = self._cols[name][i0:i1]
        return view.copy() if own else view

    def times(self, i0: int, i1: int) -> np.ndarray:
        return self._column("t", i0, i1).astype(np.int64, copy=False) + self.t_offset_us

    def rows(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p = self._column("p", i0, i1).astype(np.int8) * 2 - 1
        return self._column("x", i0, i1, own=True), self._column("y", i0, i1, own=True), p

    def indices(self, t0_us: int, t1_us: int) -> tuple[int, int]:
        return window_indices(self._f, int(t0_us), int(t1_us))

    @property
    def t_end_us(self) -> int:
        """End of the recording (the writer's t_end_us, else the offset)."""
        return int(self.info.get("t_end_us", self.t_offset_us))

    def window(self, t0_us: int, t1_us: int) -> EventStream:
        """Events with t0 <= t < t1 (absolute microseconds)."""
        i0, i1 = self.indices(t0_us, t1_us)
        return EventStream(read_slice(self._f, i0, i1), self.width, self.height)

    def stream(self) -> EventStream:
        """Every event of the file."""
        return EventStream(read_slice(self._f, 0, self.n), self.width, self.height)

    def close(self) -> None:
        self._cols = None
        self._f.close()

    def __enter__(self) -> "EventFile":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
