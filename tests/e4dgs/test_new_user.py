"""What a new user's trial found (issue 36), each case failing on the code before its fix: duplicate
YAML keys, outputs of the wrong kind or inside an input, hidden and doubled frames, negative start
times with units, colliding render names, impossible cameras and sensors, and workers that outlive
a killed `e4dgs dataset`."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from common.imageio import write_exr
from e4dgs.cli import main
from tests.e4dgs.test_cli import grating_frames

ROOT = Path(__file__).resolve().parents[2]


def cli(argv: list[str], capsys) -> tuple[int, str]:
    """(exit status, stderr and any SystemExit message) of `e4dgs argv` run in this process."""
    try:
        rc, msg = main([str(a) for a in argv]), ""
    except SystemExit as exc:
        rc, msg = (exc.code if isinstance(exc.code, int) else 1), (exc.code if isinstance(exc.code, str) else "")
    err = msg + capsys.readouterr().err
    assert "Traceback" not in err
    return rc, err


@pytest.mark.parametrize("where,text", [
    ("bench", "dataset: quick\nscenes: [hinge]\ndataset: paper\n"),
    ("dataset", "scenes: [cubes]\noverrides: {duration_s: 0.1}\noverrides: {duration_s: 0.2}\n"),
    ("sim", "pos_threshold: 0.2\nneg_threshold: 0.3\npos_threshold: 0.4\n"),
])
def test_a_key_written_twice_in_any_yaml_is_refused_naming_it(tmp_path, capsys, where, text):
    from benchmark.config import load_bench
    from common.config import ConfigError, load_config
    from datagen.config import load_preset
    from simulator.config import SimulatorConfig

    p = tmp_path / f"{where}.yaml"
    p.write_text(text)
    load = {"bench": load_bench, "dataset": load_preset, "sim": lambda q: load_config(SimulatorConfig, q)}[where]
    with pytest.raises(ConfigError, match="appears twice"):
        load(p)


@pytest.fixture
def frames(tmp_path) -> Path:
    d = tmp_path / "frames"
    for k, f in enumerate(grating_frames()):
        write_exr(d / f"frame_{k:03d}.exr", f)
    return d


def test_simulate_refuses_outputs_of_the_wrong_kind_or_inside_its_input(frames, tmp_path, capsys):
    for out, words in ((tmp_path / "wrong.png", "expected an event file name ending in .h5"),
                       (frames / "events.h5", "lies inside FRAMES")):
        rc, err = cli(["simulate", frames, "--fps", "1000", "--out", out], capsys)
        assert rc == 1 and words in err and not out.exists()
    (tmp_path / "adir.h5").mkdir()
    rc, err = cli(["simulate", frames, "--fps", "1000", "--out", tmp_path / "adir.h5"], capsys)
    assert rc == 1 and "is a folder" in err


def test_simulate_skips_hidden_files_refuses_doubled_frames_and_takes_negative_start_times(frames, tmp_path, capsys):
    from eventio.h5io import read_events

    (frames / "._frame_000.exr").write_bytes(b"\x00\x05\x16\x07 resource fork")      # a macOS copy's debris
    out = tmp_path / "ev.h5"
    assert cli(["simulate", frames, "--fps", "1000", "--t0", "-5ms", "--out", out], capsys)[0] == 0
    ev = read_events(out)
    assert ev.events["t"].min() >= -5000 and ev.events["t"].min() < 0
    import cv2
    cv2.imwrite(str(frames / "frame_003.png"), np.zeros((24, 32), np.uint8))
    rc, err = cli(["simulate", frames, "--fps", "1000", "--out", tmp_path / "b.h5"], capsys)
    assert rc == 1 and "frame_003.exr and frame_003.png are the same frame in two formats" in err


def test_render_refuses_colliding_names_negative_indices_and_impossible_cameras(tmp_path, capsys, motion_scene):
    import json

    from recon.render import camera_from_pose

    model = tmp_path / "m"
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "train", str(motion_scene), "--method", "d3dgs",
                        "--set", "train.iterations=3", "--set", "train.scale_schedule=false", "--set",
                        "train.densify.enabled=false", "--set", "train.init.n_points_object=50", "--out", str(model),
                        "--no-progress"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-1500:]
    rc, err = cli(["render", model, "--camera", "0", "--t", "0.5", "0.5000001", "--out", tmp_path / "r"],
                  capsys)
    assert rc == 1 and "two times give the same file name" in err and not (tmp_path / "r").exists()
    rc, err = cli(["render", model, "--camera=-1", "--t", "0.5", "--out", tmp_path / "r"], capsys)
    assert rc == 1 and "a camera index is >= 0" in err
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"K": [[0, 0, 32], [0, 40, 24], [0, 0, 1]], "c2w_opencv": np.eye(4).tolist(),
                               "width": 64, "height": 48}))
    rc, err = cli(["render", model, "--camera", cam, "--t", "0.5", "--out", tmp_path / "r"], capsys)
    assert rc == 1 and str(cam) in err and "positive fx, fy" in err
    bad_pose = np.eye(4)
    bad_pose[0, 3] = np.nan
    for K, pose, words in ((np.eye(4), np.eye(4), "K must be a finite 3x3"), (np.eye(3), bad_pose, "NaN or inf"),
                           (np.eye(3), np.eye(3), "4x4 camera-to-world"), (np.eye(3), np.zeros((4, 4)), "last row is not 0 0 0 1")):
        with pytest.raises(ValueError, match=words):
            camera_from_pose(K, pose, 64, 48)


def test_a_sensor_of_a_fractional_or_impossible_size_is_refused():
    from simulator import SimulatorConfig
    from simulator.simulator import EventSimulator

    with pytest.raises(ValueError, match="positive integers, got 32.5"):
        EventSimulator(SimulatorConfig(), 32.5, 24)
    with pytest.raises(ValueError, match="more than 16,777,216"):
        EventSimulator(SimulatorConfig(), 65535, 65535)


def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if int((d / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, ValueError, IndexError):
                pass
    return out


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs Linux /proc")
def test_a_killed_dataset_command_takes_its_workers_with_it(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "e4dgs.cli", "dataset", "--preset", "tiny", "--out",
                             str(tmp_path / "d")], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    workers: list[int] = []
    while time.time() < deadline and not workers:
        workers = _children(proc.pid)
        time.sleep(0.05)
    assert workers, "no worker started"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 10
    while time.time() < deadline and any(Path(f"/proc/{w}").exists() and "Z" not in
                                         Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[0]
                                         for w in workers if Path(f"/proc/{w}").exists()):
        time.sleep(0.1)
    alive = [w for w in workers if Path(f"/proc/{w}").exists()
             and "Z" not in Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[0]]
    assert not alive, f"worker(s) {alive} outlived the killed `e4dgs dataset`"


def test_view_shows_every_event_of_a_file_that_records_no_end(tmp_path, capsys):
    """Without a t_end_us attribute the default window used to end at the file's start: 1 of 3 events."""
    import cv2
    import h5py

    from eventio.events import EventStream, make_events
    from eventio.h5io import write_events

    path = tmp_path / "three.h5"
    write_events(path, EventStream(make_events([0, 400, 900], [1, 2, 3], [1, 1, 1], [1, -1, 1]), 8, 4))
    with h5py.File(path, "r+") as f:
        for key in [k for k in f.attrs if k == "t_end_us"]:
            del f.attrs[key]
    rc, err = cli(["draw-events", path, "--out", tmp_path / "v.png", "--plain"], capsys)
    assert rc == 0, err
    img = cv2.imread(str(tmp_path / "v.png"))
    assert int(np.sum(img.min(axis=-1) < 255)) == 3


