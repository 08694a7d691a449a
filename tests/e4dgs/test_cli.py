"""`e4dgs simulate` and `e4dgs draw-events` end to end on small image folders."""
import contextlib
import subprocess
import sys

import cv2
import numpy as np
import pytest

from e4dgs.cli import main
from common.imageio import write_exr
from simulator import SimulatorConfig, simulate
from eventio.h5io import read_events, read_info
from simulator.pixel import srgb_to_linear


def grating_frames(n=12, h=24, w=32):
    x = np.arange(w)[None, :] + 0 * np.arange(h)[:, None]
    return [(0.05 + 0.9 * (0.5 + 0.5 * np.sin(2 * np.pi * (x - k) / 12))).astype(np.float32) for k in range(n)]


@pytest.fixture
def exr_dir(tmp_path):
    d = tmp_path / "exr"
    for k, f in enumerate(grating_frames()):
        write_exr(d / f"frame_{k:03d}.exr", f)
    return d


def test_simulate_exr_folder_matches_the_python_api(exr_dir, tmp_path):
    out = tmp_path / "ev.h5"
    assert main(["simulate", str(exr_dir), "--fps", "3000", "--out", str(out)]) == 0
    expected = simulate(grating_frames(), [round(k * 1e6 / 3000) for k in range(12)], SimulatorConfig())
    got = read_events(out)
    assert len(got) > 0 and np.array_equal(got.events, expected.events)
    info = read_info(out)
    assert info["sim_pos_threshold"] == 0.2 and info["width"] == 32 and "simulator_config" in info


def test_simulate_png_folder_with_timestamps_and_config(tmp_path):
    d = tmp_path / "png"
    d.mkdir()
    frames = grating_frames(n=6)
    for k, f in enumerate(frames):
        cv2.imwrite(str(d / f"{k:02d}.png"), np.round(f * 255).astype(np.uint8))
    ts = tmp_path / "t.txt"
    ts.write_text("# us\n100\n200\n450\n700\n1000\n1600\n")
    cfg = tmp_path / "sim.yaml"
    cfg.write_text("pos_threshold: 0.3\nneg_threshold: 0.3\nrefractory_us: 20\n")
    out = tmp_path / "ev.h5"
    main(["simulate", str(d), "--timestamps", str(ts), "--out", str(out), "--config", str(cfg)])
    linear = [srgb_to_linear(np.round(f * 255) / 255) for f in frames]
    expected = simulate(linear, [100, 200, 450, 700, 1000, 1600], SimulatorConfig(pos_threshold=0.3, neg_threshold=0.3, refractory_us=20))
    assert np.array_equal(read_events(out).events, expected.events)
    assert read_info(out)["t_offset_us"] == 100


def test_simulate_errors_are_clear_and_write_nothing(exr_dir, tmp_path):
    out = tmp_path / "ev.h5"
    bad_cfg = tmp_path / "bad.yaml"
    bad_cfg.write_text("threshold: 0.2\n")
    with pytest.raises(SystemExit, match="threshold: unknown key"):
        main(["simulate", str(exr_dir), "--fps", "3000", "--out", str(out), "--config", str(bad_cfg)])
    ts = tmp_path / "t.txt"
    ts.write_text("1\n2\n")
    with pytest.raises(SystemExit, match="2 timestamps for 12 frames"):
        main(["simulate", str(exr_dir), "--timestamps", str(ts), "--out", str(out)])
    write_exr(exr_dir / "frame_012.exr", np.ones((5, 5), np.float32))  # wrong size, last in order
    with pytest.raises(SystemExit, match="frame_012.exr.*does not match the sensor"):
        main(["simulate", str(exr_dir), "--fps", "3000", "--out", str(out)])
    assert not out.exists() and not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_view_png_and_mp4(exr_dir, tmp_path):
    ev = tmp_path / "ev.h5"
    main(["simulate", str(exr_dir), "--fps", "3000", "--out", str(ev)])
    png = tmp_path / "p.png"
    main(["draw-events", str(ev), "--t0", "1ms", "--t1", "2ms", "--out", str(png), "--plain"])
    img = cv2.imread(str(png))[..., ::-1]
    assert img.shape == (24, 32, 3)
    events = read_events(ev).window(1000, 2000).events
    idx = events["y"].astype(int) * 32 + events["x"]
    n_on = np.bincount(idx[events["p"] > 0], minlength=24 * 32).reshape(24, 32)
    n_off = np.bincount(idx[events["p"] < 0], minlength=24 * 32).reshape(24, 32)
    r, b = img[..., 0].astype(int), img[..., 2].astype(int)
    assert np.array_equal(r > b, n_on > n_off) and np.array_equal(b > r, n_off > n_on)
    assert np.all(img[(n_on + n_off) == 0] == 255) and np.all(img[(n_on + n_off) > 0].min(axis=-1) < 255)
    big = tmp_path / "big.png"                      # labelled and scaled: 20x, plus the 18-px key strip
    main(["draw-events", str(ev), "--t0", "1ms", "--t1", "2ms", "--out", str(big)])
    labelled = cv2.imread(str(big))[..., ::-1]
    assert labelled.shape == (24 * 20 + 18, 32 * 20, 3)
    assert np.array_equal(labelled[:480:20, ::20], img)              # each event pixel a 20x20 block
    mp4 = tmp_path / "c.mp4"
    main(["draw-events", str(ev), "--window", "0.5ms", "--out", str(mp4)])
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(mp4))
    meta = next(reader)
    n = sum(1 for _ in reader)
    assert n == 8  # windows starting at 0, 0.5, ..., 3.0 ms, and the last one ending at the 3.667 ms stream's end
    assert meta["codec"] == "h264" and meta["size"] == (640, 24 * 20 + 18)    # what browsers play
    with pytest.raises(SystemExit, match="expected a .png or .mp4"):
        main(["draw-events", str(ev), "--out", str(tmp_path / "x.gif")])


