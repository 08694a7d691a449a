"""Event streams in ROS bags (ROS1 `.bag` or a ROS2 bag folder), written and read with `rosbags`.

Events travel as `dvs_msgs/EventArray` (the message of rpg_dvs_ros, ESIM and the rpg tools: a header,
the sensor's height and width, and Event[] {uint16 x, uint16 y, time ts, bool polarity}), one message
per `message_us` of events, stamped with the time of its last event. Topics follow ESIM's bags:

    /cam{k}/events        dvs_msgs/EventArray     (every camera of a scene)
    /cam{k}/camera_info   sensor_msgs/CameraInfo  (scene export: intrinsics K, plumb-bob, no distortion)
    /cam{k}/pose          geometry_msgs/PoseStamped (scene export: camera-to-world pose at each frame)
    /cam{k}/image_raw     sensor_msgs/Image       (scene export: the sharp frames, rgb8)

Bag times are the event times (microseconds -> nanoseconds); ROS stamps are unsigned, so a stream
with negative timestamps is refused. Reading takes every EventArray message of one topic (a bag with
several asks which).
"""
from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from common.fileio import as_disk_error, atomic_output, require_free_space
from eventio import ros_messages
from eventio.events import EventStream
from eventio.vendor_formats import FormatError, checked_stream, vendor_module

EVENT_MSG = "uint16 x\nuint16 y\ntime ts\nbool polarity\n"
EVENT_ARRAY_MSG = "std_msgs/Header header\nuint32 height\nuint32 width\ndvs_msgs/Event[] events\n"
EVENT_ARRAY = "dvs_msgs/msg/EventArray"


def typestore(ros2: bool):
    """rosbags' type store of ROS1 Noetic or ROS2 Humble with the dvs_msgs types registered."""
    typesys = vendor_module("rosbags.typesys", "rosbags")
    store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE if ros2 else typesys.Stores.ROS1_NOETIC)
    types = {}
    types.update(typesys.get_types_from_msg(EVENT_MSG, "dvs_msgs/msg/Event"))
    types.update(typesys.get_types_from_msg(EVENT_ARRAY_MSG, EVENT_ARRAY))
    store.register(types)
    return store


def ros_time(store, t_us: int):
    """builtin_interfaces/Time of a time in microseconds (extra topics' stamps)."""
    Time = store.types["builtin_interfaces/msg/Time"]
    return Time(sec=int(t_us // 1_000_000), nanosec=int(t_us % 1_000_000) * 1000)


def event_messages(stream: EventStream, frame_id: str, message_us: int, ros2: bool):
    """(bag time ns, serialized EventArray) per `message_us` window of the stream (empty windows skipped;
    each stamped with its last event's time)."""
    ev = stream.events
    encode = ros_messages.event_array_cdr if ros2 else ros_messages.event_array_ros1
    if not len(ev):          # one empty message, so that the bag still says the sensor size
        yield 0, encode(0, frame_id, stream.width, stream.height, ev["t"], ev["x"], ev["y"], ev["p"])
        return
    t = ev["t"]
    bins = (t - t[0]) // message_us
    cuts = np.flatnonzero(np.diff(bins)) + 1
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(ev)]):
        part = ev[lo:hi]
        stamp = int(part["t"][-1])
        yield stamp * 1000, encode(stamp, frame_id, stream.width, stream.height, part["t"], part["x"], part["y"],
                                   part["p"])


