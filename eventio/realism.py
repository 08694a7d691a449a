"""How an event stream looks to a sensor engineer, and how far two streams are apart (pure NumPy and
SciPy on EventStream). `e4dgs realism` prints and draws these for one recording, or for a simulated
one beside a real one (eventio.realism_cli).

Statistics of one stream (all times in microseconds of the stream's own clock):
- duration_s: last minus first event time; rate_ev_per_s: events / duration; rate_series: events in
  consecutive 10 ms bins from the first event (the time course);
- on_fraction: share of ON events; active_fraction: share of the sensor's pixels with any event;
- per-pixel rate: events / duration of each active pixel (Hz), summarised by its median, p99 and max;
- inter-event interval (IEI): the time between consecutive events of one pixel, us; its floor is
  p0.1 and p1 (a refractory period shows as a floor with nothing below it); distances use log10 of
  the interval clamped at 1 us (cameras stamp whole microseconds: 0 us intervals occur);
- same_polarity_fraction: share of a pixel's consecutive event pairs with the same polarity;
- background activity: an event is isolated when none of its 8 neighbouring pixels had an event in
  the 5 ms before it (up to its own time; the pixel itself not counted), the test of a causal
  background-activity filter; ba_fraction is the isolated share
  and ba_rate_hz the isolated events per sensor pixel per second (isolated events are not all noise:
  a sparse real edge is isolated too);
- hot pixels: pixels with at least 10 events whose rate exceeds 5 x the p99 of the active pixels'.

Distances of a simulated stream to a real one: Wasserstein-1 between the log10 per-pixel rates of
their active pixels and between their log10 IEIs; relative errors of the scalars ((sim - real) /
real); and the Pearson correlation of their 10 ms rate series over the common length, when the two
cover the same span within 10 % (aligned clips).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from eventio.events import EventStream

BIN_US = 10_000                 # the rate series' bin
BA_WINDOW_US = 5_000            # background activity: no neighbour event within this before
HOT_FACTOR = 5.0                # hot pixel: rate above this x p99 of the active pixels
HOT_MIN_EVENTS = 10
ALIGNED_SPAN = 0.10             # rate series are correlated when the durations agree within 10 %
_PIXEL_SHIFT = 42               # key = pixel << 42 | (t - t0): 2^42 us is 51 days


@dataclass
class RealismStats:
    """One stream's statistics (module note). Distributions are kept as arrays for the distances and
    the picture; `summary()` is the scalar part."""
    width: int
    height: int
    n_events: int
    duration_s: float
    rate_ev_per_s: float
    on_fraction: float
    active_fraction: float
    pixel_rate_median_hz: float
    pixel_rate_p99_hz: float
    pixel_rate_max_hz: float
    iei_p0_1_us: float
    iei_p1_us: float
    iei_p50_us: float
    iei_min_us: float
    same_polarity_fraction: float
    ba_fraction: float
    ba_rate_hz: float
    hot_pixels: int
    hot_fraction: float
    rate_series: np.ndarray = field(repr=False)        # [B] events per 10 ms bin
    log_pixel_rates: np.ndarray = field(repr=False)    # [A] log10 Hz of the active pixels
    log_iei: np.ndarray = field(repr=False)            # [I] log10 us, clamped at 1 us

    def summary(self) -> dict:
        return {k: v for k, v in asdict(self).items() if not isinstance(v, np.ndarray)}


def _nan() -> float:
    return float("nan")


def pixel_order(stream: EventStream) -> tuple[np.ndarray, np.ndarray]:
    """(pixel index y * W + x of each event [N], the events' order sorted by pixel, then time [N])."""
    e = stream.events
    pix = e["y"].astype(np.int64) * stream.width + e["x"].astype(np.int64)
    return pix, np.lexsort((e["t"], pix))


def inter_event_intervals(stream: EventStream) -> tuple[np.ndarray, np.ndarray]:
    """(same-pixel inter-event intervals in us [I], whether each pair keeps its polarity [I])."""
    e = stream.events
    pix, order = pixel_order(stream)
    p, t = pix[order], e["t"][order]
    same_pixel = p[1:] == p[:-1]
    return (np.diff(t)[same_pixel], (e["p"][order][1:] == e["p"][order][:-1])[same_pixel])


def isolated_events(stream: EventStream, window_us: int = BA_WINDOW_US) -> np.ndarray:
    """bool [N]: no event at any of the 8 neighbouring pixels in the window_us before (t - window_us
    <= t' <= t)."""
    e = stream.events
    n = len(e)
    if n == 0:
        return np.zeros(0, bool)
    t = e["t"].astype(np.int64) - int(e["t"].min())
    x, y = e["x"].astype(np.int64), e["y"].astype(np.int64)
    keys = np.sort(((y * stream.width + x) << _PIXEL_SHIFT) | t)
    isolated = np.ones(n, bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dx == dy == 0:
                continue
            nx, ny = x + dx, y + dy
            inside = (nx >= 0) & (nx < stream.width) & (ny >= 0) & (ny < stream.height)
            q = ((ny * stream.width + nx) << _PIXEL_SHIFT)[inside]
            lo = np.searchsorted(keys, q | np.maximum(t[inside] - window_us, 0), side="left")
            hi = np.searchsorted(keys, q | t[inside], side="right")
            near = np.zeros(n, bool)
            near[np.flatnonzero(inside)] = hi > lo
            isolated &= ~near
    return isolated


def stream_stats(stream: EventStream) -> RealismStats:
    """RealismStats of one stream (ValueError for a stream with fewer than two events)."""
    e = stream.events
    n = len(e)
    if n < 2:
        raise ValueError(f"a realism report needs at least two events, got {n}")
    t0, t1 = int(e["t"].min()), int(e["t"].max())
    duration_s = max(t1 - t0, 1) / 1e6
    pixels = stream.width * stream.height
    counts = np.bincount(e["y"].astype(np.int64) * stream.width + e["x"].astype(np.int64), minlength=pixels)
    active = counts[counts > 0]
    rates = active / duration_s
    iei, same = inter_event_intervals(stream)
    p99 = float(np.percentile(rates, 99))
    hot = int(np.sum((counts >= HOT_MIN_EVENTS) & (counts / duration_s > HOT_FACTOR * p99)))
    iso = isolated_events(stream)
    series = np.bincount((e["t"].astype(np.int64) - t0) // BIN_US, minlength=(t1 - t0) // BIN_US + 1)
    pct = (lambda q: float(np.percentile(iei, q))) if len(iei) else (lambda q: _nan())
    return RealismStats(
        width=stream.width, height=stream.height, n_events=n, duration_s=duration_s, rate_ev_per_s=n / duration_s,
        on_fraction=float(np.mean(e["p"] > 0)), active_fraction=len(active) / pixels,
        pixel_rate_median_hz=float(np.median(rates)), pixel_rate_p99_hz=p99, pixel_rate_max_hz=float(rates.max()),
        iei_p0_1_us=pct(0.1), iei_p1_us=pct(1), iei_p50_us=pct(50), iei_min_us=float(iei.min()) if len(iei) else _nan(),
        same_polarity_fraction=float(np.mean(same)) if len(same) else _nan(),
        ba_fraction=float(np.mean(iso)), ba_rate_hz=float(iso.sum()) / pixels / duration_s,
        hot_pixels=hot, hot_fraction=hot / pixels, rate_series=series.astype(np.float64),
        log_pixel_rates=np.log10(rates), log_iei=np.log10(np.maximum(iei, 1)).astype(np.float64))


# the scalars whose relative error the comparison reports
COMPARED = ("rate_ev_per_s", "on_fraction", "active_fraction", "pixel_rate_median_hz", "pixel_rate_p99_hz",
            "iei_p1_us", "iei_p50_us", "same_polarity_fraction", "ba_fraction", "ba_rate_hz", "hot_fraction")


def distances(sim: RealismStats, real: RealismStats) -> dict:
    """How far `sim` is from `real` (module note): w1_log_rate, w1_log_iei (decades), rate_correlation
    (None unless aligned) and `relative` {scalar: (sim - real) / real}."""
    from scipy.stats import wasserstein_distance

    def w1(a: np.ndarray, b: np.ndarray) -> float:
        return float(wasserstein_distance(a, b)) if len(a) and len(b) else _nan()

    rel = {}
    for k in COMPARED:
        a, b = getattr(sim, k), getattr(real, k)
        rel[k] = (a - b) / b if b and math.isfinite(a) and math.isfinite(b) else _nan()
    corr = None
    if abs(sim.duration_s - real.duration_s) <= ALIGNED_SPAN * real.duration_s:
        m = min(len(sim.rate_series), len(real.rate_series))
        a, b = sim.rate_series[:m], real.rate_series[:m]
        corr = float(np.corrcoef(a, b)[0, 1]) if m > 2 and a.std() > 0 and b.std() > 0 else None
    return {"w1_log_rate": w1(sim.log_pixel_rates, real.log_pixel_rates),
            "w1_log_iei": w1(sim.log_iei, real.log_iei), "rate_correlation": corr, "relative": rel}


def pixel_rate_hz(stream: EventStream, mask: np.ndarray) -> float:
    """Events per masked pixel per second (mask bool [H, W]: e.g. the pixels whose scene never
    changes, where every event is noise); nan for an empty mask."""
    e = stream.events
    if not mask.any() or len(e) < 2:
        return _nan()
    inside = mask[e["y"].astype(np.int64), e["x"].astype(np.int64)]
    duration_s = max(int(e["t"].max()) - int(e["t"].min()), 1) / 1e6
    return float(inside.sum()) / float(mask.sum()) / duration_s