def test_a_budget_that_ends_before_the_deformation_or_densification_starts_is_said(motion_scene, tmp_path):
    import warnings

    import recon
    from common.config import ConfigWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        recon.fit(motion_scene, "d3dgs", overrides={"train.iterations": 5, "train.scale_schedule": False,
                                                    "train.warm_up": 200, "train.densify.start": 50,
                                                    "train.init.n_points_object": 50},
                  out_dir=tmp_path / "r", progress=False)
    said = [str(w.message) for w in caught if issubclass(w.category, ConfigWarning)]
    assert any("before the deformation is switched on (warm-up 200" in m for m in said)
    assert any("before densification starts (iteration 50)" in m for m in said)
    import json
    evals = [r for r in map(json.loads, (tmp_path / "r" / "log.jsonl").read_text().splitlines()) if "test_psnr" in r]
    assert evals and all(r["test_psnr_on"] == "rgb" for r in evals)        # what the number compares, in the log



def test_a_densification_cap_below_the_initial_count_is_said(motion_scene, tmp_path):
    """Rooms started from 20k points under the quick recipes' 15k cap and never densified: said now."""
    import warnings

    import recon
    from common.config import ConfigWarning

    def said(cap):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            recon.fit(motion_scene, "d3dgs", overrides={"train.iterations": 2, "train.init.n_points_object": 60,
                                                        "train.densify.max_gaussians": cap},
                      out_dir=tmp_path / f"cap{cap}", progress=False)
        return [str(w.message) for w in caught if issubclass(w.category, ConfigWarning) and "max_gaussians" in str(w.message)]

    assert said(60) == ["train.densify.max_gaussians = 60 <= the 60 initial Gaussians: nothing is cloned or split until "
                        "pruning brings the count below it; raise max_gaussians or lower train.init.n_points_*"]
    assert said(61) == []


