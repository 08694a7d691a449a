"""Bad inputs and faults across the commands, as a new user would meet them: each case asserts the
exit status, that the one-line message names the file or field at fault, that no traceback is
printed, and that nothing (outputs, temporaries, spools, locks) is left behind."""
from __future__ import annotations

import errno
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import h5py
import numpy as np
import pytest

from e4dgs.cli import main
from common.imageio import write_exr
from simulator import SimulatorConfig, simulate
from eventio.h5io import write_events
from tests.e4dgs.test_cli import grating_frames


@pytest.fixture(scope="module")
def good_events(tmp_path_factory) -> Path:
    frames = grating_frames(n=40)
    stream = simulate(frames, [round(k * 1e6 / 3000) for k in range(40)], SimulatorConfig())
    path = tmp_path_factory.mktemp("ev") / "good.h5"
    write_events(path, stream, attrs={"sim_pos_threshold": 0.2, "sim_neg_threshold": 0.2})
    assert len(stream) > 1000
    return path


def rewrite(src: Path, dst: Path, edit: Callable[[h5py.File], None]) -> Path:
    """A copy of event file `src` at `dst` with `edit` applied to it."""
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


def replace_dataset(f: h5py.File, name: str, data) -> None:
    del f[name]
    f.create_dataset(name, data=data)


def shuffled_t(f):
    t = f["events/t"][:]
    np.random.default_rng(0).shuffle(t)
    replace_dataset(f, "events/t", t)


def signed_polarity(f):
    replace_dataset(f, "events/p", f["events/p"][:].astype(np.int8) * 2 - 1)


def float_t(f):
    replace_dataset(f, "events/t", f["events/t"][:].astype(np.float64))