def write_bag(path: str | os.PathLike, streams: dict[str, EventStream], ros2: bool = False, message_us: int = 1000,
              extra=None) -> Path:
    """Event streams {topic: stream} into a ROS1 bag file (ros2: a ROS2 bag folder); `extra(writer, store,
    serialize)` may add other topics. Written under a temporary name, renamed when complete."""
    path = Path(path)
    for topic, s in streams.items():
        if len(s) and int(s.events["t"][0]) < 0:
            raise FormatError(f"{path}: {topic}: negative timestamps (ROS times are unsigned: shift the stream)")
    if ros2 and path.exists():
        raise FormatError(f"{path}: exists (a ROS2 bag is a folder; choose a new name)")
    store = typestore(ros2)
    require_free_space(path, sum(24 * len(s) + 4096 for s in streams.values()))
    rosbag = vendor_module("rosbags.rosbag2" if ros2 else "rosbags.rosbag1", "rosbags")
    with atomic_output(path) as tmp:     # a ROS2 bag is a folder: written whole under the temporary name
        if not ros2:
            with rosbag.Writer(tmp) as writer:
                _write_all(writer, store, streams, message_us, ros2, extra)
            return path
        # the writer names its database after the folder: write it as <tmp>/<name>, then lift its files
        # into <tmp>, so that the bag's files carry the final name (`<name>.db3`), not the temporary one
        inner = tmp / path.name
        tmp.mkdir()
        try:
            with rosbag.Writer(inner, version=8) as writer:
                _write_all(writer, store, streams, message_us, ros2, extra)
        except Exception as exc:       # sqlite's 'database or disk is full' and its kin
            disk = as_disk_error(exc, path)
            if disk is None:
                raise
            raise disk from None
        for f in inner.iterdir():
            os.replace(f, tmp / f.name)
        inner.rmdir()
    return path


def _write_all(writer, store, streams, message_us, ros2, extra):
    for topic, s in streams.items():
        conn = writer.add_connection(topic, EVENT_ARRAY, typestore=store)
        frame = topic.strip("/").split("/")[0] or "cam"
        for t_ns, raw in event_messages(s, frame, message_us, ros2):
            writer.write(conn, t_ns, raw)
    if extra is not None:
        extra(writer, store, store.serialize_cdr if ros2 else store.serialize_ros1)


def bag_topics(path: str | os.PathLike) -> dict[str, str]:
    """{topic: message type} of a ROS1 bag file or ROS2 bag folder."""
    with _open(Path(path)) as reader:
        return {c.topic: c.msgtype for c in reader.connections}


def _open(path: Path):
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    if path.is_dir():
        return vendor_module("rosbags.rosbag2", "rosbags").Reader(path)
    return vendor_module("rosbags.rosbag1", "rosbags").Reader(path)


def read_bag(path: str | os.PathLike, topic: str | None = None) -> EventStream:
    """The events of one dvs_msgs/EventArray topic of a bag (several topics: name one)."""
    path = Path(path)
    ros2 = path.is_dir()
    parse = ros_messages.parse_event_array_cdr if ros2 else ros_messages.parse_event_array_ros1
    try:
        reader = _open(path)
        reader.open()
    except FileNotFoundError:
        raise
    except Exception as exc:        # rosbags raises its own ReaderError for a damaged or foreign file
        raise FormatError(f"{path}: not a readable ROS bag ({' '.join(str(exc).split())})") from None
    try:
        topics = sorted({c.topic for c in reader.connections if c.msgtype.split("/")[-1] == "EventArray"})
        if not topics:
            raise FormatError(f"{path}: no dvs_msgs/EventArray topic (topics: "
                              f"{', '.join(sorted({c.topic for c in reader.connections})) or 'none'})")
        if topic is None and len(topics) > 1:
            raise FormatError(f"{path}: several event topics ({', '.join(topics)}); choose one with --topic")
        topic = topic or topics[0]
        if topic not in topics:
            raise FormatError(f"{path}: no event topic {topic!r} (it has {', '.join(topics)})")
        conns = [c for c in reader.connections if c.topic == topic]
        cols = {k: [] for k in "txyp"}
        size = None
        for conn, _, raw in reader.messages(connections=conns):
            try:
                width, height, *columns = parse(bytes(raw))
            except (ValueError, struct.error) as exc:
                raise FormatError(f"{path}: {topic}: a message that is not a dvs_msgs/EventArray ({exc})") from None
            size = size or (width, height)
            for k, col in zip("txyp", columns):
                cols[k].append(col)
    finally:
        reader.close()
    if size is None or size[0] <= 0 or size[1] <= 0:
        raise FormatError(f"{path}: topic {topic} has no message with a sensor size (width, height)")
    cat = {k: np.concatenate(v) if v else np.empty(0, np.int64) for k, v in cols.items()}
    return checked_stream(path, cat["t"], cat["x"], cat["y"], cat["p"], size[0], size[1])
