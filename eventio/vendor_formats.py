"""Event files in the formats cameras and their software write, through the vendors' libraries:

- `.raw` EVT 3.0 / EVT 2.0 (Prophesee Metavision / OpenEB): written by our encoder
  (eventio.evt_codec: no maintained library writes them), read back with `evt3` (EVT 3.0) and
  `expelliarmus` (EVT 2.0), neither of them ours;
- `.aedat4` (iniVation DV): written and read by `dv-processing`;
- ROS bags (`dvs_msgs/EventArray`): eventio.rosbag_io.

Every writer writes to a temporary name and renames it when complete (common.fileio.atomic_output);
every reader returns an EventStream (t in microseconds, p in {-1, +1}) with the sensor size from the
file, and says what is wrong with a file it cannot read (FormatError, naming the file).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from common.fileio import atomic_output, require_free_space
from eventio import evt_codec
from eventio.events import EventStream, make_events, validate_events


class FormatError(ValueError):
    """A file that is not what its format says, or events a format cannot hold (names the file)."""


def vendor_module(module: str, package: str):
    import importlib
    try:
        return importlib.import_module(module)
    except ImportError:
        raise FormatError(f"this format needs the {package} package: pip install '{package}' "
                          "(installed with the toolkit's `formats` extra)") from None


@contextlib.contextmanager
def _named(path: Path, suffix: str):
    """`path`, or a link to it whose name ends in `suffix` (readers that go by the extension)."""
    if path.suffix == suffix:
        yield path
        return
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    with tempfile.TemporaryDirectory() as tmp:     # readers resolve symbolic links: a hard link, or a copy
        link = Path(tmp) / f"events{suffix}"
        try:
            os.link(path, link)
        except OSError:
            shutil.copyfile(path, link)
        yield link


def _library_message(exc: BaseException) -> str:
    """A vendor library's error in one line, without its source location and stack trace."""
    text = " ".join(str(exc).split()).split(" Stacktrace:")[0]
    return text.split("() ", 1)[-1]


def checked_stream(path: Path, t, x, y, p, width: int, height: int) -> EventStream:
    """EventStream from decoded columns, refusing what our event type cannot hold (naming the file)."""
    t = np.asarray(t, np.int64)
    if len(t) and (np.asarray(x).max() >= width or np.asarray(y).max() >= height):
        raise FormatError(f"{path}: events outside the sensor {width}x{height} the file declares")
    order = np.argsort(t, kind="stable")      # a recording may hold ties or small reorderings
    events = make_events(t[order], np.asarray(x)[order], np.asarray(y)[order], np.asarray(p)[order])
    try:
        validate_events(events, width, height)
    except ValueError as exc:
        raise FormatError(f"{path}: {exc}") from None
    return EventStream(events, int(width), int(height))


# -- Prophesee .raw ----------------------------------------------------------------------------------
def write_raw(path: str | os.PathLike, stream: EventStream, fmt: str = "evt3") -> Path:
    """`stream` as a Metavision `.raw` file in EVT 3.0 (`fmt="evt3"`) or EVT 2.0 (`"evt2"`). A stream
    whose absolute times the words cannot hold (epoch-stamped recordings) is written relative to its
    first event, which the header's `% t0 <us>` line keeps (faery's convention; `read_raw` adds it)."""
    if fmt not in evt_codec.FORMATS:
        raise ValueError(f"unknown .raw format {fmt!r} (expected evt2 or evt3)")
    path = Path(path)
    ev = stream.events
    t, x, y, p = ev["t"], ev["x"], ev["y"], ev["p"]
    t0 = evt_codec.time_origin_us(t, fmt)
    t = t - t0
    try:
        evt_codec.check_encodable(t, x, y, p, stream.width, stream.height,
                                  evt_codec.EVT2_MAX_TIME_US if fmt == "evt2" else None)
    except evt_codec.EvtFormatError as exc:
        raise FormatError(f"{path}: cannot write {fmt.upper()}: {exc}") from None
    if fmt == "evt3":
        body = evt_codec.encode_evt3(t, x, y, p).astype("<u2") if len(t) else np.empty(0, "<u2")
    else:
        body = evt_codec.encode_evt2(t, x, y, p).astype("<u4") if len(t) else np.empty(0, "<u4")
    with atomic_output(path) as tmp, open(tmp, "wb") as fh:
        fh.write(evt_codec.raw_header(fmt, stream.width, stream.height, t0_us=t0))
        data = body.tobytes()
        fh.write(evt_codec.neutral_lead(fmt, data) + data)
    return path