def test_frames_that_are_not_intensity_are_refused(tmp_path):
    """Alpha or depth channels were read as intensity, and a fully transparent PNG as white."""
    import cv2
    import OpenEXR

    from common.imageio import ImageReadError, read_exr, read_png_linear

    plane = np.full((4, 5), 0.5, np.float32)
    for names, words in ((("R", "G", "A"), "found A, G, R (alpha and depth are not intensity)"),
                         (("Z", "A"), "alpha and depth are not intensity"), (("Z",), "found Z")):
        p = tmp_path / f"{''.join(names)}.exr"
        with OpenEXR.File({"type": OpenEXR.scanlineimage}, {n: plane for n in names}) as f:
            f.write(str(p))
        with pytest.raises(ImageReadError, match=re.escape(words)):
            read_exr(p)
    p = tmp_path / "V.exr"
    with OpenEXR.File({"type": OpenEXR.scanlineimage}, {"V": plane}) as f:
        f.write(str(p))
    assert read_exr(p).shape == (4, 5)
    rgba = np.zeros((4, 5, 4), np.uint8)
    cv2.imwrite(str(tmp_path / "clear.png"), rgba)
    with pytest.raises(ImageReadError, match="transparent pixels"):
        read_png_linear(tmp_path / "clear.png")
    rgba[..., 3] = 255
    cv2.imwrite(str(tmp_path / "opaque.png"), rgba)
    assert read_png_linear(tmp_path / "opaque.png").shape == (4, 5, 3)


@pytest.mark.parametrize("field,value,words", [
    ("pos_threshold", 1e-6, "pos_threshold: expected a number >= threshold_min"),
    ("threshold_min", 1e-6, "threshold_min: expected a number >= 0.01"),
    ("shot_noise_rate_hz", 1e12, "shot_noise_rate_hz: expected at most 100000 events per second per pixel"),
])
def test_sensor_values_that_would_exhaust_memory_are_refused_naming_the_field(field, value, words):
    from common.config import ConfigError
    from simulator import SimulatorConfig

    with pytest.raises(ConfigError, match=re.escape(words)):
        SimulatorConfig(**{field: value})


def test_a_camera_too_large_to_render_is_refused_naming_the_fields():
    from common.config import ConfigError
    from scene_format.config import RenderConfig

    with pytest.raises(ConfigError, match="width, height: 100000 x 100000 is more than"):
        RenderConfig(width=100000, height=100000)