def x_outside(f):
    x = f["events/x"][:]
    x[len(x) // 2] = f.attrs["width"]
    replace_dataset(f, "events/x", x)


def y_outside(f):
    y = f["events/y"][:]
    y[7] = 60000
    replace_dataset(f, "events/y", y)


def polarity_two(f):
    p = f["events/p"][:]
    p[3] = 2
    replace_dataset(f, "events/p", p)


def short_x(f):
    replace_dataset(f, "events/x", f["events/x"][:-5])


def ms_index_off(f):
    ms = f["ms_to_idx"][:]
    ms[5] += 3
    replace_dataset(f, "ms_to_idx", ms)


def ms_index_decreasing(f):
    ms = f["ms_to_idx"][:]
    ms[2] = ms[-1] + 10
    replace_dataset(f, "ms_to_idx", ms)


def no_polarity(f):
    del f["events/p"]


def float_offset(f):
    replace_dataset(f, "t_offset", np.float64(0.5))


def zero_width(f):
    f.attrs["width"] = 0


def no_width(f):
    del f.attrs["width"]


EVENT_FAULTS = [
    (shuffled_t, "events/t: .*not sorted"),
    (signed_polarity, "events/p: expected dtype uint8, found int8 .polarity is stored as 1 = ON, 0 = OFF"),
    (float_t, "events/t: expected dtype int64, found float64 .timestamps are integer microseconds"),
    (x_outside, "events/x: event \\d+ has x = 32, outside the sensor .width 32"),
    (y_outside, "events/y: event 7 has y = 60000, outside the sensor .height 24"),
    (polarity_two, "events/p: event 3 has polarity 2"),
    (short_x, "events/x, y, t, p: expected four 1-D datasets of one length"),
    (ms_index_off, "ms_to_idx: entry 5 is \\d+, but \\d+ events come before 5 ms"),
    (ms_index_decreasing, "ms_to_idx: expected a non-decreasing index"),
    (no_polarity, "missing dataset 'events/p'"),
    (float_offset, "t_offset: expected an integer scalar"),
    (zero_width, "attributes width, height: expected positive integers"),
    (no_width, "missing attribute 'width'"),
]


@dataclass
class Run:
    rc: int
    text: str


def run_cli(argv: list[str], capsys) -> Run:
    try:
        rc = main([str(a) for a in argv])
        msg = ""
    except SystemExit as exc:
        rc = exc.code if isinstance(exc.code, int) else 1
        msg = exc.code if isinstance(exc.code, str) else ""
    out = capsys.readouterr()
    return Run(rc, msg + out.err + out.out)


def files_under(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}


def assert_clean_failure(run: Run, pattern: str, root: Path, before: set[Path], rc: int | None = None):
    assert (run.rc == rc) if rc is not None else run.rc != 0, run
    assert "Traceback" not in run.text, run.text
    import re

    assert re.search(pattern, run.text), (pattern, run.text)
    left = files_under(root) - before
    assert not left, f"left behind: {sorted(str(p) for p in left)}"


CONSUMERS = {
    "view-png": lambda ev, out: ["draw-events", ev, "--out", out / "v.png"],
    "view-mp4": lambda ev, out: ["draw-events", ev, "--out", out / "v.mp4", "--window", "1ms"],
    "e2vid": lambda ev, out: ["e2vid", ev, "--out", out / "frames"],
}


@pytest.mark.parametrize("fault, pattern", EVENT_FAULTS, ids=[f.__name__ for f, _ in EVENT_FAULTS])
def test_every_reader_refuses_a_malformed_event_file(fault, pattern, good_events, tmp_path, capsys):
    bad = rewrite(good_events, tmp_path / "bad.h5", fault)
    out = tmp_path / "out"
    out.mkdir()
    for name, argv in CONSUMERS.items():
        before = files_under(tmp_path)
        assert_clean_failure(run_cli(argv(bad, out), capsys), f"bad.h5: {pattern}", tmp_path, before)


def test_missing_and_foreign_event_files(tmp_path, capsys):
    text = tmp_path / "notes.h5"
    text.write_text("not hdf5")
    before = files_under(tmp_path)
    assert_clean_failure(run_cli(["draw-events", tmp_path / "none.h5", "--out", tmp_path / "v.png"], capsys),
                         "none.h5: no such event file", tmp_path, before)
    assert_clean_failure(run_cli(["e2vid", text, "--out", tmp_path / "f"], capsys),
                         "notes.h5: not a readable HDF5 file", tmp_path, before)


def test_training_refuses_a_scene_with_shuffled_events(motion_scene, tmp_path, capsys):
    scene = tmp_path / "scene"
    shutil.copytree(motion_scene, scene)
    rewrite(scene / "events" / "cam0.h5", scene / "events" / "cam0.h5.new", shuffled_t)
    os.replace(scene / "events" / "cam0.h5.new", scene / "events" / "cam0.h5")
    before = files_under(tmp_path)
    r = run_cli(["train", scene, "--method", "e4dgs", "--out", tmp_path / "run", "--no-progress",
                 "--set", "train.iterations=2"], capsys)
    assert_clean_failure(r, "cam0.h5: events/t: .*not sorted", tmp_path, before)
    r = run_cli(["check", scene], capsys)
    import re

    assert r.rc == 1 and re.search("cam0.h5: (SHA-256 differs|\\d+ bytes, the manifest records)", r.text), r.text


def test_check_reports_missing_and_modified_files(motion_scene, tmp_path, capsys):
    r = run_cli(["check", motion_scene], capsys)
    assert r.rc == 0 and "OK" in r.text
    scene = tmp_path / "scene"
    shutil.copytree(motion_scene, scene)
    (scene / "cameras.json").write_text((scene / "cameras.json").read_text()[:-20])
    next(scene.glob("rgb/**/*.png")).unlink()
    r = run_cli(["check", tmp_path], capsys)        # a dataset root: every scene under it
    assert r.rc == 1 and "cameras.json: " in r.text and "missing (listed in" in r.text
    assert_clean_failure(run_cli(["check", tmp_path / "nothing"], capsys), "nothing: no such folder",
                         tmp_path, files_under(tmp_path))


@pytest.fixture
def frames_dir(tmp_path) -> Path:
    d = tmp_path / "frames"
    for k, f in enumerate(grating_frames(n=8)):
        write_exr(d / f"frame_{k:03d}.exr", f)
    return d


def _sim(frames, out, *extra):
    return ["simulate", frames, "--out", out, *extra]


SIMULATE_CASES = [
    ("fps-negative", lambda d, o: _sim(d, o, "--fps", "-1"), 2, "argument --fps: expected a positive number up to 1e\\+09, got '-1'"),
    ("fps-zero", lambda d, o: _sim(d, o, "--fps", "0"), 2, "argument --fps: expected a positive number"),
    ("fps-nan", lambda d, o: _sim(d, o, "--fps", "nan"), 2, "argument --fps: expected a finite number"),
    ("checkpoint-every-zero", lambda d, o: _sim(d, o, "--fps", "30", "--checkpoint-every", "0"), 2,
     "argument --checkpoint-every: expected an integer in 1 .. 1,000,000,000"),
    ("frames-not-a-folder", lambda d, o: _sim(d / "nope", o, "--fps", "30"), 1, "--frames .*nope: not a directory"),
    ("timestamps-count", lambda d, o: _sim(d, o, "--timestamps", _text(d.parent / "t.txt", "1\n2\n")), 1,
     "t.txt: 2 timestamps for 8 frames"),
    ("timestamps-not-integer", lambda d, o: _sim(d, o, "--timestamps", _text(d.parent / "t.txt", "1\n2.5x\n")), 1,
     "t.txt:2: expected an integer microsecond timestamp"),
    ("config-unknown-key", lambda d, o: _sim(d, o, "--fps", "30", "--config", _text(d.parent / "c.yaml", "treshold: 1\n")),
     1, "c.yaml: treshold: unknown key"),
    ("config-bad-yaml", lambda d, o: _sim(d, o, "--fps", "30", "--config", _text(d.parent / "c.yaml", "a: [1,\n")), 1,
     "c.yaml: not valid YAML"),
    ("config-negative-rate", lambda d, o: _sim(d, o, "--fps", "30", "--config",
                                             _text(d.parent / "c.yaml", "shot_noise_rate_hz: -3\n")), 1,
     "c.yaml: shot_noise_rate_hz: expected a non-negative number"),
    ("frame-gap", lambda d, o: _sim(_gap(d), o, "--fps", "30"), 1, "numbering has a gap .frame_002.exr is followed by frame_004.exr"),
    ("frame-unpadded", lambda d, o: _sim(_unpadded(d), o, "--fps", "30"), 1, "zero-pad the frame numbers"),
    ("frame-corrupt", lambda d, o: _sim(_corrupt_last(d), o, "--fps", "30"), 1, "frame_007.exr"),
    ("out-not-writable", lambda d, o: _sim(d, Path("/sys/e4dgs_test/ev.h5"), "--fps", "30"), 1,
     "/sys/e4dgs_test: Operation not permitted"),
]


def _text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _gap(d: Path) -> Path:
    (d / "frame_003.exr").unlink()
    return d


def _unpadded(d: Path) -> Path:
    for p in sorted(d.iterdir()):
        p.rename(d / f"f{int(p.stem.split('_')[1])}.exr")
    for k in range(8, 11):
        shutil.copy(d / "f7.exr", d / f"f{k}.exr")
    return d


def _corrupt_last(d: Path) -> Path:
    (d / "frame_007.exr").write_bytes(b"not an image")
    return d


@pytest.mark.parametrize("name, argv, rc, pattern", SIMULATE_CASES, ids=[c[0] for c in SIMULATE_CASES])
def test_simulate_refuses_bad_input(name, argv, rc, pattern, frames_dir, tmp_path, capsys):
    args = argv(frames_dir, tmp_path / "ev.h5")
    before = files_under(tmp_path)
    assert_clean_failure(run_cli(args, capsys), pattern, tmp_path, before, rc)


def test_full_disk_during_simulate_leaves_nothing(frames_dir, tmp_path, capsys, monkeypatch):
    from simulator.resumable import EventSpool

    real, calls = EventSpool.append, []

    def full(self, events):
        calls.append(1)
        if len(calls) == 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.spool_path))
        return real(self, events)

    monkeypatch.setattr(EventSpool, "append", full)
    before = files_under(tmp_path)
    r = run_cli(_sim(frames_dir, tmp_path / "ev.h5", "--fps", "3000"), capsys)
    assert_clean_failure(r, "ev.h5.spool: No space left on device", tmp_path, before, 1)


