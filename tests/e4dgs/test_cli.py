"""`e4dgs simulate` and `e4dgs view` end to end on small image folders."""
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
    assert main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--out", str(out)]) == 0
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
    main(["simulate", "--frames", str(d), "--timestamps", str(ts), "--out", str(out), "--config", str(cfg)])
    linear = [srgb_to_linear(np.round(f * 255) / 255) for f in frames]
    expected = simulate(linear, [100, 200, 450, 700, 1000, 1600], SimulatorConfig(pos_threshold=0.3, neg_threshold=0.3, refractory_us=20))
    assert np.array_equal(read_events(out).events, expected.events)
    assert read_info(out)["t_offset_us"] == 100


def test_simulate_errors_are_clear_and_write_nothing(exr_dir, tmp_path):
    out = tmp_path / "ev.h5"
    bad_cfg = tmp_path / "bad.yaml"
    bad_cfg.write_text("threshold: 0.2\n")
    with pytest.raises(SystemExit, match="threshold: unknown key"):
        main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--out", str(out), "--config", str(bad_cfg)])
    ts = tmp_path / "t.txt"
    ts.write_text("1\n2\n")
    with pytest.raises(SystemExit, match="2 timestamps for 12 frames"):
        main(["simulate", "--frames", str(exr_dir), "--timestamps", str(ts), "--out", str(out)])
    write_exr(exr_dir / "frame_012.exr", np.ones((5, 5), np.float32))  # wrong size, last in order
    with pytest.raises(SystemExit, match="frame_012.exr.*does not match the sensor"):
        main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--out", str(out)])
    assert not out.exists() and not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_view_png_and_mp4(exr_dir, tmp_path):
    ev = tmp_path / "ev.h5"
    main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--out", str(ev)])
    png = tmp_path / "p.png"
    main(["view", str(ev), "--t0", "1ms", "--t1", "2ms", "--out", str(png), "--plain"])
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
    main(["view", str(ev), "--t0", "1ms", "--t1", "2ms", "--out", str(big)])
    labelled = cv2.imread(str(big))[..., ::-1]
    assert labelled.shape == (24 * 20 + 18, 32 * 20, 3)
    assert np.array_equal(labelled[:480:20, ::20], img)              # each event pixel a 20x20 block
    mp4 = tmp_path / "c.mp4"
    main(["view", str(ev), "--window", "0.5ms", "--out", str(mp4)])
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(mp4))
    meta = next(reader)
    n = sum(1 for _ in reader)
    assert n == 8  # windows starting at 0, 0.5, ..., 3.0 ms, and the last one ending at the 3.667 ms stream's end
    assert meta["codec"] == "h264" and meta["size"] == (640, 24 * 20 + 18)    # what browsers play
    with pytest.raises(SystemExit, match="expected a .png or .mp4"):
        main(["view", str(ev), "--out", str(tmp_path / "x.gif")])


def test_console_entry_point_is_installed():
    from pathlib import Path

    script = Path(sys.executable).parent / "e4dgs"
    for cmd in ([str(script), "--help"], [sys.executable, "-m", "e4dgs", "--help"]):
        r = subprocess.run(cmd, capture_output=True, text=True)
        assert r.returncode == 0 and "simulate" in r.stdout and "view" in r.stdout
    r = subprocess.run([str(script), "simulate", "--frames", "/nonexistent", "--fps", "30", "--out", "x.h5"],
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
    args = ["simulate", "--frames", str(exr_dir), "--fps", "3000", "--config", str(cfg), "--checkpoint-every", "3"]
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
        assert main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--out", str(out),
                     "--checkpoint-every", "2"]) == 130
    main(["simulate", "--frames", str(exr_dir), "--fps", "1000", "--out", str(out)])  # other timestamps
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
    assert main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--out", str(out),
                 "--format", "evt3", "--format", "aedat4", "--format", "rosbag2"]) == 0
    events = read_events(out)
    for name, fmt in (("ev.raw", "evt3"), ("ev.aedat4", "aedat4"), ("ev_rosbag2", "rosbag2")):
        back, found = read_recording(tmp_path / name)
        assert found == fmt and same_events(events, back), name
    with pytest.raises(SystemExit, match="--format evt2: its times are unsigned"):
        main(["simulate", "--frames", str(exr_dir), "--fps", "3000", "--t0", "-5ms", "--out", str(tmp_path / "neg.h5"),
              "--format", "evt2"])
    assert not (tmp_path / "neg.h5").exists()
