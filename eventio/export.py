"""Exporters of an EventStream to the formats other tools read.

- tonic: structured array with fields x, y, t (int64, microseconds), p (bool: True = ON), the
  ordering and types `tonic` transforms expect (`tonic.io.make_structured_array`), plus the sensor
  size (width, height, 2) as tonic spells it.
- E2VID text: first line "width height", then one event per line "t x y p" with t in seconds and
  p in {0, 1} (the rpg_e2vid input format).
- NumPy .npz: arrays t (int64 us), x, y (uint16), p (int8, +/-1), width, height.
All file writers write to a temporary name and rename when complete.
"""
from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np

from common.fileio import atomic_output
from eventio.events import EventStream, make_events, validate_events

TONIC_DTYPE = np.dtype([("x", "<i8"), ("y", "<i8"), ("t", "<i8"), ("p", "?")])


def to_tonic(stream: EventStream) -> tuple[np.ndarray, tuple[int, int, int]]:
    """(events [N] of TONIC_DTYPE, sensor_size (W, H, 2))."""
    ev = stream.events
    out = np.empty(len(ev), TONIC_DTYPE)
    out["x"], out["y"], out["t"], out["p"] = ev["x"], ev["y"], ev["t"], ev["p"] > 0
    return out, (stream.width, stream.height, 2)


def from_tonic(events: np.ndarray, sensor_size: tuple[int, int, int]) -> EventStream:
    p = np.where(events["p"].astype(bool), 1, -1).astype(np.int8)
    return EventStream(make_events(events["t"], events["x"], events["y"], p), int(sensor_size[0]), int(sensor_size[1]))


def write_e2vid_txt(path: str | os.PathLike, stream: EventStream, chunk: int = 1 << 20) -> Path:
    """E2VID text file: "width height" header, then "t x y p" lines (t seconds, microsecond digits)."""
    path = Path(path)
    with atomic_output(path) as tmp, open(tmp, "w") as fh:
        fh.write(f"{stream.width} {stream.height}\n")
        ev = stream.events
        for i in range(0, len(ev), chunk):
            part = ev[i:i + chunk]
            fh.write("".join(f"{seconds_text(int(t))} {x} {y} {int(p > 0)}\n"
                             for t, x, y, p in zip(part["t"].tolist(), part["x"].tolist(), part["y"].tolist(),
                                                   part["p"].tolist())))
    return path


def seconds_text(t_us: int) -> str:
    """Microseconds as exact decimal seconds, the sign written apart: -1939 -> '-0.001939'
    (divmod would floor it to -1.998061)."""
    sec, us = divmod(abs(t_us), 1_000_000)
    return f"{'-' if t_us < 0 else ''}{sec}.{us:06d}"


def parse_seconds(text: str) -> int:
    """Decimal seconds text -> integer microseconds, rounded to the nearest (half away from zero):
    the exact inverse of seconds_text, and rpg_e2vid's extractor's 12 decimals ('{:.12f}', float noise
    such as '17179.869182999999') land on the microsecond they stand for."""
    neg = text.startswith("-")
    whole, _, frac = text.lstrip("+-").partition(".")
    if not (whole or frac) or not (whole or "0").isdigit() or (frac and not frac.isdigit()):
        raise ValueError(f"{text!r} is not a time in decimal seconds")
    us = int(whole or "0") * 1_000_000 + int(frac[:6].ljust(6, "0") or "0")
    if len(frac) > 6 and int(frac[6]) >= 5:
        us += 1
    return -us if neg else us


def read_e2vid_txt(path: str | os.PathLike) -> EventStream:
    """An E2VID text file; ValueError naming the file (and the line) for anything else."""
    path = Path(path)
    try:
        return _read_e2vid_txt(path)
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not an E2VID event text file (not text: {path.read_bytes()[:8]!r}...)") from None