def test_check_compares_the_manifests_counts_with_the_files(motion_scene, tmp_path, capsys):
    import json
    import shutil

    scene = tmp_path / motion_scene.name
    shutil.copytree(motion_scene, scene)
    assert cli(["check", scene], capsys)[0] == 0
    m = json.loads((scene / "manifest.json").read_text())
    m["counts"]["events_per_camera"][0] += 7
    m["counts"]["kept_frames_per_camera"] = 1
    (scene / "manifest.json").write_text(json.dumps(m))
    capsys.readouterr()
    assert main(["check", str(scene)]) == 1
    out = capsys.readouterr().out
    assert f"counts.events_per_camera[0] is {m['counts']['events_per_camera'][0]}, events/cam0.h5 holds" in out
    assert "counts.kept_frames_per_camera is 1, rgb/cam0 has" in out


# -- the second trial's batch ------------------------------------------------------------------------
def test_event_files_whose_attributes_disagree_with_their_events_are_refused(tmp_path, capsys):
    import h5py

    from eventio.events import EventStream, make_events
    from eventio.h5io import write_events

    for attr, value, words in (("t_end_us", 100, "t_end_us = 100 us is before the last event (900 us)"),
                               ("n_events", 2, "n_events = 2 but the file holds 3 events")):
        path = tmp_path / f"{attr}.h5"
        write_events(path, EventStream(make_events([0, 400, 900], [1, 2, 3], [1, 1, 1], [1, -1, 1]), 8, 4))
        rc, err = cli(["draw-events", path, "--out", tmp_path / f"{attr}_ok.png"], capsys)
        assert rc == 0, err                                      # as written, the file is consistent
        with h5py.File(path, "r+") as f:
            f.attrs[attr] = value
        rc, err = cli(["draw-events", path, "--out", tmp_path / f"{attr}.png"], capsys)
        assert rc == 1 and words in err and str(path) in err and not (tmp_path / f"{attr}.png").exists()


def test_paths_of_the_wrong_kind_are_named_for_what_they_are(tmp_path, capsys):
    (tmp_path / "f.txt").write_text("x")
    for cmd in ("check", "masks"):
        rc, err = cli([cmd, tmp_path / "nowhere"], capsys)
        assert rc == 1 and "no such folder" in err and "manifest" not in err
        rc, err = cli([cmd, tmp_path / "f.txt"], capsys)
        assert rc == 1 and "a file, not a folder" in err
        (tmp_path / "empty").mkdir(exist_ok=True)
        rc, err = cli([cmd, tmp_path / "empty"], capsys)
        assert rc == 1 and "empty: no manifest.json in it or in its sub-folders" in err
    rc, err = cli(["dataset", "--scene-file", tmp_path / "missing.glb", "--out", tmp_path / "d"], capsys)
    assert rc == 1 and "missing.glb: no such file" in err and not (tmp_path / "d").exists()


def test_model_and_weight_files_torch_cannot_read_get_one_short_line(tmp_path, capsys, motion_scene):
    from recon.model import load

    garbage, truncated = tmp_path / "g.pt", tmp_path / "t.pt"
    garbage.write_text("garbage\n")
    import torch

    torch.save({"a": torch.zeros(1000)}, truncated)
    truncated.write_bytes(truncated.read_bytes()[:300])
    for f, words in ((garbage, "Unsupported operand"), (truncated, "failed reading zip archive")):
        with pytest.raises(ValueError) as info:
            load(f)
        msg = str(info.value)
        assert msg.startswith(f"{f}: cannot read it as a model file") and words in msg
        assert "weights_only" not in msg and "\n" not in msg and len(msg) < 300
    rc, err = cli(["e2vid", motion_scene / "events" / "cam0.h5", "--out", tmp_path / "v",
                   "--weights", garbage], capsys)
    assert rc == 1 and "cannot read it as E2VID / FireNet weights" in err and "weights_only" not in err
    unfinished = tmp_path / "run"
    unfinished.mkdir()
    (unfinished / "checkpoint.pt").write_bytes(b"")
    rc, err = cli(["render", unfinished, "--camera", "0", "--t", "0.5", "--out", tmp_path / "r"], capsys)
    assert rc == 1 and "has not finished" in err and "run the same `e4dgs train` again" in err
    rc, err = cli(["render", unfinished, "--camera", "0", "--t", "0.5", "--out", garbage], capsys)
    assert rc == 1 and "an existing file; expected a folder" in err


