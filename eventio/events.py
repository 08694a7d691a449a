"""The event type: one NumPy structured dtype, a stream that carries its sensor size, validation.

Events are `EVENT_DTYPE` records: `t` in integer microseconds, `x`/`y` pixel column/row, `p` in
{-1, +1}, sorted by `t` (ties in any order). An empty stream is an empty array, never None.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Iterable

import numpy as np

if TYPE_CHECKING:  # torch is imported only by `to_torch`
    import torch

EVENT_DTYPE = np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "i1")])


class EventValidationError(ValueError):
    """An event array breaks the format; the message names the first offending index."""

    def __init__(self, message: str, index: int | None = None):
        super().__init__(message)
        self.index = index


def empty_events() -> np.ndarray:
    return np.empty(0, dtype=EVENT_DTYPE)


def make_events(t_us, x, y, p) -> np.ndarray:
    """Pack column arrays [N] into an `EVENT_DTYPE` array (no sorting, no validation of ranges).

    EventValidationError for columns of different lengths, times that are not whole microseconds
    (a float 1.7 would silently become 1), or values a column's type cannot hold (x = -1, p = 300)."""
    cols = {"t": np.asarray(t_us), "x": np.asarray(x), "y": np.asarray(y), "p": np.asarray(p)}
    for name, col in cols.items():
        if col.ndim != 1:
            raise EventValidationError(f"make_events: {name} must be one-dimensional, got shape {col.shape}")
        if col.dtype.kind not in "iub":
            if col.dtype.kind != "f" or not np.all(np.isfinite(col)) or np.any(col != np.round(col)):
                raise EventValidationError(f"make_events: {name} must hold whole numbers (microseconds for t), "
                                           f"got dtype {col.dtype}" + (" with fractions or non-finite values"
                                                                       if col.dtype.kind == "f" else ""))
    lengths = {name: len(col) for name, col in cols.items()}
    if len(set(lengths.values())) > 1:
        raise EventValidationError(f"make_events: columns of different lengths {lengths}")
    out = np.empty(lengths["t"], dtype=EVENT_DTYPE)
    for name, col in cols.items():
        info = np.iinfo(out.dtype[name])
        if col.size and (col.min() < info.min or col.max() > info.max):
            raise EventValidationError(f"make_events: {name} holds values outside {info.min} .. {info.max} "
                                       f"({out.dtype[name]})")
        out[name] = col
    return out


def validate_events(events: np.ndarray, width: int, height: int) -> None:
    """Raise `EventValidationError` naming the first index that breaks the format.

    Checks, in this order of report: dtype, timestamps non-decreasing, x < width, y < height,
    p in {-1, +1}. Among several broken rules the smallest offending index is reported.
    """
    if not isinstance(events, np.ndarray) or events.dtype != EVENT_DTYPE:
        got = events.dtype if isinstance(events, np.ndarray) else type(events).__name__
        raise EventValidationError(f"events must be a NumPy array of EVENT_DTYPE {EVENT_DTYPE}, got {got}")
    if events.ndim != 1:
        raise EventValidationError(f"events must be one-dimensional, got shape {events.shape}")
    if len(events) == 0:
        return
    t = events["t"]
    problems = []
    bad = np.flatnonzero(t[1:] < t[:-1])
    if bad.size:
        i = int(bad[0]) + 1
        problems.append((i, f"timestamps not sorted: t[{i}]={t[i]} us < t[{i - 1}]={t[i - 1]} us"))
    for name, limit in (("x", width), ("y", height)):
        bad = np.flatnonzero(events[name] >= limit)
        if bad.size:
            i = int(bad[0])
            problems.append((i, f"{name}[{i}]={events[name][i]} out of range [0, {limit})"))
    bad = np.flatnonzero((events["p"] != 1) & (events["p"] != -1))
    if bad.size:
        i = int(bad[0])
        problems.append((i, f"p[{i}]={events['p'][i]} is not -1 or +1"))
    if problems:
        i, message = min(problems, key=lambda item: item[0])
        raise EventValidationError(f"invalid event at index {i}: {message}", index=i)


@dataclass(frozen=True)
class EventStream:
    """Events [N] of EVENT_DTYPE with the sensor size they were recorded at."""

    events: np.ndarray
    width: int
    height: int

    def __post_init__(self):
        if not isinstance(self.events, np.ndarray) or self.events.dtype != EVENT_DTYPE:
            raise EventValidationError(f"EventStream.events must have EVENT_DTYPE, got {getattr(self.events, 'dtype', type(self.events))}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"EventStream: sensor size must be positive, got {self.width}x{self.height}")

    def __len__(self) -> int:
        return len(self.events)

    def validate(self) -> "EventStream":
        validate_events(self.events, self.width, self.height)
        return self

    @property
    def t_us(self) -> np.ndarray:
        return self.events["t"]

    def window(self, t0_us: int, t1_us: int) -> "EventStream":
        """Events with t0_us <= t < t1_us (a view, found by binary search)."""
        t = self.events["t"]
        i0, i1 = np.searchsorted(t, [t0_us, t1_us], side="left")
        return EventStream(self.events[i0:i1], self.width, self.height)

    @staticmethod
    def concatenate(streams: Iterable["EventStream"]) -> "EventStream":
        """Join time-ordered, non-overlapping streams of one sensor."""
        streams = list(streams)
        if not streams:
            raise ValueError("EventStream.concatenate needs at least one stream")
        sizes = {(s.width, s.height) for s in streams}
        if len(sizes) != 1:
            raise ValueError(f"cannot concatenate streams of different sensor sizes: {sorted(sizes)}")
        width, height = sizes.pop()
        return EventStream(np.concatenate([s.events for s in streams]), width, height)


def to_torch(stream: EventStream, device: "str | torch.device" = "cpu") -> dict[str, "torch.Tensor"]:
    """The one boundary into torch: int64 t [N], int64 x [N], int64 y [N], float32 p [N]."""
    import torch

    ev = stream.events
    return {
        "t": torch.from_numpy(np.ascontiguousarray(ev["t"])).to(device),
        "x": torch.from_numpy(ev["x"].astype(np.int64)).to(device),
        "y": torch.from_numpy(ev["y"].astype(np.int64)).to(device),
        "p": torch.from_numpy(ev["p"].astype(np.float32)).to(device),
    }
