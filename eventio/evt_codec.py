"""Prophesee EVT 2.0 and EVT 3.0 encoders (events -> words) and the `.raw` file header, as pure
functions, written from Prophesee's published format descriptions (docs.prophesee.ai, "EVT 2.0
Format", "EVT 3.0 Format"). No maintained library writes these formats; decoding is left to
independent decoders (`evt3` for EVT 3.0, `expelliarmus` for EVT 2.0 and 3.0, Metavision / OpenEB).

EVT 2.0: 32-bit little-endian words, type in bits 31-28.
    CD_OFF 0x0 / CD_ON 0x1: [27:22] timestamp bits 5-0, [21:11] x, [10:0] y
    EVT_TIME_HIGH 0x8:      [27:0] timestamp bits 33-6
EVT 3.0: 16-bit little-endian words, type in bits 15-12; the decoder keeps a state (y, base x,
polarity, 24-bit time) that words update:
    EVT_ADDR_Y 0x0:    [10:0] y ([11] system type: 0)
    EVT_ADDR_X 0x2:    [11] polarity, [10:0] x: one event at (x, y)
    VECT_BASE_X 0x3:   [11] polarity, [10:0] x: the base of the following vectors
    VECT_12 0x4:       [11:0] valid mask: events at base + i for each set bit i; base += 12
    VECT_8 0x5:        [7:0] valid mask; base += 8
    EVT_TIME_LOW 0x6:  [11:0] timestamp bits 11-0
    EVT_TIME_HIGH 0x8: [11:0] timestamp bits 23-12 (the decoder counts a wrap when it decreases)
The encoder emits these seven types (CONTINUED_4 / CONTINUED_12 / EXT_TRIGGER / OTHERS carry data
that a CD event stream does not have). Events at one timestamp are grouped by row, then polarity;
within a group, a run of >= 2 distinct columns inside 12 goes out as VECT_BASE_X + VECT_12 / VECT_8
words, the rest (and repeated events of one pixel) as EVT_ADDR_X. Like a sensor, the encoder emits
every EVT_TIME_HIGH value (one word per 4,096 us, also across gaps without events): Metavision's
decoder counts a wrap of the 24-bit time (every 16.78 s) only when the time high falls from near
4095 to near 0 (by at least 4085), so a word that jumped further would lose 16.78 s. Decoded order within one timestamp follows the encoding (row, polarity, column), so round
trips are compared as the same events per timestamp.

Each encoder comes as a readable reference (`*_ref`) and a fast one with the same signature.
"""
from __future__ import annotations

import datetime
import re
from typing import NamedTuple

import numba
import numpy as np

MAX_SENSOR = 2048                     # 11-bit x and y in both formats
EVT2_MAX_TIME_US = (1 << 34) - 1      # 28 + 6 timestamp bits
EVT3_TIME_HIGH_STEP = 1               # EVT_TIME_HIGH units one word advances (a sensor emits every one)

EVT2_CD_OFF, EVT2_CD_ON, EVT2_TIME_HIGH = 0x0, 0x1, 0x8
EVT3_ADDR_Y, EVT3_ADDR_X, EVT3_VECT_BASE_X, EVT3_VECT_12, EVT3_VECT_8 = 0x0, 0x2, 0x3, 0x4, 0x5
EVT3_TIME_LOW, EVT3_TIME_HIGH = 0x6, 0x8

FORMATS = {"evt2": ("2.0", "EVT2"), "evt3": ("3.0", "EVT3")}


class EvtFormatError(ValueError):
    """Events that a format cannot hold, or a file that is not one (the message names what)."""


