"""Recordings as cameras write them: times in Unix-epoch microseconds, the peers' conventions (faery's
`% t0` and missing `% end`, rpg_e2vid's 12-decimal seconds), empty streams, and inputs that used to be
read wrong without a word (float-second npz times, polarity 5)."""
import numpy as np
import pytest

from e4dgs.cli import main
from eventio import evt_codec, formats, vendor_formats
from eventio.event_file import EventFile
from eventio.events import EventStream, make_events
from eventio.export import read_e2vid_txt, read_npz
from eventio.h5io import read_events, write_events

EPOCH_US = 1_700_000_000_123_456          # 2023-11-14, as DV stamps an AEDAT4 file


def epoch_stream(n: int = 3000, seed: int = 0, start_us: int = EPOCH_US) -> EventStream:
    rng = np.random.default_rng(seed)
    t = start_us + np.sort(rng.integers(0, 2_000_000, n))
    return EventStream(make_events(t, rng.integers(0, 346, n), rng.integers(0, 260, n), rng.choice([-1, 1], n)), 346, 260)


@pytest.mark.parametrize("fmt", [f for f in formats.FORMATS])
def test_an_epoch_stamped_stream_round_trips_every_format_and_the_import_command(fmt, tmp_path, capsys):
    s = epoch_stream()
    src = formats.write_stream(tmp_path / f"rec{formats.SUFFIX[fmt]}", s, fmt)
    assert formats.same_events(formats.read_recording(src)[0], s)
    assert main(["import", str(src), "--out", str(tmp_path / "imported.h5")]) == 0
    back = read_events(tmp_path / "imported.h5")
    assert formats.same_events(back, s)                     # absolute times kept, exactly
    with EventFile(tmp_path / "imported.h5") as ev:
        assert ev.t_offset_us == EPOCH_US // 1000 * 1000      # DSEC's t_offset: the first millisecond
        assert ev.indices(EPOCH_US + 500_000, EPOCH_US + 600_000) == tuple(
            np.searchsorted(s.events["t"], [EPOCH_US + 500_000, EPOCH_US + 600_000]))
    # and back out in the same format from the imported file
    assert main(["export", str(tmp_path / "imported.h5"), "--format", fmt,
                 "--out", str(tmp_path / f"again{formats.SUFFIX[fmt]}")]) == 0
    assert formats.same_events(formats.read_recording(tmp_path / f"again{formats.SUFFIX[fmt]}")[0], s)


def test_a_stream_near_zero_keeps_offset_zero_and_the_same_bytes(tmp_path):
    """The simulator's streams (starting in the first millisecond) are written as before: t_offset 0."""
    s = epoch_stream(start_us=250)
    with EventFile(write_events(tmp_path / "a.h5", s)) as ev:
        assert ev.t_offset_us == 0
    for fmt in ("evt3", "evt2"):
        path = vendor_formats.write_raw(tmp_path / f"a.{fmt}.raw", s, fmt)
        assert vendor_formats.raw_info(path).t0_us == 0 and b"% t0" not in path.read_bytes()[:400]


def test_epoch_events_reach_view_e2vid_and_check(tmp_path, capsys):
    s = epoch_stream()
    path = write_events(tmp_path / "rec.h5", s)
    assert main(["draw-events", str(path), "--out", str(tmp_path / "v.mp4"), "--window", "100ms"]) == 0
    assert "20 frames of 100000 us" in capsys.readouterr().out           # from the first event, not from 0
    assert main(["draw-events", str(path), "--out", str(tmp_path / "v.png")]) == 0
    assert f"3000 events in [{s.events['t'][0]}, {s.events['t'][-1] + 1}) us" in capsys.readouterr().out
    assert main(["check", str(path)]) == 0
    assert main(["e2vid", str(path), "--out", str(tmp_path / "frames")]) == 0
    stamps = [int(v) for v in (tmp_path / "frames" / "timestamps.txt").read_text().split()]
    assert len(stamps) == 30 and EPOCH_US < stamps[0] < stamps[-1] <= EPOCH_US + 2_000_000


