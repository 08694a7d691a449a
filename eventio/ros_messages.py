"""dvs_msgs/EventArray serialized with NumPy: the fast twins of `rosbags`' message (de)serialization
(a Python object per event: ~25 us an event), checked byte for byte against it in the tests.

ROS1 (little-endian, packed):
    header: uint32 seq, uint32 sec, uint32 nsec, uint32 len + frame_id bytes
    uint32 height, uint32 width, uint32 count, then count x 13 bytes {u16 x, u16 y, u32 sec, u32 nsec, u8 polarity}
ROS2 (CDR little-endian: a 4-byte encapsulation header, then each field aligned to its size,
counted from after that header):
    header: int32 sec, uint32 nanosec, uint32 len (with the NUL) + frame_id + NUL; align 4
    uint32 height, uint32 width, uint32 count; events: the first at offset o (o % 4 == 0) takes
    13 bytes {x, y, sec, nanosec, polarity}; every later one starts 2 bytes after a multiple of 4 and
    takes 16: {u16 x, u16 y, 2 padding, i32 sec, u32 nanosec, u8 polarity} (x needs 2-byte alignment,
    sec 4-byte).
Event times are microseconds (ROS keeps nanoseconds: the last three digits are zero).
"""
from __future__ import annotations

import struct

import numpy as np

ROS1_EVENT = np.dtype([("x", "<u2"), ("y", "<u2"), ("sec", "<u4"), ("nsec", "<u4"), ("p", "u1")])      # 13 bytes
CDR_LATER_EVENT = np.dtype({"names": ["x", "y", "sec", "nsec", "p"], "formats": ["<u2", "<u2", "<i4", "<u4", "u1"],
                            "offsets": [0, 2, 6, 10, 14], "itemsize": 16})
CDR_HEADER = b"\x00\x01\x00\x00"


def _fill(rec: np.ndarray, t_us, x, y, p) -> None:
    t = np.asarray(t_us, np.int64)
    rec["x"], rec["y"] = x, y
    rec["sec"], rec["nsec"] = t // 1_000_000, (t % 1_000_000) * 1000
    rec["p"] = np.asarray(p) > 0


def event_array_ros1(stamp_us: int, frame_id: str, width: int, height: int, t_us, x, y, p, seq: int = 0) -> bytes:
    """A dvs_msgs/EventArray message in ROS1 serialization (events t_us, x, y, p [N], p in {-1, +1})."""
    fid = frame_id.encode()
    head = struct.pack("<III", seq, stamp_us // 1_000_000, (stamp_us % 1_000_000) * 1000)
    head += struct.pack("<I", len(fid)) + fid + struct.pack("<III", height, width, len(t_us))
    rec = np.empty(len(t_us), ROS1_EVENT)
    _fill(rec, t_us, x, y, p)
    return head + rec.tobytes()


def parse_event_array_ros1(raw: bytes) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(width, height, t_us, x, y, p) of a ROS1-serialized dvs_msgs/EventArray."""
    (n_fid,) = struct.unpack_from("<I", raw, 12)
    off = 16 + n_fid
    height, width, count = struct.unpack_from("<III", raw, off)
    rec = np.frombuffer(raw, ROS1_EVENT, count, off + 12)
    return width, height, *_columns(rec)


def _columns(rec: np.ndarray):
    t = rec["sec"].astype(np.int64) * 1_000_000 + rec["nsec"].astype(np.int64) // 1000
    return t, rec["x"].astype(np.int64), rec["y"].astype(np.int64), np.where(rec["p"] > 0, 1, -1).astype(np.int8)


def _align(n: int, a: int) -> int:
    return (n + a - 1) // a * a


def event_array_cdr(stamp_us: int, frame_id: str, width: int, height: int, t_us, x, y, p) -> bytes:
    """A dvs_msgs/EventArray message in ROS2 CDR (little-endian) serialization."""
    fid = frame_id.encode() + b"\x00"
    body = bytearray(struct.pack("<iII", stamp_us // 1_000_000, (stamp_us % 1_000_000) * 1000, len(fid)) + fid)
    body += b"\x00" * (_align(len(body), 4) - len(body))
    body += struct.pack("<III", height, width, len(t_us))
    n = len(t_us)
    if n:
        first = np.empty(1, ROS1_EVENT)          # the first event has the packed ROS1 layout (13 bytes)
        _fill(first, t_us[:1], x[:1], y[:1], p[:1])
        body += first.tobytes()
        if n > 1:
            later = np.zeros(n - 1, CDR_LATER_EVENT)
            _fill(later, t_us[1:], x[1:], y[1:], p[1:])
            body += b"\x00" + later.tobytes()[:-1]     # pad to the 2-byte boundary; no padding after the last
    return CDR_HEADER + bytes(body)


def parse_event_array_cdr(raw: bytes) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(width, height, t_us, x, y, p) of a CDR-serialized dvs_msgs/EventArray."""
    if raw[:2] != b"\x00\x01":
        raise ValueError("not little-endian CDR (encapsulation header 00 01)")
    body = memoryview(raw)[4:]
    (n_fid,) = struct.unpack_from("<I", body, 8)
    off = _align(12 + n_fid, 4)
    height, width, count = struct.unpack_from("<III", body, off)
    off += 12
    if count == 0:
        return width, height, *_columns(np.empty(0, ROS1_EVENT))
    first = np.frombuffer(body, ROS1_EVENT, 1, off)
    later = np.frombuffer(bytes(body[off + 14:]) + b"\x00", CDR_LATER_EVENT, count - 1) if count > 1 else \
        np.empty(0, CDR_LATER_EVENT)
    cols = [np.concatenate([a, b]) for a, b in zip(_columns(first), _columns(later))]
    return width, height, *cols