def test_api_misuse_says_what_was_expected(motion_scene, tmp_path):
    from recon.api import fit

    model = fit(motion_scene, "d3dgs", out_dir=tmp_path / "m", progress=False,
                overrides={"train.iterations": 2, "train.scale_schedule": False, "train.densify.enabled": False,
                           "train.init.n_points_object": 50, "train.snapshots": []}).model
    for t, words in ((np.array([0.1, 0.2]), "of shape (2,)"), ("half", "got str 'half'")):
        with pytest.raises(ValueError, match=r"time: expected one number in \[0, 1\]") as info:
            model.render(0, t)
        assert words in str(info.value)
    for camera in ([0, 1], 0.5, None):
        with pytest.raises(ValueError, match="camera: expected a Camera"):
            model.render(camera, 0.5)
    assert model.render(np.int64(1), np.float32(0.5)).shape == (48, 64, 3)     # numpy scalars are fine


def test_config_errors_blame_the_source_that_made_them(tmp_path):
    import recon
    from common.config import ConfigError

    recipe = ROOT / "configs" / "recipes" / "d3dgs" / "mlp.yaml"
    with pytest.raises(ConfigError) as info:                     # the file is fine, the --set is not
        recon.resolve_config("d3dgs", recipe, {"train.lr.nosuch": 1})
    assert str(info.value).startswith("--set: train.lr.nosuch: unknown key")
    with pytest.raises(ConfigError) as info:                     # a section's own check: its key once
        recon.resolve_config("d3dgs", recipe, {"train.lr.feature": -1})
    assert str(info.value) == "--set: train.lr.feature: expected a learning rate >= 0, got -1.0"
    bad = tmp_path / "bad.yaml"
    bad.write_text("train:\n  lr:\n    feature: abc\n")
    with pytest.raises(ConfigError) as info:                     # the file is wrong whatever --set says
        recon.resolve_config("d3dgs", bad, {"train.iterations": 5})
    assert str(info.value).startswith(f"{bad}: train.lr.feature: expected a number")
    from benchmark.config import BenchConfig, CellSpec
    from benchmark.grid import jobs
    from common.config import build_config

    cfg = build_config(BenchConfig, {"scenes": ["s"], "cells": {"a": CellSpec("d3dgs", overrides={"train.nosuch": 1})}})
    with pytest.raises(ConfigError) as info:
        next(j for j in jobs(cfg)).method_config
    assert "the preset's overrides of this job" in str(info.value) and "--set" not in str(info.value)


def test_simulate_names_a_frame_rate_beyond_microseconds_and_an_output_under_a_file(frames, tmp_path, capsys):
    rc, err = cli(["simulate", frames, "--fps", "1e9", "--out", tmp_path / "e.h5"], capsys)
    assert rc == 1 and "less than 1 us apart" in err and "timestamps must increase" not in err
    (tmp_path / "note.txt").write_text("x")
    out = tmp_path / "note.txt" / "sub" / "e.h5"
    rc, err = cli(["simulate", frames, "--fps", "1000", "--out", out], capsys)
    assert rc == 1 and "note.txt is not a folder" in err and "File exists" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames", "note.txt"]
    rc, err = cli(["simulate", frames, "--fps", "1e6", "--out", tmp_path / "ok.h5"], capsys)
    assert rc == 0, err                                        # 1 us apart is still whole microseconds