def test_a_second_simulate_into_the_same_output_is_refused(frames_dir, tmp_path, capsys):
    from common.fileio import output_lock

    out = tmp_path / "ev.h5"
    with output_lock(out):
        before = files_under(tmp_path)
        r = run_cli(_sim(frames_dir, out, "--fps", "3000"), capsys)
        assert r.rc == 1 and f"another run (pid {os.getpid()}) is writing this output" in r.text
        assert files_under(tmp_path) == before
    assert run_cli(_sim(frames_dir, out, "--fps", "3000"), capsys).rc == 0
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_unresumable_checkpoint_and_stale_temporaries_are_cleared(frames_dir, tmp_path, capsys, monkeypatch):
    from common import imageio

    out = tmp_path / "ev.h5"
    real_read, calls = imageio.read_linear_image, []

    def dying(path):
        calls.append(path)
        if len(calls) == 6:
            raise KeyboardInterrupt
        return real_read(path)

    with monkeypatch.context() as m:
        m.setattr(imageio, "read_linear_image", dying)
        assert run_cli(_sim(frames_dir, out, "--fps", "3000", "--checkpoint-every", "2"), capsys).rc == 130
    (tmp_path / ".ev.h5.spool").unlink()                           # the spool is lost, the checkpoint stays
    (tmp_path / ".ev.h5.999999999.tmp").write_bytes(b"x" * 100)    # a killed writer's temporary
    r = run_cli(_sim(frames_dir, out, "--fps", "3000", "--checkpoint-every", "2"), capsys)
    assert r.rc == 0 and "cannot resume" in r.text and "starting" in r.text
    clean = tmp_path / "clean.h5"
    assert run_cli(_sim(frames_dir, clean, "--fps", "3000"), capsys).rc == 0
    from eventio.h5io import read_events

    assert np.array_equal(read_events(out).events, read_events(clean).events)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_sigma_far_beyond_the_threshold_warns(frames_dir, tmp_path, capsys):
    cfg = _text(tmp_path / "c.yaml", "threshold_sigma: 5\n")
    r = run_cli(_sim(frames_dir, tmp_path / "ev.h5", "--fps", "3000", "--config", cfg), capsys)
    assert r.rc == 0 and "warning: threshold_sigma: 5" in r.text and "Traceback" not in r.text