# -- header ------------------------------------------------------------------------------------------
def raw_header(fmt: str, width: int, height: int, date: datetime.datetime | None = None, t0_us: int = 0) -> bytes:
    """The ASCII header Metavision / OpenEB write before the words of a `.raw` file; `t0_us` > 0 adds
    faery's `% t0 <us>` line (the words hold times relative to it)."""
    version, name = FORMATS[fmt]
    date = date or datetime.datetime.now(datetime.timezone.utc)
    lines = [f"date {date:%Y-%m-%d %H:%M:%S}", f"evt {version}", f"format {name};height={height};width={width}",
             f"geometry {width}x{height}", "integrator_name e4dgs-toolkit", "plugin_name e4dgs_simulator"]
    if t0_us:
        lines.append(f"t0 {int(t0_us)}")
    lines.append("end")
    return "".join(f"% {line}\n" for line in lines).encode("ascii")


class RawHeader(NamedTuple):
    fmt: str            # 'evt2' | 'evt3'
    width: int
    height: int
    offset: int         # bytes before the first word
    t0_us: int          # absolute time of word time 0 (faery's `% t0` line; 0 without one)
    has_end: bool       # the header closes with `% end` (else its end is where lines stop)


_HEADER_LINE = re.compile(rb"%[ -~]{0,1023}\r?\n")   # '%', printable ASCII, a line end


# Sensor size of each Metavision HAL plug-in, for headers written before `format` / `geometry` lines
# existed (e.g. a Gen3 VGA camera's EVT 2.0 file: `% plugin_name hal_plugin_gen3_fx3`, `% evt 2.0`).
# From openeb's hal_psee_plugins raw_constants.h (plugins_map).
PLUGIN_SENSORS = {"hal_plugin_gen3_fx3": (640, 480), "hal_plugin_gen31_fx3": (640, 480),
                  "hal_plugin_gen31_evk2": (640, 480), "hal_plugin_gen31_evk3": (640, 480),
                  "hal_plugin_gen4_fx3": (1280, 720), "hal_plugin_gen4_evk2": (1280, 720),
                  "hal_plugin_gen41_evk2": (1280, 720), "hal_plugin_gen41_evk3": (1280, 720)}


def parse_raw_header(data: bytes, source: str = "file") -> RawHeader:
    """The header of a `.raw` file's bytes. Without a `% end` line (faery writes none) the header is
    the run of lines of '%' and printable ASCII; a first word whose first byte is '%' stays data."""
    fields: dict[str, str] = {}
    pos = 0
    has_end = False
    while pos < len(data) and data[pos:pos + 1] == b"%":
        m = _HEADER_LINE.match(data, pos)
        if m is None:
            if not fields:
                raise EvtFormatError(f"{source}: the header's first line is not a text line ending in a line "
                                     "break (a truncated file, or not a .raw file)")
            break                       # not a text line: the words begin here
        line = m.group()[1:].decode("ascii").strip()
        pos = m.end()
        if line == "end":
            has_end = True
            break
        key, _, value = line.partition(" ")
        fields[key] = value.strip()
    if not fields:
        raise EvtFormatError(f"{source}: no '% ...' header: not a Prophesee .raw file")
    fmt = width = height = None
    if "format" in fields:
        parts = fields["format"].split(";")
        fmt = {"EVT2": "evt2", "EVT3": "evt3", "2.0": "evt2", "3.0": "evt3"}.get(parts[0].strip().upper())
        opts = dict(p.split("=", 1) for p in parts[1:] if "=" in p)
        width, height = opts.get("width"), opts.get("height")
    if fmt is None and "evt" in fields:
        fmt = {"2.0": "evt2", "3.0": "evt3"}.get(fields["evt"])
    if (width is None or height is None) and "geometry" in fields:
        width, _, height = fields["geometry"].partition("x")
    if (width is None or height is None) and fields.get("plugin_name") in PLUGIN_SENSORS:
        width, height = PLUGIN_SENSORS[fields["plugin_name"]]      # older headers name only the camera's plug-in
    if fmt is None:
        raise EvtFormatError(f"{source}: the header names no EVT 2.0 / 3.0 format "
                             f"(format {fields.get('format')!r}, evt {fields.get('evt')!r})")
    try:
        w, h = int(width), int(height)
    except (TypeError, ValueError):
        raise EvtFormatError(f"{source}: the header gives no sensor size (format / geometry, or a known "
                             f"plugin_name; got {fields.get('plugin_name')!r})") from None
    if not (0 < w <= MAX_SENSOR and 0 < h <= MAX_SENSOR):
        raise EvtFormatError(f"{source}: sensor {w}x{h} outside 1..{MAX_SENSOR} per side")
    t0 = fields.get("t0", "0")
    if not t0.isdigit():
        raise EvtFormatError(f"{source}: header line '% t0 {t0}': expected the start time in whole microseconds")
    return RawHeader(fmt, w, h, pos, int(t0), has_end)