def raw_info(path: str | os.PathLike) -> evt_codec.RawHeader:
    """The header of a `.raw` file (format, sensor size, header bytes, `% t0`)."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    try:
        return evt_codec.parse_raw_header(head, str(path))
    except evt_codec.EvtFormatError as exc:
        raise FormatError(str(exc)) from None


@contextlib.contextmanager
def _plain_header(path: Path, info: evt_codec.RawHeader):
    """`path`, or a copy a decoder reads right when it is not: the header closed by `% end` (faery writes
    none), and a neutral word first when the first word's first byte is '%' (which expelliarmus takes
    for a header line, even after `% end`, and then hangs or drops events)."""
    with open(path, "rb") as src:
        src.seek(info.offset)
        first = src.read(1)
        if info.has_end and first != b"%":
            yield path
            return
        with tempfile.TemporaryDirectory() as tmp:
            copy = Path(tmp) / "events.raw"
            src.seek(0)
            with open(copy, "wb") as dst:
                dst.write(src.read(info.offset) + (b"" if info.has_end else b"% end\n"))
                dst.write(evt_codec.neutral_lead(info.fmt, first))
                shutil.copyfileobj(src, dst)
            yield copy


def read_raw(path: str | os.PathLike) -> EventStream:
    """A `.raw` EVT 3.0 file (decoded by `evt3`) or EVT 2.0 file (decoded by `expelliarmus`); times
    absolute (the header's `% t0` added)."""
    path = Path(path)
    info = raw_info(path)
    fmt, width, height = info.fmt, info.width, info.height
    size = path.stat().st_size - info.offset
    word = 2 if fmt == "evt3" else 4
    if size % word:
        raise FormatError(f"{path}: {size} bytes of {fmt.upper()} words is not a whole number of {word}-byte words "
                          "(a truncated file?)")
    if size == 0:                 # a header-only file: an empty stream (decoders return None for it)
        return checked_stream(path, [], [], [], [], width, height)
    if fmt == "evt3":
        with open(path, "rb") as fh:
            fh.seek(info.offset)
            ev = vendor_module("evt3", "evt3").decode_bytes(fh.read(), width, height)
        return checked_stream(path, np.asarray(ev.t, np.int64) + info.t0_us, ev.x, ev.y,
                              np.where(np.asarray(ev.p) > 0, 1, -1), width, height)
    wizard = vendor_module("expelliarmus", "expelliarmus").Wizard(encoding="evt2")
    with _plain_header(path, info) as whole, _named(whole, ".raw") as named:   # expelliarmus reads only .raw names
        arr = wizard.read(str(named))
    if arr is None:
        arr = {k: np.empty(0, np.int64) for k in "txyp"}
    return checked_stream(path, np.asarray(arr["t"], np.int64) + info.t0_us, arr["x"], arr["y"],
                          np.where(arr["p"] > 0, 1, -1), width, height)


# -- iniVation AEDAT4 --------------------------------------------------------------------------------
AEDAT4_CAMERA = "e4dgs_simulated"


def write_aedat4(path: str | os.PathLike, stream: EventStream, camera_name: str = AEDAT4_CAMERA) -> Path:
    """`stream` as an AEDAT4 file (one event stream `events`, written by dv-processing)."""
    dv = vendor_module("dv_processing", "dv-processing")
    path = Path(path)
    require_free_space(path, 16 * len(stream) + 4096)    # dv-processing aborts the process on a full disk
    store = dv.EventStore()
    ev = stream.events
    push = store.push_back
    for t, x, y, p in zip(ev["t"].tolist(), ev["x"].tolist(), ev["y"].tolist(), (ev["p"] > 0).tolist()):
        push(t, x, y, p)
    with atomic_output(path) as tmp:
        # dv-processing aborts the process (C++ terminate) on a name not ending in .aedat4
        named = Path(f"{tmp}.aedat4")
        try:
            writer = dv.io.MonoCameraWriter(str(named), dv.io.MonoCameraWriter.EventOnlyConfig(
                camera_name, (stream.width, stream.height)))
            if len(ev):
                writer.writeEvents(store)
            del writer                   # closes the file (dv-processing writes on its own thread)
            os.replace(named, tmp)
        finally:
            named.unlink(missing_ok=True)
    return path


def read_aedat4(path: str | os.PathLike, stream_name: str | None = None) -> EventStream:
    """The event stream of an AEDAT4 file (dv-processing); a file with several asks for `stream_name`."""
    dv = vendor_module("dv_processing", "dv-processing")
    path = Path(path)
    with _named(path, ".aedat4") as named:    # dv-processing reads only names ending in .aedat4
        try:
            rec = dv.io.MonoCameraRecording(str(named))
        except RuntimeError as exc:
            raise FormatError(f"{path}: not a readable AEDAT4 file ({_library_message(exc)})") from None
        return _read_recording(path, rec, stream_name)


def _read_recording(path: Path, rec, stream_name: str | None) -> EventStream:
    names = [n for n in rec.getStreamNames() if rec.isStreamOfEventType(n)]
    if not names:
        raise FormatError(f"{path}: the file holds no event stream (streams: {', '.join(rec.getStreamNames()) or 'none'})")
    if stream_name is None and len(names) > 1:
        raise FormatError(f"{path}: several event streams ({', '.join(names)}); choose one with --stream")
    name = stream_name or names[0]
    if name not in names:
        raise FormatError(f"{path}: no event stream {name!r} (it has {', '.join(names)})")
    resolution = rec.getEventResolution(name)
    if resolution is None:
        raise FormatError(f"{path}: event stream {name!r} declares no sensor size")
    parts = []
    while True:
        batch = rec.getNextEventBatch(name)
        if batch is None:
            break
        parts.append(batch.numpy())
    arr = np.concatenate(parts) if parts else np.empty(0, [("timestamp", "<i8"), ("x", "<i2"), ("y", "<i2"),
                                                            ("polarity", "i1")])
    return checked_stream(path, arr["timestamp"], arr["x"], arr["y"], np.where(arr["polarity"] > 0, 1, -1),
                    int(resolution[0]), int(resolution[1]))