def test_camera_poses_must_be_rigid_in_every_reader(tmp_path):
    """A rotation scaled by 2, a reflection or a projective last row is refused (render --camera, the
    API and a dataset's cameras.json), naming what is wrong and the tolerance."""
    import json

    from recon.render import camera_from_pose
    from scene_format.cameras import RIGID_TOL, load_cameras, rigid_pose_problem

    K = np.array([[60.0, 0, 32], [0, 60, 24], [0, 0, 1]])
    scaled, mirrored, projective = np.eye(4), np.eye(4), np.eye(4)
    scaled[:3, :3] *= 2
    mirrored[0, 0] = -1
    projective[3, 0] = 0.5
    nearly = np.eye(4)
    nearly[:3, :3] *= 1 + 0.1 * RIGID_TOL                      # within the tolerance: accepted
    assert rigid_pose_problem(nearly) is None and rigid_pose_problem(np.stack([np.eye(4)] * 3)) is None
    for pose, words in ((scaled, "not orthonormal"), (mirrored, "reflection"), (projective, "last row")):
        with pytest.raises(ValueError, match=f"{words}.*rigid to within"):
            camera_from_pose(K, pose, 64, 48)
    # a dataset's cameras.json: the camera and the pose index are named
    poses = np.stack([np.eye(4), scaled])
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps({"intrinsics": {"width": 64, "height": 48, "fx": 60.0, "fy": 60.0, "cx": 32.0, "cy": 24.0},
                                "cameras": [{"timestamps_us": [0, 10], "c2w_opencv": poses.tolist()}]}))
    with pytest.raises(ValueError, match=r"cameras\[0\]\.c2w_opencv: its rotation is not orthonormal .*pose 1"):
        load_cameras(path)


def test_seeds_scene_lists_and_frame_names_that_cannot_be_meant_are_refused(tmp_path, capsys):
    import cv2

    frames = tmp_path / "frames"
    frames.mkdir()
    for name in ("frame9", "frame10", "frame_a", "frame_b"):
        cv2.imwrite(str(frames / f"{name}.png"), np.full((8, 8), 128, np.uint8))
    rc, err = cli(["simulate", frames, "--fps", "3000", "--out", tmp_path / "ev.h5"], capsys)
    assert rc == 1 and "frame10.png ends in a frame number but frame_a.png does not" in err
    assert not (tmp_path / "ev.h5").exists()
    for args, words in ((["simulate", str(frames), "--fps", "3000", "--out", str(tmp_path / "ev.h5"),
                          "--seed", "99999999999999999999999"], "--seed: expected an integer seed in 0 .. 9223372036854775807"),
                        (["simulate", str(frames), "--fps", "3000", "--out", str(tmp_path / "ev.h5"),
                          "--seed", "-1"], "--seed: expected an integer seed"),
                        (["dataset", "--preset", "tiny", "--scenes", "", "--out", str(tmp_path / "d")],
                         "--scenes: expected one or more comma-separated names"),
                        (["dataset", "--preset", "tiny", "--scenes", " , ", "--out", str(tmp_path / "d")],
                         "--scenes: expected one or more"),
                        (["bench", "--preset", "tiny", "--scenes", "cubes,,x", "--out", str(tmp_path / "b")],
                         "--scenes: a blank name between commas"),
                        (["bench", "--preset", "tiny", "--cells", "", "--out", str(tmp_path / "b")], "--cells: expected")):
        rc, err = cli(args, capsys)
        assert rc == 2 and words in err, (args, err)
    assert not (tmp_path / "d").exists() and not (tmp_path / "b").exists()


def test_check_names_an_unfinished_scene_and_folders_that_are_not_scenes(motion_scene, tmp_path, capsys):
    import shutil

    root = tmp_path / "root"
    shutil.copytree(motion_scene, root / "a")
    shutil.copytree(motion_scene, root / "b")
    (root / "b" / "manifest.json").unlink()              # a generation that did not finish
    (root / "logs").mkdir()                              # not a scene at all
    def check(path):
        try:
            rc = main(["check", str(path)])
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
            print(exc.code, file=sys.stderr)
        captured = capsys.readouterr()
        return rc, captured.out + captured.err
    rc, out = check(root)
    assert rc == 1 and f"{root / 'a'}: OK" in out and f"{root / 'b'}: not a finished scene: no manifest.json" in out
    assert f"{root / 'logs'}: skipped, not a scene folder" in out
    shutil.rmtree(root / "b")
    rc, out = check(root)
    assert rc == 0 and "not a finished scene" not in out
    rc, out = check(root / "logs")       # a folder with nothing of a dataset: refused as before
    assert rc == 1 and "no manifest.json in it or in its sub-folders" in out