def neutral_lead(fmt: str, body: bytes) -> bytes:
    """A TIME_HIGH 0 word to put before `body` when its first byte is '%' (0x25): a reader that takes
    every line starting with '%' as header (expelliarmus does, even after `% end`) would swallow the
    first words. At the start of a stream the word changes no decoded time (the time high starts at
    0 and only rises to the first word's)."""
    if body[:1] != b"%":
        return b""
    return np.array([EVT2_TIME_HIGH << 28], "<u4").tobytes() if fmt == "evt2" else \
        np.array([EVT3_TIME_HIGH << 12], "<u2").tobytes()


def time_origin_us(t: np.ndarray, fmt: str) -> int:
    """The `% t0` a stream needs in format `fmt`: 0 when its absolute times fit the words (EVT 2.0: up
    to 2^34 us; EVT 3.0: a first time before the first 24-bit wrap, 16.78 s, which a decoder starting
    from 0 reads exactly), else the first event's time (a recording stamped in epoch time)."""
    if len(t) == 0 or int(t[0]) < 0:
        return 0
    fits = int(t[-1]) <= EVT2_MAX_TIME_US if fmt == "evt2" else int(t[0]) < (1 << 24)
    return 0 if fits else int(t[0])


def check_encodable(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int,
                    max_time_us: int | None = None) -> None:
    """EvtFormatError naming the first event a `.raw` file cannot hold (times sorted and >= 0, within
    the format's time range, coordinates inside a sensor of at most 2048 x 2048)."""
    if not (0 < width <= MAX_SENSOR and 0 < height <= MAX_SENSOR):
        raise EvtFormatError(f"sensor {width}x{height}: EVT formats hold at most {MAX_SENSOR} x {MAX_SENSOR}")
    if len(t) == 0:
        return
    checks = [(t < 0, "negative timestamp (EVT times are unsigned: shift the stream)"),
              (np.r_[False, t[1:] < t[:-1]], "timestamps not sorted"),
              (x >= width, f"x outside the sensor width {width}"), (y >= height, f"y outside the sensor height {height}"),
              ((p != 1) & (p != -1), "polarity not +1 / -1")]
    if max_time_us is not None:
        checks.append((t > max_time_us, f"timestamp beyond the format's {max_time_us} us"))
    for bad, what in checks:
        idx = np.flatnonzero(bad)
        if idx.size:
            i = int(idx[0])
            raise EvtFormatError(f"event {i} (t={int(t[i])} us, x={int(x[i])}, y={int(y[i])}, p={int(p[i])}): {what}")


# -- EVT 2.0 -----------------------------------------------------------------------------------------
def encode_evt2_ref(t, x, y, p) -> np.ndarray:
    """Events (sorted t in us, x, y, p in {-1, +1}) -> EVT 2.0 words [M] uint32 (readable reference)."""
    words = []
    high = None
    for ti, xi, yi, pi in zip(np.asarray(t).tolist(), np.asarray(x).tolist(), np.asarray(y).tolist(),
                              np.asarray(p).tolist()):
        if ti >> 6 != high:
            high = ti >> 6
            words.append((EVT2_TIME_HIGH << 28) | (high & 0x0FFFFFFF))
        kind = EVT2_CD_ON if pi > 0 else EVT2_CD_OFF
        words.append((kind << 28) | ((ti & 0x3F) << 22) | ((xi & 0x7FF) << 11) | (yi & 0x7FF))
    return np.asarray(words, np.uint32)