E2VID_VIEW_CASES = [
    ("e2vid-dt-negative", lambda ev, o: ["e2vid", ev, "--out", o / "f", "--dt-ms", "-1"], 2,
     "argument --dt-ms: expected a positive number"),
    ("e2vid-dt-zero", lambda ev, o: ["e2vid", ev, "--out", o / "f", "--dt-ms", "0"], 2,
     "argument --dt-ms: expected a positive number"),
    ("e2vid-window-negative", lambda ev, o: ["e2vid", ev, "--out", o / "f", "--events-per-window", "-5"],
     2, "argument --events-per-window: expected an integer in 0 .. 1,000,000,000"),
    ("e2vid-weights-missing", lambda ev, o: ["e2vid", ev, "--out", o / "f", "--weights", o / "w.pth"], 1,
     "w.pth"),
    ("view-t1-before-t0", lambda ev, o: ["draw-events", ev, "--out", o / "v.png", "--t0", "5ms", "--t1", "1ms"], 1,
     "--t1 .* must be after --t0"),
    ("view-bad-suffix", lambda ev, o: ["draw-events", ev, "--out", o / "v.gif"], 1, "v.gif: expected a .png or .mp4"),
    ("view-bad-time", lambda ev, o: ["draw-events", ev, "--out", o / "v.png", "--t0", "soon"], 1, "soon"),
    ("view-fps-zero", lambda ev, o: ["draw-events", ev, "--out", o / "v.mp4", "--fps", "0"], 2,
     "argument --fps: expected a positive number"),
]


