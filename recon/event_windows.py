"""Event-adaptive slicing (ESS): windows holding a chosen number of events, read by index.

Each draw picks a camera, a count N (uniform integer in [n_min, n_max], or a fixed count) and a
start index i0 uniform in [1, n_events - N]; the window is (t_start, t_end] with t_start the time of
event i0 - 1 and t_end the time of event i0 + N - 1, i.e. it holds events i0 .. i0 + N - 1 plus any
that share t_end (or lose those sharing t_start). Only those rows are read from the HDF5 file (plus a
few to settle ties), so a draw never scans the stream.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eventio.event_file import EventFile
from eventio.h5io import EventFileError

_TIE_PAD = 1024   # extra rows read past the window to include events sharing its end time


@dataclass
class EventWindow:
    camera: int
    t_start_us: int          # exclusive
    t_end_us: int            # inclusive
    x: np.ndarray            # [N] uint16
    y: np.ndarray            # [N] uint16
    p: np.ndarray            # [N] int8 in {-1, +1}

    def __len__(self) -> int:
        return len(self.x)


class EventSource(EventFile):
    """One camera's event file (eventio.EventFile: the file and its sensor record), with ESS windows cut by event index."""

    def thresholds(self) -> tuple[float, float]:
        """The sensor's nominal contrast thresholds (C+, C-), from the file's sensor record."""
        return float(self.sensor.pos_threshold), float(self.sensor.neg_threshold)

    def window(self, camera: int, i0: int, n: int) -> EventWindow:
        """Events i0 .. i0 + n - 1 as a (t_start, t_end] window (1 <= i0, i0 + n <= n_events)."""
        i1 = i0 + n
        t = self.times(i0 - 1, min(i1 + _TIE_PAD, self.n))
        t_start, t_end = int(t[0]), int(t[n])
        lo = int(np.searchsorted(t, t_start, side="right"))          # first event after t_start
        hi = int(np.searchsorted(t, t_end, side="right"))            # one past the last at t_end
        x, y, p = self.rows(i0 - 1 + lo, i0 - 1 + hi)
        return EventWindow(camera, t_start, t_end, x, y, p)

    def window_between(self, camera: int, t_start_us: int, t_end_us: int) -> EventWindow:
        """This camera's events with t_start < t <= t_end (the same time window as another camera's)."""
        i0, i1 = self.indices(t_start_us + 1, t_end_us + 1)
        x, y, p = self.rows(i0, i1)
        return EventWindow(camera, t_start_us, t_end_us, x, y, p)


class WindowSampler:
    """Random windows over several cameras' event files (seeded through the caller's generator)."""

    def __init__(self, sources: list[EventSource], n_range: tuple[int, int] | None, n_fixed: int):
        self.sources = sources
        self.n_range = n_range
        self.n_fixed = n_fixed

    def count_bounds(self, source: EventSource) -> tuple[int, int]:
        lo, hi = self.n_range if self.n_range is not None else (self.n_fixed, self.n_fixed)
        top = max(source.n - 1, 0)
        return min(lo, top), min(hi, top)

    def sample(self, rng: np.random.Generator) -> EventWindow:
        cam = int(rng.integers(len(self.sources)))
        src = self.sources[cam]
        lo, hi = self.count_bounds(src)
        if hi < 1:
            raise EventFileError(f"{src.path}: too few events ({src.n}) to cut a window from")
        n = int(rng.integers(lo, hi + 1))
        i0 = int(rng.integers(1, src.n - n + 1))
        return src.window(cam, i0, n)

    def sample_views(self, rng: np.random.Generator, n_views: int) -> list[EventWindow]:
        """One ESS window as `sample` draws it, then the same time window on n_views - 1 other cameras
        (distinct, in random order): the multi-view step's supervision."""
        first = self.sample(rng)
        others = [c for c in rng.permutation(len(self.sources)).tolist() if c != first.camera][:n_views - 1]
        return [first] + [self.sources[c].window_between(c, first.t_start_us, first.t_end_us) for c in others]

    def close(self) -> None:
        for s in self.sources:
            s.close()