def encode_evt2(t, x, y, p) -> np.ndarray:
    """`encode_evt2_ref` vectorised: a time-high word before each event whose t >> 6 differs from the last."""
    t = np.asarray(t, np.int64)
    n = len(t)
    high = t >> 6
    new_high = np.ones(n, bool)
    new_high[1:] = high[1:] != high[:-1]
    cd = ((np.where(np.asarray(p) > 0, EVT2_CD_ON, EVT2_CD_OFF).astype(np.uint64) << 28)
          | ((t & 0x3F).astype(np.uint64) << 22) | ((np.asarray(x, np.uint64) & 0x7FF) << 11)
          | (np.asarray(y, np.uint64) & 0x7FF))
    pos = np.arange(n) + np.cumsum(new_high)          # each event's word index
    out = np.empty(n + int(new_high.sum()), np.uint64)
    out[pos] = cd
    out[pos[new_high] - 1] = (np.uint64(EVT2_TIME_HIGH) << np.uint64(28)) | (high[new_high].astype(np.uint64) & 0x0FFFFFFF)
    return out.astype(np.uint32)


# -- EVT 3.0 -----------------------------------------------------------------------------------------
def evt3_order(t, x, y, p) -> np.ndarray:
    """The order [N] the EVT 3.0 encoder writes events in: by time, then row, then polarity, then column
    (one int64 key: t below 2^40 us, 12.7 days, as `check_encodable` leaves it)."""
    t = np.asarray(t, np.int64)
    if len(t) and (t.min() < 0 or t.max() >= 1 << 40):
        return np.lexsort((np.asarray(x), np.asarray(p), np.asarray(y), t))
    key = (t << 23) | (np.asarray(y, np.int64) << 12) | ((np.asarray(p) > 0).astype(np.int64) << 11) \
        | np.asarray(x, np.int64)
    return np.argsort(key, kind="stable")


def _w3(kind: int, payload: int) -> int:
    return (kind << 12) | (payload & 0xFFF)


def encode_evt3_ref(t, x, y, p) -> np.ndarray:
    """Events (sorted t in us, x, y, p in {-1, +1}) -> EVT 3.0 words [M] uint16 (readable reference)."""
    order = evt3_order(t, x, y, p)
    t, x, y, p = (np.asarray(a)[order].tolist() for a in (t, x, y, p))
    words: list[int] = []
    last_high = cur_low = cur_y = None
    i, n = 0, len(t)
    while i < n:
        ti = t[i]
        high = ti >> 12
        if last_high is None:
            last_high = high
            words.append(_w3(EVT3_TIME_HIGH, high))
            cur_low = None
        while last_high < high:           # every time-high value, as a sensor sends them
            last_high += min(high - last_high, EVT3_TIME_HIGH_STEP)
            words.append(_w3(EVT3_TIME_HIGH, last_high))
            cur_low = None
        if cur_low != ti & 0xFFF:
            cur_low = ti & 0xFFF
            words.append(_w3(EVT3_TIME_LOW, cur_low))
        # one (t, y, p) group: its columns, sorted (repeats possible)
        j = i
        while j < n and t[j] == ti and y[j] == y[i] and p[j] == p[i]:
            j += 1
        if cur_y != y[i]:
            cur_y = y[i]
            words.append(_w3(EVT3_ADDR_Y, cur_y & 0x7FF))
        pol = 1 if p[i] > 0 else 0
        words += _row_words_ref(x[i:j], pol)
        i = j
    return np.asarray(words, np.uint16)