def test_numbers_that_overflow_or_are_infinite_are_refused_by_name():
    import recon
    from common.config import ConfigError
    from eventio.representations import parse_time_us

    for text in ("1e400", "-1e400", "1e13s"):
        with pytest.raises(ValueError, match="out of range"):
            parse_time_us(text)
    assert parse_time_us("-5ms") == -5000
    for key, value in (("train.lr.position_init", float("inf")), ("train.lr.scaling", float("nan")),
                       ("train.lr.feature", 10 ** 400)):
        with pytest.raises(ConfigError, match=f"{key.split('.')[-1]}: expected a finite number"):
            recon.resolve_config("d3dgs", overrides={key: value})


def test_an_output_inside_its_input_is_refused(motion_scene, tmp_path, capsys):
    """train --out into the scene folder, bench / score --out into the dataset: refused before any write."""
    import recon

    before = sorted(p.relative_to(motion_scene) for p in Path(motion_scene).rglob("*"))
    for out in (motion_scene, Path(motion_scene) / "run"):
        rc, err = cli(["train", motion_scene, "--out", out, "--set", "train.iterations=2"], capsys)
        assert rc == 1 and (("inside the scene folder" in err and "choose another folder" in err)
                            or f"is also SCENE {motion_scene}" in err or f"lies inside SCENE {motion_scene}" in err), err
        with pytest.raises(ValueError, match="out_dir: .*inside the scene folder"):
            recon.fit(motion_scene, "d3dgs", overrides={"train.iterations": 2}, out_dir=out, progress=False)
    root = Path(motion_scene).parent
    rc, err = cli(["bench", "--preset", "tiny", "--data", root, "--out", root / "results"], capsys)
    assert rc == 1 and "inside --data" in err
    rc, err = cli(["score", "--data", root, tmp_path, "--name", "x", "--inputs", "rgb",
                   "--out", tmp_path / "r"], capsys)
    assert rc == 1 and "inside RENDERS" in err
    assert sorted(p.relative_to(motion_scene) for p in Path(motion_scene).rglob("*")) == before
    assert not (root / "results").exists() and not (tmp_path / "r").exists()


def test_a_sliding_window_video_shows_the_last_events():
    """`e4dgs draw-events --window 5ms` on a 19.7 ms stream: four frames, the last one ending at the stream's end."""
    from eventio.representations import window_starts

    assert window_starts(0, 19_700, 5000, 5000) == [0, 5000, 10_000, 14_700]
    assert window_starts(0, 20_000, 5000, 5000) == [0, 5000, 10_000, 15_000]
    assert window_starts(0, 3000, 5000, 5000) == [0]                   # a window longer than the stream
    assert window_starts(100, 10_100, 4000, 2000) == [100, 2100, 4100, 6100]


def test_a_real_full_disk_names_the_file_and_leaves_no_partial_output(motion_scene, tmp_path, capsys):
    """e4dgs e2vid onto a 12 KiB tmpfs: one line naming the file being written, and no partial PNGs."""
    small = tmp_path / "small"
    small.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=12k", "tmpfs", str(small)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode(errors='replace').strip()}")
    try:
        rc, err = cli(["e2vid", Path(motion_scene) / "events" / "cam0.h5", "--out", small / "video"], capsys)
        assert rc == 1 and "No space left on device" in err and str(small / "video") in err, err
        assert list(small.iterdir()) == []
    finally:
        subprocess.run(["umount", str(small)], check=True)


