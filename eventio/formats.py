"""One event stream in or out of any supported format, and a scene's cameras out as a set of files or
one ROS bag (the I/O under `e4dgs export` and `e4dgs import`).

| format   | file                     | written by                  | read by                 |
|----------|--------------------------|-----------------------------|-------------------------|
| h5       | .h5 (ours, DSEC layout)  | eventio.h5io              | eventio.h5io          |
| aedat4   | .aedat4 (iniVation DV)   | dv-processing               | dv-processing           |
| evt3     | .raw (Prophesee EVT 3.0) | eventio.evt_codec         | evt3                    |
| evt2     | .raw (Prophesee EVT 2.0) | eventio.evt_codec         | expelliarmus            |
| rosbag   | .bag (ROS1)              | rosbags (+ ros_messages)    | rosbags (+ ros_messages)|
| rosbag2  | folder (ROS2, sqlite3)   | rosbags (+ ros_messages)    | rosbags (+ ros_messages)|
| npz      | .npz                     | NumPy                       | NumPy                   |
| txt      | .txt (E2VID text)        | eventio.export            | eventio.export        |
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from eventio import export, h5io, rosbag_io, vendor_formats
from eventio.events import EventStream
from eventio.vendor_formats import FormatError

FORMATS = ("h5", "aedat4", "evt3", "evt2", "rosbag", "rosbag2", "npz", "txt")
SUFFIX = {"h5": ".h5", "aedat4": ".aedat4", "evt3": ".raw", "evt2": ".raw", "rosbag": ".bag", "rosbag2": "",
          "npz": ".npz", "txt": ".txt"}


def write_stream(path: str | os.PathLike, stream: EventStream, fmt: str, topic: str = "/cam0/events",
                 message_us: int = 1000) -> Path:
    """One stream as a file of format `fmt` (see FORMATS). Every format refuses, before writing, a
    stream its readers would refuse (EventValidationError: unsorted times, x or y outside the sensor,
    polarity not +-1)."""
    path = Path(path)
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")
    stream.validate()
    if fmt == "h5":
        return h5io.write_events(path, stream)
    if fmt == "aedat4":
        return vendor_formats.write_aedat4(path, stream)
    if fmt in ("evt3", "evt2"):
        return vendor_formats.write_raw(path, stream, fmt)
    if fmt in ("rosbag", "rosbag2"):
        return rosbag_io.write_bag(path, {topic: stream}, ros2=fmt == "rosbag2", message_us=message_us)
    if fmt == "npz":
        return export.write_npz(path, stream)
    if fmt == "txt":
        return export.write_e2vid_txt(path, stream)
    raise ValueError(f"unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")


def detect_format(path: str | os.PathLike) -> str:
    """The format of a recording, from its name and first bytes."""
    path = Path(path)
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return "rosbag2"
        raise FormatError(f"{path}: a folder that is not a ROS2 bag (no metadata.yaml)")
    with open(path, "rb") as fh:
        head = fh.read(16)
    if head.startswith(b"\x89HDF"):
        return "h5"
    if head.startswith(b"#!AER-DAT4"):
        return "aedat4"
    if head.startswith(b"#ROSBAG V2.0"):
        return "rosbag"
    if head.startswith(b"PK"):
        return "npz"
    if head.startswith(b"%"):
        return vendor_formats.raw_info(path).fmt
    if path.suffix == ".txt":
        return "txt"
    raise FormatError(f"{path}: not a recognised event file (HDF5, AEDAT4, Prophesee .raw EVT 2.0 / 3.0, ROS bag, "
                      f".npz or E2VID .txt); its first bytes are {head[:12]!r}")


def read_recording(path: str | os.PathLike, topic: str | None = None, stream: str | None = None) -> tuple[EventStream, str]:
    """(events, format) of a recording in any supported format; `topic` / `stream` pick one of several
    event topics of a bag / event streams of an AEDAT4 file."""
    path = Path(path)
    fmt = detect_format(path)
    if fmt == "h5":
        return h5io.read_events(path), fmt
    if fmt == "aedat4":
        return vendor_formats.read_aedat4(path, stream), fmt
    if fmt in ("evt3", "evt2"):
        return vendor_formats.read_raw(path), fmt
    if fmt in ("rosbag", "rosbag2"):
        return rosbag_io.read_bag(path, topic), fmt
    if fmt == "npz":
        try:
            return export.read_npz(path), fmt
        except KeyError as exc:
            raise FormatError(f"{path}: an .npz without the event arrays t, x, y, p, width, height ({exc})") from None
    return export.read_e2vid_txt(path), fmt


def same_events(a: EventStream, b: EventStream) -> bool:
    """Equal sensors and the same events at each timestamp (order within one timestamp free)."""
    if (a.width, a.height) != (b.width, b.height) or len(a) != len(b):
        return False
    ka = np.lexsort((a.events["p"], a.events["x"], a.events["y"], a.events["t"]))
    kb = np.lexsort((b.events["p"], b.events["x"], b.events["y"], b.events["t"]))
    return bool(np.array_equal(a.events[ka], b.events[kb]))
