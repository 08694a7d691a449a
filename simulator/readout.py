"""The readout after the pixels: latency and its jitter, a semi-synchronous readout's timestamp steps,
and a bandwidth limit (a FIFO that serves at most a rate of events, delaying and dropping the rest).

Model (each stage only when its parameter is on, SimulatorConfig):
  arrival_us = round(t_us + latency_us + jitter), jitter ~ Normal(0, latency_jitter_us) truncated at
               +-3 sigma, never before t_us;
  bandwidth:   events served in arrival order, one every 1e6 / max_event_rate_hz us: an event starts at
               max(arrival, the end of the previous one's service); its wait (start - arrival) over
               max_readout_delay_us drops it (0: never dropped); its time is ceil(start);
  readout:     the time rounded up to a multiple of readout_period_us (a frame of the semi-synchronous
               readout reports its events with the frame's time).
Events keep their pixel and polarity; only the timestamps move (and some events are dropped).

`fifo_ref` / `fifo_fast` (numba) are the sequential stage, one signature, tested against each other.
`Readout` holds what a frame interval leaves pending (events not yet out by its end) so the stream
stays in time order across `push` calls; `flush` releases the rest at the end.
"""
from __future__ import annotations

import json
import math

import numpy as np
from numba import njit

from eventio.events import EVENT_DTYPE, empty_events


def fifo_ref(arrival_us: np.ndarray, free_us: float, period_us: float, max_delay_us: int):
    """The bandwidth stage. arrival_us [N] int64, non-decreasing. free_us: when the server is next free.
    period_us: service time of one event (1e6 / rate). Returns (out_us [N] int64, kept [N] bool, free_us)."""
    n = arrival_us.shape[0]
    out = np.zeros(n, np.int64)
    kept = np.zeros(n, np.bool_)
    for i in range(n):
        a = float(arrival_us[i])
        start = a if a > free_us else free_us
        if max_delay_us > 0 and start - a > max_delay_us:
            continue
        out[i] = int(math.ceil(start))
        kept[i] = True
        free_us = start + period_us
    return out, kept, free_us


# the same loop, compiled: fifo_ref's Python runs it as written (the reference), numba compiles it
_fifo_numba = njit(cache=True, nogil=True)(fifo_ref)


def fifo_fast(arrival_us: np.ndarray, free_us: float, period_us: float, max_delay_us: int):
    """fifo_ref, compiled (numba)."""
    out, kept, free = _fifo_numba(np.ascontiguousarray(arrival_us, np.int64), float(free_us), float(period_us),
                                  int(max_delay_us))
    return out, kept, float(free)


def arrival_times_us(t_us: np.ndarray, latency_us: float, jitter_us: float, rng: np.random.Generator) -> np.ndarray:
    """[N] int64: each event's arrival at the readout (see the module docstring)."""
    a = t_us.astype(np.float64) + latency_us
    if jitter_us > 0:
        a += np.clip(rng.standard_normal(t_us.shape[0]), -3.0, 3.0) * jitter_us
    return np.maximum(np.rint(a).astype(np.int64), t_us)


def round_up_to_period(t_us: np.ndarray, period_us: int) -> np.ndarray:
    """Timestamps rounded up to a multiple of period_us (a semi-synchronous readout's frame times)."""
    return -(-t_us // period_us) * period_us if period_us > 0 else t_us


class Readout:
    """The readout of one sensor (config: SimulatorConfig with has_readout); see the module docstring."""

    def __init__(self, config, rng: np.random.Generator, backend: str = "fast"):
        self.config, self.rng = config, rng
        self._fifo = fifo_fast if backend == "fast" else fifo_ref
        self.pending = empty_events()                 # not yet served: their arrival times in .t
        self.queued = empty_events()                  # served (final times), not yet out
        self.free_us = -math.inf
        self.n_dropped = 0

    def _serve(self, ready: np.ndarray) -> None:
        c = self.config
        if c.max_event_rate_hz > 0 and ready.size:
            out, kept, self.free_us = self._fifo(ready["t"], self.free_us, 1e6 / c.max_event_rate_hz,
                                                 c.max_readout_delay_us)
            self.n_dropped += int(ready.size - kept.sum())
            ready = ready[kept]
            ready["t"] = out[kept]
        ready["t"] = round_up_to_period(ready["t"], c.readout_period_us)
        self.queued = np.concatenate([self.queued, ready]) if self.queued.size else ready

    def push(self, events: np.ndarray, t_now_us: int) -> np.ndarray:
        """Take the pixels' events of an interval ending at t_now_us; return those out by t_now_us, in time order."""
        c = self.config
        if events.size:
            events = events.copy()
            events["t"] = arrival_times_us(events["t"], c.latency_us, c.latency_jitter_us, self.rng)
        pool = np.concatenate([self.pending, events]) if self.pending.size else events
        if c.latency_jitter_us > 0:     # without jitter the arrivals keep the pixels' order (pending ones first)
            pool = pool[np.argsort(pool["t"], kind="stable")]
        n_ready = int(np.searchsorted(pool["t"], t_now_us, side="right"))   # every later event arrives after t_now
        self.pending = pool[n_ready:]
        self._serve(pool[:n_ready])
        n_out = int(np.searchsorted(self.queued["t"], t_now_us, side="right"))
        out, self.queued = self.queued[:n_out], self.queued[n_out:]
        return np.ascontiguousarray(out, EVENT_DTYPE)

    def flush(self) -> np.ndarray:
        """Every event still inside the readout, in time order (the end of the recording)."""
        self._serve(self.pending)
        self.pending = empty_events()
        out, self.queued = self.queued, empty_events()
        return np.ascontiguousarray(out, EVENT_DTYPE)

    def state(self) -> dict:
        return {"readout_pending": self.pending.copy(), "readout_queued": self.queued.copy(),
                "readout_free_us": self.free_us, "readout_n_dropped": self.n_dropped,
                "readout_rng": json.dumps(self.rng.bit_generator.state)}

    def load_state(self, state) -> None:
        self.pending = np.asarray(state["readout_pending"], EVENT_DTYPE)
        self.queued = np.asarray(state["readout_queued"], EVENT_DTYPE)
        self.free_us = float(state["readout_free_us"])
        self.n_dropped = int(state["readout_n_dropped"])
        self.rng.bit_generator.state = json.loads(str(state["readout_rng"]))