def test_check_names_files_the_manifest_does_not_list(motion_scene, tmp_path, capsys):
    import shutil

    scene = tmp_path / "scene"
    shutil.copytree(motion_scene, scene)
    (scene / "testviews.json").write_text("{}")
    (scene / "rgb" / "extra.png").write_bytes(b"x")
    assert main(["check", str(scene)]) == 0
    out = capsys.readouterr().out
    assert f"{scene}: OK" in out and "note: 2 file(s) the manifest does not list, not verified: rgb/extra.png, testviews.json" in out


def test_a_shipped_config_is_found_from_any_folder_and_by_name(tmp_path, monkeypatch):
    import recon
    from common.config import ConfigError

    monkeypatch.chdir(tmp_path)                     # outside the checkout
    repo = Path(__file__).resolve().parents[2]
    by_path = recon.resolve_config("d3dgs", "configs/recipes/d3dgs/mlp.yaml")
    assert by_path == recon.resolve_config("d3dgs", "d3dgs/mlp") and by_path.train.iterations == 1500
    # `quick` with a method is that method's leaderboard recipe
    for method in ("d3dgs", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb"):
        assert recon.resolve_config(method, "quick") == recon.resolve_config(method, repo / f"configs/recipes/{method}/quick.yaml")
        assert recon.resolve_config(method, "quick") == recon.resolve_config(method, f"{method}/quick")
    assert recon.resolve_config("d3dgs", "d3dgs/mlp", overrides={"train.iterations": 7}).train.iterations == 7
    (tmp_path / "quick.yaml").write_text("train: {iterations: 3}\n")     # a file of the user's wins
    assert recon.resolve_config("d3dgs", "quick.yaml").train.iterations == 3
    with pytest.raises(ConfigError, match=r"nope: cannot read config file .*shipped: .*e4dgs/quick"):
        recon.resolve_config("d3dgs", "nope")


def test_config_integers_beyond_64_bits_are_refused_by_key():
    """The sibling of --seed 99999999999999999999999 in every config: a seed or count no generator or
    file can hold is refused naming the key."""
    import recon
    from common.config import ConfigError, from_dict
    from scene_format.config import SceneConfig

    with pytest.raises(ConfigError, match="train.seed: expected an integer within 64 bits, got one of 23 digits"):
        recon.resolve_config("d3dgs", overrides={"train.seed": 99999999999999999999999})
    with pytest.raises(ConfigError, match="seed: expected an integer within 64 bits"):
        from_dict(SceneConfig, {"name": "x", "kind": "object", "seed": 2 ** 64})
    assert recon.resolve_config("d3dgs", overrides={"train.seed": 2 ** 63 - 1}).train.seed == 2 ** 63 - 1


def test_shipped_configs_leave_densification_room_above_their_initial_points():
    """A cap at or below the initial count stops densification (garage never densified under the quick
    recipes' 15k cap and 20k room points). Every example config holds for objects and rooms; every
    bench preset's cell on each of its scenes, with the scene's overrides and the scene's kind."""
    import recon
    from benchmark.config import load_bench
    from benchmark.grid import jobs
    from datagen.config import scene_yaml_path
    from scene_format.config import read_scene_config

    repo = Path(__file__).resolve().parents[2]
    root = repo / "configs" / "recon"
    for path in sorted(root.glob("*.yaml")):
        t = recon.resolve_config(path.stem.removesuffix("_quick"), path).train
        assert t.densify.max_gaussians > max(t.init.n_points_object, t.init.n_points_room), path.name
    checked = set()
    for preset in sorted((repo / "configs" / "bench").glob("*.yaml")):
        for job in (j for j in jobs(load_bench(preset)) if j.study == "main"):    # every cell on every scene
            kind = read_scene_config(scene_yaml_path(job.scene)).kind
            t = job.method_config.train
            n0 = t.init.n_points_room if kind == "room" else t.init.n_points_object
            assert t.densify.max_gaussians > n0, (preset.name, job.scene, job.cell, t.densify.max_gaussians, n0)
            checked.add(kind)
    assert checked == {"object", "room"}