def test_view_refuses_a_video_of_millions_of_frames_and_a_giant_picture(tmp_path, capsys):
    path = write_events(tmp_path / "rec.h5", epoch_stream())
    with pytest.raises(SystemExit, match="frames; at most 100000"):
        main(["draw-events", str(path), "--out", str(tmp_path / "v.mp4"), "--window", "1us"])
    with pytest.raises(SystemExit, match="at most 8192 a side"):
        main(["draw-events", str(path), "--out", str(tmp_path / "v.png"), "--scale", "1000000"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.h5"]


@pytest.mark.parametrize("fmt", ["evt3", "evt2"])
def test_faery_style_raw_files_honour_t0_and_have_no_end_line(fmt, tmp_path):
    """faery writes times from 0, the start in `% t0 <us>`, and no `% end`: a first word whose first
    byte is '%' (0x25) must stay data. EVT 2.0's first word is a TIME_HIGH whose low byte is t >> 6; EVT
    3.0's is a TIME_HIGH whose low byte is t >> 12."""
    t_first = 0x25 * 64 if fmt == "evt2" else 0x25 * 4096
    rel = EventStream(make_events([t_first, t_first + 7, t_first + 5000], [3, 4, 5], [1, 2, 3], [1, -1, 1]), 64, 48)
    words = (evt_codec.encode_evt2 if fmt == "evt2" else evt_codec.encode_evt3)(*(rel.events[k] for k in "txyp"))
    body = words.astype("<u4" if fmt == "evt2" else "<u2").tobytes()
    assert body[:1] == b"%"
    head = evt_codec.raw_header(fmt, 64, 48).replace(b"% end\n", f"% t0 {EPOCH_US}\n".encode())
    path = tmp_path / "faery.raw"
    path.write_bytes(head + body)
    info = vendor_formats.raw_info(path)
    assert (info.offset, info.t0_us, info.has_end) == (len(head), EPOCH_US, False)
    back = vendor_formats.read_raw(path)
    assert back.events["t"].tolist() == [EPOCH_US + t for t in rel.events["t"].tolist()]
    assert back.events["x"].tolist() == [3, 4, 5]
    # our writer puts a neutral word first rather than a first data byte '%', and its file reads the same
    ours = vendor_formats.write_raw(tmp_path / "ours.raw", rel, fmt)
    assert ours.read_bytes()[vendor_formats.raw_info(ours).offset:][:1] != b"%"
    assert formats.same_events(vendor_formats.read_raw(ours), rel)


@pytest.mark.parametrize("fmt", ["evt2", "evt3", "rosbag", "rosbag2", "aedat4", "npz", "txt", "h5"])
def test_an_empty_stream_exports_and_imports_back_with_its_sensor_size(fmt, tmp_path):
    empty = EventStream(make_events([], [], [], []), 346, 260)
    src = formats.write_stream(tmp_path / f"e{formats.SUFFIX[fmt]}", empty, fmt)
    assert main(["import", str(src), "--out", str(tmp_path / "back.h5")]) == 0
    back = read_events(tmp_path / "back.h5")
    assert (len(back), back.width, back.height) == (0, 346, 260)


def test_the_ros2_export_names_its_database_after_the_bag_and_is_reproducible(tmp_path):
    s = epoch_stream(300)
    a = formats.write_stream(tmp_path / "a" / "cam0", s, "rosbag2")
    b = formats.write_stream(tmp_path / "b" / "cam0", s, "rosbag2")
    assert sorted(p.name for p in a.iterdir()) == ["cam0.db3", "metadata.yaml"]
    assert "tmp" not in (a / "metadata.yaml").read_text()
    assert (a / "cam0.db3").read_bytes() == (b / "cam0.db3").read_bytes()


def test_rpg_e2vid_twelve_decimal_times_round_to_the_nearest_microsecond(tmp_path):
    path = tmp_path / "e2vid.txt"
    path.write_text("346 260\n17179.869182999999 1 2 1\n17179.869183400000 3 4 0\n17179.869183500000 5 6 1\n")
    s = read_e2vid_txt(path)
    assert s.events["t"].tolist() == [17_179_869_183, 17_179_869_183, 17_179_869_184]
    assert s.events["p"].tolist() == [1, -1, 1]


def test_inputs_once_read_wrong_are_refused_by_name(tmp_path):
    txt = tmp_path / "p5.txt"
    txt.write_text("346 260\n0.000001 1 2 5\n")
    with pytest.raises(ValueError, match=r"line 2: p = 5; expected 0 \(OFF\) or 1 \(ON\)"):
        read_e2vid_txt(txt)
    npz = tmp_path / "sec.npz"
    np.savez(npz, t=np.array([0.1, 0.2]), x=np.array([1, 2]), y=np.array([1, 2]), p=np.array([1, -1]),
             width=346, height=260)
    with pytest.raises(ValueError, match=r"sec.npz: t: expected integers, found float64 \(seconds\?"):
        read_npz(npz)
    np.savez(npz, t=np.array([1, 2]), x=np.array([1, 2]), y=np.array([1, 2]), p=np.array([1, 5]), width=346, height=260)
    with pytest.raises(ValueError, match="p: expected"):
        read_npz(npz)
    np.savez(npz, t=np.array([1, 2]), x=np.array([1, 2]), y=np.array([1, 2]), p=np.array([1, 0]), width=346, height=260)
    assert read_npz(npz).events["p"].tolist() == [1, -1]                 # 1 / 0 is ON / OFF
    for bad in (txt, npz):
        if bad is npz:
            np.savez(npz, t=np.array([0.1]), x=np.array([1]), y=np.array([1]), p=np.array([1]), width=346, height=260)
        out = tmp_path / f"out_{bad.suffix[1:]}.h5"
        with pytest.raises(SystemExit, match=str(bad.name)):
            main(["import", str(bad), "--out", str(out)])
        assert not out.exists()
