"""Event files in the vendors' formats: our EVT encoders against their readable references and against
independent decoders (evt3, expelliarmus), AEDAT4 through dv-processing, ROS bags through rosbags
(our NumPy message serialization byte for byte against rosbags' own), files the vendors' libraries
wrote themselves, scene export, the CLI, and bad input."""
import struct

import numpy as np
import pytest

from e4dgs.cli import main
from eventio import evt_codec, formats, ros_messages, rosbag_io, vendor_formats
from eventio.events import EventStream, make_events
from eventio.h5io import read_events, write_events
from eventio.vendor_formats import FormatError

EVT3_TYPES = {0x0: "ADDR_Y", 0x2: "ADDR_X", 0x3: "VECT_BASE_X", 0x4: "VECT_12", 0x5: "VECT_8", 0x6: "TIME_LOW",
              0x8: "TIME_HIGH"}


def demanding_stream(n: int = 6000, seed: int = 0) -> EventStream:
    """Random events over 60 s (three 24-bit wraps, and a 20 s gap), plus a burst of 40 events on one
    row at one time (vectors), a pixel firing twice at one time, and a burst of 5 columns (VECT_8)."""
    rng = np.random.default_rng(seed)
    t = np.sort(np.r_[rng.integers(0, 20_000_000, n // 2), rng.integers(40_000_000, 60_000_000, n - n // 2)])
    x, y, p = rng.integers(0, 346, n), rng.integers(0, 260, n), rng.choice([-1, 1], n)
    burst = slice(100, 140)
    t[burst], y[burst], p[burst], x[burst] = t[100], 7, 1, np.arange(40) * 1 + 20
    x[120] = x[119]                      # a repeat inside the burst
    small = slice(300, 305)
    t[small], y[small], p[small], x[small] = t[300], 9, -1, [50, 51, 53, 54, 56]
    return EventStream(make_events(t, x, y, p), 346, 260)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_fast_encoders_write_the_references_words(seed):
    s = demanding_stream(seed=seed)
    e = s.events
    for ref, fast in ((evt_codec.encode_evt2_ref, evt_codec.encode_evt2), (evt_codec.encode_evt3_ref, evt_codec.encode_evt3)):
        a, b = ref(e["t"], e["x"], e["y"], e["p"]), fast(e["t"], e["x"], e["y"], e["p"])
        assert a.dtype == b.dtype and np.array_equal(a, b)
    words = evt_codec.encode_evt3(e["t"], e["x"], e["y"], e["p"])
    used = {EVT3_TYPES[int(w) >> 12] for w in np.unique(words >> 12 << 12)}
    assert used == set(EVT3_TYPES.values())        # every word type the encoder can emit is exercised


def test_evt2_words_by_hand():
    # one event at t = 100 us (high 1, low 36), x 5, y 3, ON; then t = 101 (same high), OFF
    words = evt_codec.encode_evt2([100, 101], [5, 6], [3, 4], [1, -1])
    assert words.tolist() == [(0x8 << 28) | 1, (0x1 << 28) | (36 << 22) | (5 << 11) | 3, (0x0 << 28) | (37 << 22) | (6 << 11) | 4]


def test_evt3_words_by_hand():
    # three events on row 2 at t = 4097 us, columns 10, 11, 13, ON: one VECT_8 after its base
    words = evt_codec.encode_evt3([4097] * 3, [10, 11, 13], [2] * 3, [1] * 3)
    assert words.tolist() == [(0x8 << 12) | 1, (0x6 << 12) | 1, (0x0 << 12) | 2, (0x3 << 12) | (1 << 11) | 10,
                              (0x5 << 12) | 0b1011]


@pytest.mark.parametrize("fmt", ["evt3", "evt2"])
def test_raw_files_decode_exactly_in_independent_decoders(fmt, tmp_path):
    s = demanding_stream()
    path = vendor_formats.write_raw(tmp_path / f"cam.{fmt}.raw", s, fmt)
    back = vendor_formats.read_raw(path)                       # evt3 / expelliarmus, not ours
    assert formats.same_events(s, back)
    assert vendor_formats.raw_info(path)[:3] == (fmt, 346, 260)
    head = path.read_bytes()[:400].decode("ascii", "replace")
    assert f"% format {fmt.upper()};height=260;width=346" in head and "% end" in head


def test_evt3_decoder_sees_our_order_exactly(tmp_path):
    import evt3
    s = demanding_stream()
    e = s.events
    path = vendor_formats.write_raw(tmp_path / "c.raw", s, "evt3")
    got = evt3.decode_file(str(path))
    o = evt_codec.evt3_order(e["t"], e["x"], e["y"], e["p"])
    assert np.array_equal(np.asarray(got.t, np.int64), e["t"][o]) and np.array_equal(got.x, e["x"][o])
    assert (got.sensor_width, got.sensor_height) == (346, 260)


@pytest.mark.parametrize("fmt", ["aedat4", "rosbag", "rosbag2", "npz", "h5", "evt3", "evt2"])
def test_every_format_round_trips(fmt, tmp_path):
    s = demanding_stream(n=3000)
    path = tmp_path / f"events{formats.SUFFIX[fmt]}"
    formats.write_stream(path, s, fmt)
    back, found = formats.read_recording(path)
    assert found == fmt and formats.same_events(s, back)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]       # no temporary left behind


@pytest.mark.parametrize("n", [0, 1, 2, 3, 57])
@pytest.mark.parametrize("ros2", [False, True])
def test_our_message_bytes_are_rosbags_bytes(n, ros2):
    store = rosbag_io.typestore(ros2)
    T = store.types
    rng = np.random.default_rng(n)
    t = np.sort(rng.integers(0, 5 * 10**7, n))
    x, y, p = rng.integers(0, 346, n), rng.integers(0, 260, n), rng.choice([-1, 1], n)
    events = [T["dvs_msgs/msg/Event"](x=int(a), y=int(b), ts=rosbag_io.ros_time(store, int(c)), polarity=bool(d > 0))
              for c, a, b, d in zip(t, x, y, p)]
    fields = {"stamp": rosbag_io.ros_time(store, 123_456_789), "frame_id": "cam3"}
    header = T["std_msgs/msg/Header"](**fields) if ros2 else T["std_msgs/msg/Header"](seq=0, **fields)
    msg = T[rosbag_io.EVENT_ARRAY](header=header, height=260, width=346, events=events)
    ref = bytes(store.serialize_cdr(msg, rosbag_io.EVENT_ARRAY) if ros2 else store.serialize_ros1(msg, rosbag_io.EVENT_ARRAY))
    encode = ros_messages.event_array_cdr if ros2 else ros_messages.event_array_ros1
    assert encode(123_456_789, "cam3", 346, 260, t, x, y, p) == ref
    parse = ros_messages.parse_event_array_cdr if ros2 else ros_messages.parse_event_array_ros1
    w, h, tt, xx, yy, pp = parse(ref)
    assert (w, h) == (346, 260) and np.array_equal(tt, t) and np.array_equal(xx, x) and np.array_equal(pp, p)


def test_import_reads_what_the_vendors_own_writers_wrote(tmp_path):
    """An AEDAT4 file written by dv-processing and a ROS1 bag written by rosbags (its own message
    objects), neither through our writers, come in as the events they were given."""
    import dv_processing as dv
    from rosbags.rosbag1 import Writer

    s = demanding_stream(n=500)
    e = s.events
    store_dv = dv.EventStore()
    for t, x, y, p in zip(e["t"].tolist(), e["x"].tolist(), e["y"].tolist(), (e["p"] > 0).tolist()):
        store_dv.push_back(t, x, y, p)
    writer = dv.io.MonoCameraWriter(str(tmp_path / "dv.aedat4"), dv.io.MonoCameraWriter.EventOnlyConfig("DVXplorer", (346, 260)))
    writer.writeEvents(store_dv)
    del writer
    store = rosbag_io.typestore(False)
    T = store.types
    with Writer(tmp_path / "ros.bag") as w:
        conn = w.add_connection("/dvs/events", rosbag_io.EVENT_ARRAY, typestore=store)
        for lo in range(0, len(e), 100):
            part = e[lo:lo + 100]
            msg = T[rosbag_io.EVENT_ARRAY](
                header=T["std_msgs/msg/Header"](seq=lo, stamp=rosbag_io.ros_time(store, int(part["t"][-1])), frame_id="dvs"),
                height=260, width=346,
                events=[T["dvs_msgs/msg/Event"](x=int(x), y=int(y), ts=rosbag_io.ros_time(store, int(t)), polarity=bool(p > 0))
                        for t, x, y, p in part])
            w.write(conn, int(part["t"][-1]) * 1000, store.serialize_ros1(msg, rosbag_io.EVENT_ARRAY))
    for name in ("dv.aedat4", "ros.bag"):
        assert main(["import", str(tmp_path / name), "--out", str(tmp_path / f"{name}.h5")]) == 0
        assert formats.same_events(s, read_events(tmp_path / f"{name}.h5")), name


def test_scene_export_and_the_cli(motion_scene, tmp_path, capsys):
    from rosbags.rosbag1 import Reader

    bag = tmp_path / "scene.bag"
    assert main(["export", str(motion_scene), "--format", "rosbag", "--out", str(bag)]) == 0
    topics = rosbag_io.bag_topics(bag)
    for k in range(2):
        assert topics[f"/cam{k}/events"] == rosbag_io.EVENT_ARRAY
        assert topics[f"/cam{k}/camera_info"] == "sensor_msgs/msg/CameraInfo"
        assert topics[f"/cam{k}/pose"] == "geometry_msgs/msg/PoseStamped"
        assert topics[f"/cam{k}/image_raw"] == "sensor_msgs/msg/Image"
    store = rosbag_io.typestore(False)
    with Reader(bag) as r:
        conn = [c for c in r.connections if c.topic == "/cam1/camera_info"]
        info = store.deserialize_ros1(next(r.messages(connections=conn))[2], "sensor_msgs/msg/CameraInfo")
    assert (info.width, info.height) == (64, 48) and info.K[8] == 1.0
    for k in range(2):
        assert main(["import", str(bag), "--topic", f"/cam{k}/events", "--out", str(tmp_path / f"b{k}.h5")]) == 0
        assert formats.same_events(read_events(motion_scene / "events" / f"cam{k}.h5"), read_events(tmp_path / f"b{k}.h5"))
    with pytest.raises(SystemExit, match="several event topics"):
        main(["import", str(bag), "--out", str(tmp_path / "x.h5")])
    assert main(["export", str(motion_scene), "--format", "evt3", "--out", str(tmp_path / "raw")]) == 0
    assert sorted(p.name for p in (tmp_path / "raw").iterdir()) == ["cam0.raw", "cam1.raw"]
    assert main(["import", str(tmp_path / "raw" / "cam1.raw"), "--out", str(tmp_path / "r1.h5")]) == 0
    assert formats.same_events(read_events(motion_scene / "events" / "cam1.h5"), read_events(tmp_path / "r1.h5"))
    assert main(["check", str(tmp_path / "r1.h5")]) == 0
    assert "OK (" in capsys.readouterr().out


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


def test_bad_recordings_get_one_line_and_leave_nothing(tmp_path):
    s = demanding_stream(n=400)
    good = vendor_formats.write_raw(tmp_path / "good.raw", s, "evt3")
    data = good.read_bytes()
    cases = {
        "cut.raw": (data[:-1], "whole number"),
        "magic.bin": (b"GIF89a" + data[:100], "not a recognised event file"),
        "huge.raw": (data.replace(b"width=346", b"width=5000", 1), "outside 1..2048"),
        "nohead.raw": (b"% hello world\n% end\n" + data[-64:], "names no EVT"),
        "small.raw": (data.replace(b"width=346", b"width=20", 1).replace(b"geometry 346x", b"geometry 20x", 1),
                      "outside the sensor"),
        "broken.aedat4": (b"#!AER-DAT4.0\r\n" + b"\x00" * 50, "AEDAT4"),
        "broken.bag": (b"#ROSBAG V2.0\n" + b"\x01" * 50, "ROS bag"),
        "words.txt": (b"hello world\nnot events\n", "words.txt: first line must be 'width height'"),
        "value.txt": (b"346 260\n0.000001 1 2 1\n0.000002 x 2 1\n", "value.txt: line 3: x = 'x'"),
        "outside.txt": (b"10 10\n0.000001 50 2 1\n", "outside.txt: line 2: x = 50 outside the sensor"),
        "columns.txt": (b"10 10\n0.000001 5 2\n", "columns.txt: expected 4 columns"),
    }
    for name, (content, match) in cases.items():
        path = _write(tmp_path / name, content)
        with pytest.raises(SystemExit, match=match):
            main(["import", str(path), "--out", str(tmp_path / f"{name}.h5")])
        assert not (tmp_path / f"{name}.h5").exists(), name
    bag = rosbag_io.write_bag(tmp_path / "empty.bag", {})        # a bag without event topics
    with pytest.raises(SystemExit, match="no dvs_msgs/EventArray topic"):
        main(["import", str(bag), "--out", str(tmp_path / "e.h5")])
    negative = EventStream(make_events([-5, 3], [1, 2], [1, 2], [1, -1]), 10, 10)
    write_events(tmp_path / "neg.h5", negative, t_offset_us=-5)
    for fmt in ("evt3", "evt2", "rosbag"):
        with pytest.raises(SystemExit, match="negative"):
            main(["export", str(tmp_path / "neg.h5"), "--format", fmt, "--out", str(tmp_path / f"neg{formats.SUFFIX[fmt]}")])
        assert not (tmp_path / f"neg{formats.SUFFIX[fmt]}").exists()
    big = EventStream(make_events([0], [3000], [1], [1]), 4000, 10)
    with pytest.raises(FormatError, match="at most 2048"):
        vendor_formats.write_raw(tmp_path / "big.raw", big, "evt3")
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_header_parsing():
    head = evt_codec.raw_header("evt2", 640, 480)
    assert evt_codec.parse_raw_header(head + b"\x00\x00\x00\x00") == ("evt2", 640, 480, len(head), 0, True)
    # a Metavision-style header with only the geometry and evt lines
    other = b"% evt 3.0\n% geometry 1280x720\n% serial_number 00ca\n% end\n"
    assert evt_codec.parse_raw_header(other)[:3] == ("evt3", 1280, 720)
    with pytest.raises(evt_codec.EvtFormatError, match="not a text line ending in a line break"):
        evt_codec.parse_raw_header(b"% evt 3.0")
    assert struct.calcsize("<I") == 4


@pytest.mark.parametrize("fmt", [f for f in formats.FORMATS if f != "rosbag2"])
def test_export_refuses_a_name_of_another_format_or_a_folder(fmt, tmp_path):
    """EVT 3.0 bytes under an .h5 name, or a file export into a folder, are refused before writing."""
    src = tmp_path / "src.h5"
    write_events(src, EventStream(make_events([1, 3], [1, 2], [1, 2], [1, -1]), 10, 10))
    wrong = ".h5" if fmt != "h5" else ".raw"
    with pytest.raises(SystemExit, match=f"--format {fmt} writes a \\{formats.SUFFIX[fmt]} file"):
        main(["export", str(src), "--format", fmt, "--out", str(tmp_path / f"x{wrong}")])
    (tmp_path / "adir").mkdir()
    with pytest.raises(SystemExit, match="is a folder"):
        main(["export", str(src), "--format", fmt, "--out", str(tmp_path / "adir")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir", "src.h5"]
    assert list((tmp_path / "adir").iterdir()) == []