def test_console_entry_point_is_installed():
    from pathlib import Path

    script = Path(sys.executable).parent / "e4dgs"
    for cmd in ([str(script), "--help"], [sys.executable, "-m", "e4dgs", "--help"]):
        r = subprocess.run(cmd, capture_output=True, text=True)
        assert r.returncode == 0 and "simulate" in r.stdout and "view" in r.stdout
    r = subprocess.run([str(script), "simulate", "/nonexistent", "--fps", "30", "--out", "x.h5"],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "not a directory" in r.stderr


@contextlib.contextmanager
def killed_at_frame_read(monkeypatch, n):
    """Interrupt the run (as a kill would) when it reads its n-th frame file."""
    from common import imageio

    real_read, calls = imageio.read_linear_image, []

    def dying_read(path):
        calls.append(path)
        if len(calls) == n:
            raise KeyboardInterrupt("killed")
        return real_read(path)

    with monkeypatch.context() as m:
        m.setattr(imageio, "read_linear_image", dying_read)
        yield


def test_killed_simulate_resumes_to_the_same_file(exr_dir, tmp_path, monkeypatch):
    cfg = tmp_path / "noisy.yaml"  # random noise too: the resumed run must continue the same RNG stream
    cfg.write_text("shot_noise_rate_hz: 2000.0\nrefractory_us: 30\nthreshold_sigma: 0.03\nleak_rate_hz: 50.0\n")
    args = ["simulate", str(exr_dir), "--fps", "3000", "--config", str(cfg), "--checkpoint-every", "3"]
    clean = tmp_path / "clean.h5"
    main(args + ["--out", str(clean)])

    out = tmp_path / "resumed.h5"
    with killed_at_frame_read(monkeypatch, 8):
        assert main(args + ["--out", str(out)]) == 130      # interrupted: one line, exit 130
    assert not out.exists()  # nothing that looks complete
    assert (tmp_path / ".resumed.h5.ckpt.npz").exists()
    main(args + ["--out", str(out)])
    assert np.array_equal(read_events(out).events, read_events(clean).events)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    assert read_info(out)["n_events"] == read_info(clean)["n_events"] > 0


def test_changed_inputs_discard_a_stale_checkpoint(exr_dir, tmp_path, monkeypatch):
    out = tmp_path / "ev.h5"
    with killed_at_frame_read(monkeypatch, 6):
        assert main(["simulate", str(exr_dir), "--fps", "3000", "--out", str(out),
                     "--checkpoint-every", "2"]) == 130
    main(["simulate", str(exr_dir), "--fps", "1000", "--out", str(out)])  # other timestamps
    expected = simulate(grating_frames(), [round(k * 1e6 / 1000) for k in range(12)], SimulatorConfig())
    assert np.array_equal(read_events(out).events, expected.events)


def test_simulate_files_is_the_library_call_under_the_command(exr_dir, tmp_path):
    from simulator.files import simulate_files

    files = sorted(exr_dir.iterdir())
    t_us = [round(k * 1e6 / 3000) for k in range(len(files))]
    r = simulate_files(files, t_us, tmp_path / "lib.h5", SimulatorConfig(), progress=False)
    expected = simulate(grating_frames(), t_us, SimulatorConfig())
    assert (r.n_events, r.width, r.height) == (len(expected), 32, 24)
    assert np.array_equal(read_events(tmp_path / "lib.h5").events, expected.events)
    (exr_dir / "frame_005.exr").write_bytes(b"broken")
    with pytest.raises(ValueError, match="frame_005.exr"):     # an exception, never SystemExit
        simulate_files(files, t_us, tmp_path / "bad.h5", progress=False)
    assert not (tmp_path / "bad.h5").exists() and not list(tmp_path.glob(".bad.h5*"))


def test_simulate_writes_extra_formats_beside_the_h5(exr_dir, tmp_path):
    from eventio.formats import read_recording, same_events

    out = tmp_path / "ev.h5"
    assert main(["simulate", str(exr_dir), "--fps", "3000", "--out", str(out),
                 "--format", "evt3", "--format", "aedat4", "--format", "rosbag2"]) == 0
    events = read_events(out)
    for name, fmt in (("ev.raw", "evt3"), ("ev.aedat4", "aedat4"), ("ev_rosbag2", "rosbag2")):
        back, found = read_recording(tmp_path / name)
        assert found == fmt and same_events(events, back), name
    with pytest.raises(SystemExit, match="--format evt2: its times are unsigned"):
        main(["simulate", str(exr_dir), "--fps", "3000", "--t0", "-5ms", "--out", str(tmp_path / "neg.h5"),
              "--format", "evt2"])
    assert not (tmp_path / "neg.h5").exists()


# ---- one pattern for the main input; old spellings for one release ---------------------------------

def _subparsers():
    import argparse

    from e4dgs.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return parser, sub.choices


def test_every_command_is_listed_by_stage_and_every_option_has_help(capsys):
    from e4dgs.cli import STAGES, main

    parser, commands = _subparsers()
    names = {n for n in commands if n != "view"}
    assert sorted(c for _, cs in STAGES for c in cs) == sorted(names)
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for stage, cs in STAGES:
        block = out.split(f"\n{stage}:\n", 1)[1]
        assert all(f"\n  {c} " in "\n" + block.split("\n\n")[0] for c in cs), stage
    missing = [f"{n} {a.option_strings or a.dest}" for n, p in commands.items() for a in p._actions
               if a.help is None and not isinstance(a, __import__("argparse")._HelpAction)]
    assert missing == []


MAIN_INPUTS = {"simulate": "FRAMES", "draw-events": "EVENTS", "train": "SCENE", "render": "RUN", "e2vid": "EVENTS",
               "score": "RENDERS", "check": None, "masks": None, "testviews": None, "verify": None, "export": None,
               "import": None, "viewer": None}


def test_the_main_input_is_the_first_positional_argument_of_every_command_that_reads_one():
    import argparse

    _, commands = _subparsers()
    for name, p in commands.items():
        positional = [a for a in p._actions if not a.option_strings]
        if name in ("dataset", "bench", "train-e2vid"):       # no main input: a preset with a default, or none
            assert positional == [], name
            continue
        assert positional, f"{name}: its main input is an option"
        if MAIN_INPUTS.get(name):
            assert positional[0].metavar == MAIN_INPUTS[name], name


@pytest.mark.parametrize("old, new, words", [
    (["train", "--scene", "S"], ["train", "S"], "--scene is deprecated (kept until 0.3): give the SCENE as the first argument"),
    (["render", "--model", "R", "--out", "o"], ["render", "R", "--out", "o"], "--model is deprecated"),
    (["simulate", "--frames", "F", "--fps", "1", "--out", "e.h5"], ["simulate", "F", "--fps", "1", "--out", "e.h5"],
     "--frames is deprecated"),
    (["e2vid", "--events", "E", "--out", "o"], ["e2vid", "E", "--out", "o"], "--events is deprecated"),
    (["score", "--renders", "R", "--data", "d", "--name", "n", "--inputs", "rgb"],
     ["score", "R", "--data", "d", "--name", "n", "--inputs", "rgb"], "--renders is deprecated"),
    (["bench", "--methods", "e4dgs"], ["bench", "--cells", "e4dgs"], "--methods is deprecated (kept until 0.3): use --cells"),
])
def test_an_old_option_spelling_parses_as_the_new_one_with_a_deprecation_line(old, new, words, capsys):
    from e4dgs.cli import build_parser

    parser = build_parser()
    a = vars(parser.parse_args(old))
    assert words in capsys.readouterr().err
    b = vars(parser.parse_args(new))
    assert capsys.readouterr().err == ""
    assert {k: v for k, v in a.items() if not callable(v)} == {k: v for k, v in b.items() if not callable(v)}


def test_a_missing_main_input_is_named(capsys):
    from e4dgs.cli import main

    with pytest.raises(SystemExit) as e:
        main(["train", "--method", "d3dgs"])
    assert e.value.code == 2 and "the following arguments are required: SCENE" in capsys.readouterr().err


def test_the_old_view_command_runs_draw_events_with_a_deprecation_line(tmp_path, capsys):
    import numpy as np

    from e4dgs.cli import main
    from eventio import EventStream, make_events, write_events

    ev = EventStream(make_events(np.arange(0, 5000, 100), np.arange(50) % 8, np.arange(50) % 6, np.where(np.arange(50) % 2, 1, -1)), 8, 6)
    write_events(tmp_path / "e.h5", ev)
    assert main(["view", str(tmp_path / "e.h5"), "--out", str(tmp_path / "a.png"), "--plain"]) == 0
    assert "`e4dgs view` is deprecated (kept until 0.3): it is `e4dgs draw-events`" in capsys.readouterr().err
    assert main(["draw-events", str(tmp_path / "e.h5"), "--out", str(tmp_path / "b.png"), "--plain"]) == 0
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
