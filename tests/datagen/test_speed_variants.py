"""Speed variants (datagen.speed): the time-compression construction checked against hand-solved
cases, on the generator end to end (Blender in subprocesses) and on its pure helpers."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common.config import ConfigError
from datagen.config import resolve_scene
from datagen.speed import check_interpolation, check_speeds, shutter_frames, variant_config
from scene_format.naming import split_variant, variant_name
from eventio.h5io import read_events

ROOT = Path(__file__).resolve().parents[2]
PAPER = str(ROOT / "configs" / "datasets" / "paper.yaml")


def generate(out, scene, preset, extra=()):
    cmd = [sys.executable, "-m", "datagen.generate", "--scene", scene, "--preset", preset, "--out", str(out),
           "--no-progress", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)


def _plane_yaml(tmp_path: Path, speeds: str) -> Path:
    text = (ROOT / "blender_scenes" / "blur_plane.yaml").read_text() + f"speeds: {speeds}\n"
    path = tmp_path / "plane.yaml"
    path.write_text(text)
    return path


def test_names_round_trip_and_frames_follow_speed():
    assert variant_name("garage", 4) == "garage_x4" and variant_name("garage", 2.5) == "garage_x2.5"
    assert split_variant("garage_x4") == ("garage", 4.0) and split_variant("rubiks_cube") == ("rubiks_cube", 1.0)
    assert split_variant(variant_name("mc_toy", 12.25)) == ("mc_toy", 12.25)
    # 2 ms at 3000 FPS is 6 rendered frames at speed 1 and 6 s frames at speed s
    assert [shutter_frames(2.0, 3000, s) for s in (1, 2, 4, 8.5)] == [6, 12, 24, 51]
    assert shutter_frames(0.1, 3000, 1) == 1


def test_variant_config_compresses_time_and_keeps_the_scene():
    cfg = resolve_scene("garage", {"speeds": {"factors": [1, 4], "exposure_ms": 2.0}})
    v = variant_config(cfg, 4)
    assert v.name == "garage" and v.speed == 4.0 and v.speeds.factors == ()
    assert v.blur.target_px == {} and v.blur.exposure_ms == {"shutter": 2.0}
    assert v.sensor == cfg.sensor and v.camera == cfg.camera and v.seed == cfg.seed
    assert v.real_duration_s == pytest.approx(cfg.duration_s / 4) and v.real_fps == 4 * cfg.render.fps


def test_speeds_out_of_reach_are_refused_naming_scene_and_speed():
    check_speeds("hinge", [1, 50], 2.0, 3000, 301)               # 300 frames fit in 301
    with pytest.raises(ConfigError, match=r"scene hinge, speed x64: the 2 ms exposure spans 384 rendered frames, "
                                          r"more than the clip's 301.*fastest speed this exposure allows is x50\.16"):
        check_speeds("hinge", [1, 64], 2.0, 3000, 301)
    check_interpolation("lego", [2, 4], 1.9, 2.0)
    with pytest.raises(ConfigError, match=r"scene lego, speeds x2, x4: the image moves 2\.50 px \(p90\) between "
                                          r"rendered frames, more than speeds.max_px_per_frame = 2 px"):
        check_interpolation("lego", [2, 4], 2.5, 2.0)
    with pytest.raises(ConfigError, match="factors: expected speed factors >= 1"):
        resolve_scene("garage", {"speeds": {"factors": [0.5]}})


def test_blur_of_a_sliding_board_grows_with_speed_as_solved_by_hand(tmp_path):
    """The board moves p = fx * v / (fps * Z) px per rendered frame at every speed (the frames are the
    same); a 1 ms shutter integrates n(s) = 3 s rendered frames at 3000 FPS * s, so its blur is
    (n(s) - 1) * p px: 2p, 5p, 11p, 23p at s = 1, 2, 4, 8."""
    from blender_scenes import blur_plane as B
    from scene_format.cameras import intrinsics_from_fov

    yaml_path = _plane_yaml(tmp_path, "{factors: [1, 2, 4, 8], exposure_ms: 1.0}")
    r = generate(tmp_path / "out", "blur_plane", PAPER, ["--scene-config", str(yaml_path)])
    assert r.returncode == 0, r.stderr
    cfg = resolve_scene("blur_plane", scene_file=yaml_path)
    p = intrinsics_from_fov(64, 48, 50.0).fx * (B.TRAVEL_M / cfg.duration_s) / (cfg.render.fps * B.FRONT_DEPTH_M)
    base = json.loads((tmp_path / "out" / "blur_plane" / "manifest.json").read_text())
    assert base["speed_variants"] == {f"x{s}": f"blur_plane_x{s}" for s in (1, 2, 4, 8)}
    for s in (1, 2, 4, 8):
        m = json.loads((tmp_path / "out" / f"blur_plane_x{s}" / "manifest.json").read_text())
        lv = m["blur"]["levels"]["shutter"]
        assert m["speed"]["factor"] == s and m["speed"]["exposure_ms"] == 1.0
        assert lv["n_frames"] == 3 * s and lv["exposure_ms"] == pytest.approx(1.0)
        assert lv["median_px"] == pytest.approx((3 * s - 1) * p, rel=2e-3)
        assert m["blur"]["px_per_frame"]["median"] == pytest.approx(p, rel=2e-3)   # unchanged by compression
        assert math.isfinite(lv["psnr_vs_sharp_db"]["median_db"])
        times = [c["timestamps_us"] for c in json.loads((tmp_path / "out" / f"blur_plane_x{s}" / "cameras.json")
                                                        .read_text())["cameras"]]
        assert times[0][-1] == round(cfg.duration_s * 1e6 / s)                 # the clip lasts duration / s
        assert (tmp_path / "out" / f"blur_plane_x{s}" / "preview" / "contact_sheet.png").exists()
    assert (tmp_path / "out" / "blur_plane" / "preview" / "speeds.png").exists()


def test_ideal_sensor_events_of_speed_s_are_speed_1_events_with_time_divided_by_s(tmp_path):
    """No time constant in the sensor: compressing time compresses the event times and changes nothing
    else (same pixels, polarities and order; times equal to t / s up to the whole-microsecond rounding)."""
    preset = tmp_path / "p.yaml"
    preset.write_text((ROOT / "configs" / "datasets" / "tiny.yaml").read_text()
                      + "  speeds: {factors: [1, 4, 7.5], exposure_ms: 0.3333, max_px_per_frame: 10.0}\n")
    r = generate(tmp_path / "out", "cubes", str(preset))
    assert r.returncode == 0, r.stderr
    ev1 = read_events(tmp_path / "out" / "cubes_x1" / "events" / "cam0.h5").events
    base = read_events(tmp_path / "out" / "cubes" / "events" / "cam0.h5").events
    assert len(ev1) > 1000 and np.array_equal(ev1, base)       # speed 1 is the scene's own stream
    pixel1 = ev1["y"].astype(np.int64) * 10_000 + ev1["x"]
    a = np.argsort(pixel1, kind="stable")                       # per pixel, in time order
    for s in (4, 7.5):
        ev = read_events(tmp_path / "out" / f"cubes_x{s:g}" / "events" / "cam0.h5").events
        assert len(ev) == len(ev1)
        b = np.argsort(ev["y"].astype(np.int64) * 10_000 + ev["x"], kind="stable")
        assert np.array_equal(pixel1[a], (ev["y"].astype(np.int64) * 10_000 + ev["x"])[b])
        assert np.array_equal(ev1["p"][a], ev["p"][b])
        # frame and event times are whole microseconds at both speeds: at most ~1 us of rounding each
        assert np.abs(ev["t"][b] - ev1["t"][a] / s).max() <= 2.0


def test_a_speed_beyond_the_clip_is_refused_and_writes_nothing(tmp_path):
    yaml_path = _plane_yaml(tmp_path, "{factors: [1, 20], exposure_ms: 1.0}")      # 60 frames > 31
    r = generate(tmp_path / "out", "blur_plane", PAPER, ["--scene-config", str(yaml_path)])
    assert r.returncode == 2, r.stderr
    assert "scene blur_plane, speed x20: the 1 ms exposure spans 60 rendered frames, more than the clip's 31" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


def test_a_render_too_coarse_for_the_interpolation_is_refused_and_writes_nothing(tmp_path):
    yaml_path = _plane_yaml(tmp_path, "{factors: [2], exposure_ms: 1.0, max_px_per_frame: 0.1}")
    r = generate(tmp_path / "out", "blur_plane", PAPER, ["--scene-config", str(yaml_path)])
    assert r.returncode == 2, r.stderr
    assert "scene blur_plane, speeds x2: the image moves" in r.stderr and "raise render.fps" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()