@pytest.mark.parametrize("name, argv, rc, pattern", E2VID_VIEW_CASES, ids=[c[0] for c in E2VID_VIEW_CASES])
def test_e2vid_and_view_refuse_bad_options(name, argv, rc, pattern, good_events, tmp_path, capsys):
    before = files_under(tmp_path)
    assert_clean_failure(run_cli(argv(good_events, tmp_path), capsys), pattern, tmp_path, before, rc)


def _camera_json(path: Path, **fields) -> Path:
    import json

    cam = {"K": [[50, 0, 32], [0, 50, 24], [0, 0, 1]], "c2w_opencv": np.eye(4).tolist(), "width": 64, "height": 48}
    cam.update(fields)
    path.write_text(json.dumps(cam))
    return path


TRAIN_CASES = [
    ("lr-negative", lambda s, o: ["train", s, "--out", o, "--set", "train.lr.feature=-1"], 1, "lr.feature"),
    ("unknown-key", lambda s, o: ["train", s, "--out", o, "--set", "train.iteratons=5"], 1,
     "train.iteratons: unknown key"),
    ("set-bad-yaml", lambda s, o: ["train", s, "--out", o, "--set", "train.iterations=[1,"], 1,
     "--set train.iterations: the value '\\[1,' is not valid YAML"),
    ("set-no-equals", lambda s, o: ["train", s, "--out", o, "--set", "train.iterations"], 1,
     "--set 'train.iterations': expected key=value"),
    ("scene-missing", lambda s, o: ["train", s.parent / "cubez", "--out", o], 1,
     "cubez: no such scene folder"),
    ("method-unknown", lambda s, o: ["train", s, "--out", o, "--method", "nerf"], 1, "nerf.*e4dgs"),
    ("config-missing", lambda s, o: ["train", s, "--out", o, "--config", o.parent / "none.yaml"], 1,
     "none.yaml: cannot read config file"),
    ("device-unknown", lambda s, o: ["train", s, "--out", o, "--set", "train.device=gpu"], 1,
     "device: expected auto, cpu, cuda or cuda:N"),
    ("gsplat-on-cpu", lambda s, o: ["train", s, "--out", o, "--set", "train.backend=gsplat",
                                    "--set", "train.device=cpu"], 1, "train.backend: .*'gsplat' renders CUDA tensors"),
    ("blur-level-unknown", lambda s, o: ["train", s, "--out", o, "--set", "frames=extreme"], 1,
     "no blur level 'extreme'"),
    ("render-model-missing", lambda s, o: ["render", o / "none", "--camera", "0", "--t", "0",
                                           "--out", o.parent / "r"], 1, "none: no such model file"),
]


@pytest.mark.parametrize("name, argv, rc, pattern", TRAIN_CASES, ids=[c[0] for c in TRAIN_CASES])
def test_train_and_render_refuse_bad_input(name, argv, rc, pattern, motion_scene, tmp_path, capsys):
    args = argv(motion_scene, tmp_path / "run")
    before = files_under(tmp_path)
    assert_clean_failure(run_cli(args, capsys), pattern, tmp_path, before, rc)