def _row_words_ref(xs: list[int], pol: int) -> list[int]:
    """Words for the sorted columns (repeats possible) of one (t, y, polarity) group."""
    words = []
    k = 0
    while k < len(xs):
        block = [v for v in xs[k:] if v < xs[k] + 12]          # a prefix: xs is sorted
        if len(set(block)) < 2 or len(set(block)) < len(block):
            words.append(_w3(EVT3_ADDR_X, (pol << 11) | xs[k]))  # a lone column, or a pixel firing twice
            k += 1
            continue
        base = xs[k]
        words.append(_w3(EVT3_VECT_BASE_X, (pol << 11) | base))
        while k < len(xs) and xs[k] < base + 12:
            block = [v for v in xs[k:] if v < base + 12]
            if len(set(block)) < len(block):
                break                                            # a repeat: the next pass of the loop sends it alone
            kind, width = (EVT3_VECT_8, 8) if block[-1] < base + 8 else (EVT3_VECT_12, 12)
            words.append(_w3(kind, sum(1 << (v - base) for v in block)))
            k += len(block)
            base += width
    return words


@numba.njit(cache=True, nogil=True)
def _encode_evt3_sorted(t, x, y, p, out):
    """The reference's algorithm on arrays already in `evt3_order`; returns the number of words."""
    n = t.shape[0]
    m = 0
    last_high = -1
    cur_low = -1
    cur_y = -1
    i = 0
    while i < n:
        ti = t[i]
        high = ti >> 12
        if last_high < 0:
            last_high = high
            out[m] = (EVT3_TIME_HIGH << 12) | (high & 0xFFF)
            m += 1
            cur_low = -1
        while last_high < high:
            last_high += min(high - last_high, EVT3_TIME_HIGH_STEP)
            out[m] = (EVT3_TIME_HIGH << 12) | (last_high & 0xFFF)
            m += 1
            cur_low = -1
        if cur_low != (ti & 0xFFF):
            cur_low = ti & 0xFFF
            out[m] = (EVT3_TIME_LOW << 12) | cur_low
            m += 1
        j = i
        while j < n and t[j] == ti and y[j] == y[i] and p[j] == p[i]:
            j += 1
        if cur_y != y[i]:
            cur_y = y[i]
            out[m] = (EVT3_ADDR_Y << 12) | (cur_y & 0x7FF)
            m += 1
        pol = 1 if p[i] > 0 else 0
        k = i
        while k < j:
            x0 = x[k]
            # distinct columns within [x0, x0 + 12) and whether one repeats there
            cnt = 0
            rep = False
            q = k
            while q < j and x[q] < x0 + 12:
                if q > k and x[q] == x[q - 1]:
                    rep = True
                else:
                    cnt += 1
                q += 1
            if cnt < 2 or rep:
                out[m] = (EVT3_ADDR_X << 12) | (pol << 11) | x0
                m += 1
                k += 1
                continue
            out[m] = (EVT3_VECT_BASE_X << 12) | (pol << 11) | x0
            m += 1
            base = x0
            while k < j and x[k] < base + 12:
                q = k
                rep = False
                while q < j and x[q] < base + 12:
                    if q > k and x[q] == x[q - 1]:
                        rep = True
                    q += 1
                if rep:
                    break
                mask = 0
                for r in range(k, q):
                    mask |= 1 << (x[r] - base)
                if x[q - 1] < base + 8:
                    out[m] = (EVT3_VECT_8 << 12) | mask
                    base += 8
                else:
                    out[m] = (EVT3_VECT_12 << 12) | mask
                    base += 12
                m += 1
                k = q
        i = j
    return m


def encode_evt3(t, x, y, p) -> np.ndarray:
    """`encode_evt3_ref` compiled (numba); the same words."""
    order = evt3_order(t, x, y, p)
    ts = np.ascontiguousarray(np.asarray(t, np.int64)[order])
    xs, ys = (np.ascontiguousarray(np.asarray(a, np.int64)[order]) for a in (x, y))
    ps = np.ascontiguousarray(np.asarray(p, np.int64)[order])
    span = int(ts[-1] >> 12) - int(ts[0] >> 12) if len(ts) else 0
    out = np.empty(4 * len(ts) + span // EVT3_TIME_HIGH_STEP + 2, np.int64)   # <= 4 words an event, + time highs
    m = _encode_evt3_sorted(ts, xs, ys, ps, out)
    return out[:m].astype(np.uint16)