def _read_e2vid_txt(path: Path) -> EventStream:
    with open(path) as fh:
        header = fh.readline().split()
        if len(header) != 2 or not all(v.isdigit() and int(v) > 0 for v in header):
            raise ValueError(f"{path}: first line must be 'width height' (two positive integers), got "
                             f"{' '.join(header)[:80]!r}")
        width, height = int(header[0]), int(header[1])
        try:
            with warnings.catch_warnings():            # a header-only file is an empty recording, not a warning
                warnings.filterwarnings("ignore", message="loadtxt: input contained no data", category=UserWarning)
                data = np.loadtxt(fh, dtype=str, ndmin=2)
        except ValueError as exc:
            raise ValueError(f"{path}: expected lines 't x y p' ({' '.join(str(exc).split())[:120]})") from None
    if data.size == 0:
        return EventStream(make_events([], [], [], []), width, height)
    if data.shape[1] != 4:
        raise ValueError(f"{path}: expected 4 columns 't x y p', got {data.shape[1]}")
    try:
        t = np.array([parse_seconds(v) for v in data[:, 0].tolist()], np.int64)
    except ValueError as exc:
        raise ValueError(f"{path}: time column: {exc}") from None
    cols = []
    for k, name in ((1, "x"), (2, "y"), (3, "p")):
        bad = [i for i, v in enumerate(data[:, k].tolist()) if not v.isdigit()]
        if bad:
            raise ValueError(f"{path}: line {bad[0] + 2}: {name} = {data[bad[0], k][:20]!r} is not a non-negative integer")
        cols.append(data[:, k].astype(np.int64))
    x, y, p = cols
    if (p > 1).any():
        i = int(np.flatnonzero(p > 1)[0])
        raise ValueError(f"{path}: line {i + 2}: p = {int(p[i])}; expected 0 (OFF) or 1 (ON)")
    for name, v, limit in (("x", x, width), ("y", y, height)):
        if (v >= limit).any():
            i = int(np.flatnonzero(v >= limit)[0])
            raise ValueError(f"{path}: line {i + 2}: {name} = {int(v[i])} outside the sensor ({width}x{height} in the header)")
    stream = EventStream(make_events(t, x, y, np.where(p > 0, 1, -1).astype(np.int8)), width, height)
    try:
        validate_events(stream.events, width, height)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return stream


def write_npz(path: str | os.PathLike, stream: EventStream) -> Path:
    path = Path(path)
    ev = stream.events
    buf = io.BytesIO()      # zipped in memory: a full disk then fails one plain write, not zipfile's finaliser
    np.savez(buf, t=ev["t"], x=ev["x"], y=ev["y"], p=ev["p"], width=stream.width, height=stream.height)
    with atomic_output(path) as tmp, open(tmp, "wb") as fh:
        fh.write(buf.getbuffer())
    return path


def read_npz(path: str | os.PathLike) -> EventStream:
    """An .npz of arrays t (integer microseconds), x, y, p (+1 / -1, or 1 / 0), width, height; a
    column of another kind (float seconds, negative pixels, other polarities) is refused by name."""
    import zipfile

    path = Path(path)
    try:
        z = np.load(path, allow_pickle=False)
        if not hasattr(z, "files"):
            raise ValueError("a single array, not an archive of named arrays")
        with z:
            missing = [k for k in ("t", "x", "y", "p", "width", "height") if k not in z.files]
            if missing:
                raise ValueError(f"no array {', '.join(missing)} (it has {', '.join(z.files) or 'none'})")
            cols = {k: np.asarray(z[k]) for k in ("t", "x", "y", "p")}
            width, height = (np.asarray(z[k]) for k in ("width", "height"))
    except FileNotFoundError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not an .npz event file ({' '.join(str(exc).split())[:160]})") from None
    for name in ("width", "height"):
        v = {"width": width, "height": height}[name]
        if v.shape != () or v.dtype.kind not in "iu" or int(v) <= 0:
            found = f"{v.item()!r}" if v.shape == () else f"{v.dtype.name} of shape {v.shape}"
            raise ValueError(f"{path}: {name}: expected the sensor's {name} as a positive integer, found {found}")
    n = len(cols["t"])
    for name, col in cols.items():
        if col.ndim != 1 or len(col) != n:
            raise ValueError(f"{path}: {name}: expected a 1-D array of {n} values like t, found shape {col.shape}")
        if col.dtype.kind not in "iu" and not (name == "p" and col.dtype.kind == "b"):
            hint = " (seconds? multiply by 1e6 and round to integer microseconds)" if name == "t" and col.dtype.kind == "f" else ""
            raise ValueError(f"{path}: {name}: expected integers, found {col.dtype.name}{hint}")
    p = cols["p"].astype(np.int64)
    if n and not (np.isin(p, (-1, 1)).all() or np.isin(p, (0, 1)).all()):
        bad = int(p[~np.isin(p, (-1, 0, 1))][0]) if (~np.isin(p, (-1, 0, 1))).any() else 0
        raise ValueError(f"{path}: p: expected +1 / -1 (or 1 / 0) for ON / OFF, found {bad}")
    for name, limit in (("x", int(width)), ("y", int(height))):
        col = cols[name]
        bad = np.flatnonzero((col < 0) | (col >= limit))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"{path}: {name}[{i}] = {int(col[i])} outside the sensor ({int(width)}x{int(height)})")
    events = make_events(cols["t"], cols["x"], cols["y"], np.where(p > 0, 1, -1).astype(np.int8))
    try:
        validate_events(events, int(width), int(height))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return EventStream(events, int(width), int(height))