@pytest.fixture(scope="module")
def tiny_model(motion_scene, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("model") / "run"
    assert main(["train", str(motion_scene), "--out", str(out), "--no-progress", "--set",
                 "train.iterations=3", "--set", "train.init.n_points_object=200"]) == 0
    return out


RENDER_CAMERA_CASES = [
    ("truncated", lambda p: _text(p, '{"K": [[1'), "cam.json: not valid JSON"),
    ("c2w-3x3", lambda p: _camera_json(p, c2w_opencv=np.eye(3).tolist()),
     "cam.json: c2w_opencv: expected a finite 4x4 matrix, got shape \\(3, 3\\)"),
    ("K-missing", lambda p: _text(p, '{"c2w_opencv": [], "width": 4, "height": 4}'), "cam.json: missing field 'K'"),
    ("width-zero", lambda p: _camera_json(p, width=0), "cam.json: width: expected a positive integer"),
    ("not-an-object", lambda p: _text(p, "[1, 2]"), "cam.json: expected a JSON object"),
]


@pytest.mark.parametrize("name, make, pattern", RENDER_CAMERA_CASES, ids=[c[0] for c in RENDER_CAMERA_CASES])
def test_render_refuses_bad_camera_files(name, make, pattern, tiny_model, tmp_path, capsys):
    cam = make(tmp_path / "cam.json")
    before = files_under(tmp_path)
    r = run_cli(["render", tiny_model, "--camera", cam, "--t", "0", "--out", tmp_path / "r"], capsys)
    assert_clean_failure(r, pattern, tmp_path, before, 1)


def test_render_refuses_times_outside_the_clip(tiny_model, tmp_path, capsys):
    r = run_cli(["render", tiny_model, "--camera", "0", "--t", "1.5", "--out", tmp_path / "r"], capsys)
    assert_clean_failure(r, "argument --t: expected a number in 0 .. 1 \\(a normalised time\\)", tmp_path, set(), 2)


DATASET_CASES = [
    ("checkpoint-every-zero", ["dataset", "--preset", "tiny", "--checkpoint-every", "0"], 2,
     "argument --checkpoint-every: expected an integer in 1 .. 1,000,000,000"),
    ("jobs-zero", ["dataset", "--preset", "tiny", "--jobs", "0"], 2, "argument --jobs: expected an integer in 1 .. 1,000,000,000"),
    ("preset-unknown", ["dataset", "--preset", "huge"], 1, "unknown dataset preset 'huge'"),
    ("scene-unknown", ["dataset", "--preset", "tiny", "--scenes", "cubez"], 1, "--scenes: cubez not in preset"),
    ("bench-preset-unknown", ["bench", "--preset", "huge"], 1, "huge.yaml: no such benchmark preset"),
]


@pytest.mark.parametrize("name, argv, rc, pattern", DATASET_CASES, ids=[c[0] for c in DATASET_CASES])
def test_dataset_and_bench_refuse_bad_options(name, argv, rc, pattern, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert_clean_failure(run_cli(argv, capsys), pattern, tmp_path, set(), rc)


def test_a_typo_in_a_preset_override_is_blamed_on_the_preset(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    preset = _text(tmp_path / "mine.yaml", "scenes: [cubes]\noverrides:\n  render: {widht: 64}\n")
    before = files_under(tmp_path)
    r = run_cli(["dataset", "--preset", preset, "--out", tmp_path / "data"], capsys)
    assert_clean_failure(r, "mine.yaml: overrides \\(applied to scene 'cubes'\\): render.widht: unknown key",
                         tmp_path, before, 1)
    assert "resume" not in r.text


def test_a_second_training_into_the_same_folder_is_refused(motion_scene, tmp_path, capsys):
    from common.fileio import output_lock

    out = tmp_path / "run"
    with output_lock(out):
        before = files_under(tmp_path)
        r = run_cli(["train", motion_scene, "--out", out, "--no-progress", "--set", "train.iterations=2"],
                    capsys)
        assert_clean_failure(r, f"run: another run \\(pid {os.getpid()}\\) is writing this output", tmp_path, before, 1)
    assert not (tmp_path / ".run.lock").exists()
