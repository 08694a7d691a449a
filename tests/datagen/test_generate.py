"""The dataset generator end to end on tiny scenes (Blender in subprocesses), and every scene builder."""
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from scene_format.cameras import load_cameras, project
from datagen.config import SCENE_NAMES, load_preset, resolve_scene
from common.imageio import read_exr, read_png_linear
from eventio.events import validate_events
from eventio.h5io import read_events, read_info
from simulator.pixel import linear_to_srgb

ROOT = Path(__file__).resolve().parents[2]


def generate(out, scene="cubes", preset="tiny", extra=(), **kw):
    cmd = [sys.executable, "-m", "datagen.generate", "--scene", scene, "--preset", preset, "--out", str(out),
           "--no-progress", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, **kw)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny")
    r = generate(out)
    assert r.returncode == 0, r.stderr
    return out / "cubes"


def test_tiny_scene_layout_is_complete(tiny):
    cfg = resolve_scene("cubes", load_preset("tiny").overrides)
    manifest = json.loads((tiny / "manifest.json").read_text())
    for name in ("scene.yaml", "cameras.json", "transforms_train.json", "transforms_test.json",
                 "preview/contact_sheet.png", "events/cam0.h5", "events/cam1.h5"):
        assert (tiny / name).is_file(), name
        assert name in manifest["files"]
    kept = len(range(0, cfg.n_timestamps, cfg.frames.keep_every))
    for k in range(2):
        for sub, ext in (("frames", "exr"), ("rgb", "png"), ("gray", "png")):
            assert len(list((tiny / sub / f"cam{k}").glob(f"*.{ext}"))) == kept
        for level in cfg.blur.levels:
            assert len(list((tiny / "blur" / level / f"cam{k}").glob("*.png"))) == kept
    assert manifest["counts"]["timestamps"] == cfg.n_timestamps == 13
    assert set(manifest["seconds"]) == {"blur_geometry", "render", "simulate", "write", "total"}
    assert not list(tiny.glob(".*"))  # no spool or checkpoint left behind
    train = json.loads((tiny / "transforms_train.json").read_text())
    test = json.loads((tiny / "transforms_test.json").read_text())
    assert len(train["frames"]) + len(test["frames"]) == 2 * kept
    assert all(f["index"] % cfg.frames.test_every == 0 for f in test["frames"])
    assert all(0.0 <= f["time"] <= 1.0 for f in train["frames"] + test["frames"])
    for f in test["frames"]:
        assert (tiny / (f["file_path"] + ".png")).exists() and (tiny / (f["gray_path"] + ".png")).exists()


def test_tiny_scene_events_are_valid_and_non_empty(tiny):
    for k in range(2):
        stream = read_events(tiny / "events" / f"cam{k}.h5")
        validate_events(stream.events, 64, 48)
        assert len(stream) > 1000 and {-1, 1} <= set(np.unique(stream.events["p"]).tolist())
        assert stream.events["t"].max() <= 4000
        info = read_info(tiny / "events" / f"cam{k}.h5")
        assert info["sim_pos_threshold"] == 0.2 and info["camera"] == k


def test_blurred_frames_are_the_mean_of_their_sharp_frames(tmp_path):
    # keep every rendered frame so the test can average them itself
    preset = tmp_path / "p.yaml"
    preset.write_text("scenes: [cubes]\noverrides:\n  duration_s: 0.004\n  render: {width: 64, height: 48, samples: 5}\n"
                      "  camera: {n_cameras: 1}\n  frames: {keep_every: 1, test_every: 4}\n"
                      "  blur: {target_px: {mild: 2.0, medium: 4.5, strong: 9.0}, max_exposure_ms: 4.0}\n")
    r = generate(tmp_path, preset=str(preset))
    assert r.returncode == 0, r.stderr
    d = tmp_path / "cubes"
    sharp = np.stack([read_exr(d / "frames" / "cam0" / f"{j:05d}.exr") for j in range(13)])
    chosen = json.loads((d / "manifest.json").read_text())["blur"]["levels"]
    for level in ("mild", "medium", "strong"):
        for e in json.loads((d / "blur" / level / "exposures.json").read_text()):
            first, last = round(e["first_frame_us"] * 3e-3), round(e["last_frame_us"] * 3e-3)
            assert last - first + 1 == e["n_frames"] == chosen[level]["n_frames"] > 1
            expected = linear_to_srgb(sharp[first:last + 1].astype(np.float64).mean(0))
            got = cv2.imread(str(d / "blur" / level / "cam0" / f"{e['index']:05d}.png"))[..., ::-1] / 255.0
            # 8-bit output and half-float sharp frames: within 1.5 grey levels
            assert np.abs(got - expected).max() <= 1.5 / 255


def test_tiny_preset_blur_levels_are_ordered_and_inside_the_clip(tiny):
    manifest = json.loads((tiny / "manifest.json").read_text())
    levels = manifest["blur"]["levels"]
    assert list(levels) == ["mild", "medium", "strong"]
    for key in ("target_px", "n_frames", "median_px", "p90_px"):
        values = [levels[name][key] for name in levels]
        assert values == sorted(values) and len(set(values)) == 3, key
    psnr = [levels[name]["psnr_vs_sharp_db"]["median_db"] for name in levels]
    assert psnr == sorted(psnr, reverse=True)       # more blur, further from the sharp frame
    for name, level in levels.items():
        assert abs(level["median_px"] / level["target_px"] - 1) <= manifest["blur"]["tolerance"]
        assert level["n_frames"] <= manifest["counts"]["timestamps"]
        for e in json.loads((tiny / "blur" / name / "exposures.json").read_text()):
            assert 0 <= e["first_frame_us"] <= e["center_us"] <= e["last_frame_us"] <= 4000
    assert len(manifest["events_per_second_per_camera"]) == 2


def test_blur_length_of_a_sliding_board_is_the_analytic_one(tmp_path):
    """A board slides sideways at constant speed before a fixed camera: every visible point moves
    fx * v / Z px per second, so an exposure of n rendered frames blurs fx * v * (n - 1) / (fps * Z) px."""
    from blender_scenes import blur_plane as B
    from scene_format.cameras import intrinsics_from_fov

    yaml_path = ROOT / "blender_scenes" / "blur_plane.yaml"
    r = generate(tmp_path, scene="blur_plane", preset=str(ROOT / "configs" / "datasets" / "paper.yaml"),
                 extra=["--scene-config", str(yaml_path)])
    assert r.returncode == 0, r.stderr
    cfg = resolve_scene("blur_plane", scene_file=yaml_path)
    fx = intrinsics_from_fov(64, 48, 50.0).fx
    px_per_frame = fx * (B.TRAVEL_M / cfg.duration_s) / (cfg.render.fps * B.FRONT_DEPTH_M)
    blur = json.loads((tmp_path / "blur_plane" / "manifest.json").read_text())["blur"]
    for name, level in blur["levels"].items():
        target = cfg.blur.target_px[name]
        n_best = min(range(2, 40), key=lambda n: abs(math.log((n - 1) * px_per_frame / target)))
        assert level["n_frames"] == n_best
        assert level["median_px"] == pytest.approx((n_best - 1) * px_per_frame, rel=2e-3)
        assert level["p90_px"] == pytest.approx(level["median_px"], rel=2e-3)
        assert level["per_camera"][0]["samples"] == 16 * 12 * 7      # every sample hits the board; 7 blurred frames
    assert blur["px_per_frame"]["median"] == pytest.approx(px_per_frame, rel=2e-3)


def test_blur_of_a_board_moved_by_a_shape_key_equals_the_rigid_boards(tmp_path):
    """blur_plane_deform moves blur_plane's board by a shape key (the object never moves): its surface
    points are tracked on the deforming mesh by triangle and barycentric coordinates, so every blur
    figure equals the rigidly moved board's, and every pixel is dynamic."""
    figures = {}
    for name in ("blur_plane", "blur_plane_deform"):
        r = generate(tmp_path, scene=name, preset=str(ROOT / "configs" / "datasets" / "paper.yaml"),
                     extra=["--scene-config", str(ROOT / "blender_scenes" / f"{name}.yaml")])
        assert r.returncode == 0, r.stderr
        m = json.loads((tmp_path / name / "manifest.json").read_text())
        figures[name] = {lv: (v["n_frames"], v["median_px"], v["p90_px"]) for lv, v in m["blur"]["levels"].items()}
        masks = json.loads((tmp_path / name / "dynamic" / "masks.json").read_text())
        assert all(v["dynamic_fraction"] == 1.0 for v in masks["views"])
    rigid, deform = figures["blur_plane"], figures["blur_plane_deform"]
    assert rigid.keys() == deform.keys()
    for lv in rigid:
        assert deform[lv][0] == rigid[lv][0]
        assert deform[lv][1:] == pytest.approx(rigid[lv][1:], rel=1e-3)


def test_a_mesh_whose_topology_changes_is_refused_naming_it_and_nothing_is_written(tmp_path):
    r = generate(tmp_path / "out", scene="blur_plane_topology", preset=str(ROOT / "configs" / "datasets" / "paper.yaml"),
                 extra=["--scene-config", str(ROOT / "blender_scenes" / "blur_plane_topology.yaml")])
    assert r.returncode != 0
    line = r.stderr.strip().splitlines()[-1]
    assert "part 'face' changes its mesh topology" in line and "scene blur_plane_topology" in line, r.stderr
    assert not (tmp_path / "out" / "blur_plane_topology").exists()


def test_a_blur_level_out_of_reach_is_refused_and_writes_nothing(tmp_path):
    bad = tmp_path / "plane.yaml"
    bad.write_text((ROOT / "blender_scenes" / "blur_plane.yaml").read_text().replace("strong: 9.0", "strong: 90.0"))
    r = generate(tmp_path / "out", scene="blur_plane", preset=str(ROOT / "configs" / "datasets" / "paper.yaml"),
                 extra=["--scene-config", str(bad)])
    assert r.returncode == 2, r.stderr
    assert "scene blur_plane, blur level strong: target 90 px cannot be reached" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


def test_cameras_project_world_points_where_blender_draws_them(tmp_path):
    from blender_scenes.calibration import MARKERS

    r = generate(tmp_path, scene="calibration", preset=str(ROOT / "configs" / "datasets" / "paper.yaml"),
                 extra=["--scene-config", str(ROOT / "blender_scenes" / "calibration.yaml")])
    assert r.returncode == 0, r.stderr
    d = tmp_path / "calibration"
    assert not (d / "blur").exists()  # no blur levels asked for: no blur buffers, no blur files
    cams = load_cameras(d / "cameras.json")
    frames = json.loads((d / "transforms_train.json").read_text())["frames"] + \
        json.loads((d / "transforms_test.json").read_text())["frames"]
    assert len(frames) == 3 * 3
    errors = []
    for f in frames:
        img = read_png_linear(d / (f["file_path"] + ".png"))
        cam = cams[f["camera"]]
        c2w = cam.pose_at(f["timestamp_us"])
        for channel, (name, (pos, _)) in enumerate(MARKERS.items()):
            c = img[..., channel]
            mask = (c > 0.5 * c.max()) & (c > 3 * np.delete(img, channel, axis=-1).max(-1))
            assert mask.sum() > 5, name
            v, u = np.nonzero(mask)
            centroid = np.array([u.mean() + 0.5, v.mean() + 0.5])  # pixel centres sample (u + 0.5, v + 0.5)
            uv, depth = project(cam.intrinsics.K, c2w, np.array([pos]))
            assert depth[0] > 0
            errors.append(np.abs(centroid - uv[0]).max())
    print(f"projection error: max {max(errors):.3f} px over {len(errors)} markers")
    assert max(errors) < 0.6


RESUME_PRESET = ("scenes: [cubes]\noverrides:\n  duration_s: 0.03\n  render: {width: 64, height: 48, samples: 1}\n"
                 "  camera: {n_cameras: 2}\n  frames: {keep_every: 10, test_every: 2}\n"
                 "  blur: {target_px: {mild: 1.0, medium: 2.5, strong: 5.0}, max_exposure_ms: 10.0}\n"
                 "  sensor: {shot_noise_rate_hz: 50.0, refractory_us: 40}\n"
                 "  speeds: {factors: [1, 3], exposure_ms: 1.0, max_px_per_frame: 10.0}\n")


def _killed_after_first_checkpoint(preset: Path, out: Path) -> Path:
    """Start generating the preset into `out` and SIGKILL it once its first checkpoint exists."""
    cmd = [sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset", str(preset),
           "--out", str(out), "--no-progress", "--checkpoint-every", "7"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ckpt = out / "cubes" / ".generate.ckpt.npz"
    deadline = time.time() + 120
    while not ckpt.exists() and proc.poll() is None and time.time() < deadline:
        time.sleep(0.005)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    return ckpt


def _same_files(a: Path, b: Path) -> list[str]:
    """Files whose SHA-256 differs between two generated roots (the scene and its speed variants)."""
    folders = sorted(p.parent.name for p in a.glob("*/manifest.json"))
    assert folders == sorted(p.parent.name for p in b.glob("*/manifest.json")) and len(folders) == 3
    differ = []
    for folder in folders:
        ma = json.loads((a / folder / "manifest.json").read_text())["files"]
        mb = json.loads((b / folder / "manifest.json").read_text())["files"]
        assert ma.keys() == mb.keys()
        differ += [f"{folder}/{k}" for k in ma if ma[k]["sha256"] != mb[k]["sha256"]]
    return differ


@pytest.mark.parametrize("render", ["", ", adaptive_px: 2.0, max_stride: 4"], ids=["every-frame", "adaptive"])
def test_killed_run_resumes_to_identical_files(tmp_path, render):
    """(adaptive: the resumed run renders the frame before its checkpoint again as the blend anchor of
    the frames it skips)"""
    preset = tmp_path / "p.yaml"
    preset.write_text(RESUME_PRESET.replace("samples: 1}", "samples: 1" + render + "}"))
    assert generate(tmp_path / "a", preset=str(preset)).returncode == 0
    ckpt = _killed_after_first_checkpoint(preset, tmp_path / "b")
    assert ckpt.exists(), "the run ended before its first checkpoint: nothing to resume"
    assert not (tmp_path / "b" / "cubes" / "manifest.json").exists()
    assert (tmp_path / "b" / "cubes" / ".generate.geometry.npz").exists()
    r = generate(tmp_path / "b", preset=str(preset))
    assert r.returncode == 0 and "resuming at timestamp" in r.stdout
    assert "from an earlier start" in r.stdout         # the geometry is not measured again
    assert _same_files(tmp_path / "a", tmp_path / "b") == []
    assert not list((tmp_path / "b").rglob(".generate.*"))        # checkpoint and geometry removed when complete


def test_a_checkpoint_whose_spool_is_lost_starts_over(tmp_path):
    preset = tmp_path / "p.yaml"
    preset.write_text(RESUME_PRESET)
    assert generate(tmp_path / "a", preset=str(preset)).returncode == 0
    ckpt = _killed_after_first_checkpoint(preset, tmp_path / "b")
    assert ckpt.exists()
    (tmp_path / "b" / "cubes" / "events" / ".cam1.h5.spool").unlink()
    r = generate(tmp_path / "b", preset=str(preset))
    assert r.returncode == 0 and "starting cubes over" in r.stdout and "resuming" not in r.stdout
    assert _same_files(tmp_path / "a", tmp_path / "b") == []
    assert not list((tmp_path / "b").rglob(".*.spool")) and not list((tmp_path / "b").rglob(".*.lock"))


def test_a_checkpoint_of_another_sensor_starts_over(tmp_path):
    """A checkpoint whose event sensors another config wrote (an older release's) is not resumed with
    a mismatched sensor, nor is it an error: the scene starts over, saying why, to the same files."""
    preset = tmp_path / "p.yaml"
    preset.write_text(RESUME_PRESET)
    assert generate(tmp_path / "a", preset=str(preset)).returncode == 0
    ckpt = _killed_after_first_checkpoint(preset, tmp_path / "b")
    assert ckpt.exists()
    with np.load(ckpt, allow_pickle=False) as z:
        state = {k: z[k] for k in z.files}
    config = json.loads(str(state["sim0__config"]))
    state["sim0__config"] = np.array(json.dumps({**config, "refractory_us": 41}, sort_keys=True))
    with open(ckpt, "wb") as fh:
        np.savez(fh, **state)
    r = generate(tmp_path / "b", preset=str(preset))
    assert r.returncode == 0 and "starting cubes over" in r.stdout and "resuming" not in r.stdout, r.stdout + r.stderr
    assert "camera 0 of cubes" in r.stdout
    assert _same_files(tmp_path / "a", tmp_path / "b") == []


def test_bad_config_or_scene_fails_clearly_and_writes_nothing(tmp_path):
    r = generate(tmp_path / "out", scene="kitchen")
    assert r.returncode == 2 and "unknown scene 'kitchen'" in r.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROOT / "blender_scenes" / "cubes.yaml").read_text() + "colour_grading: warm\n")
    r = generate(tmp_path / "out", extra=["--scene-config", str(bad)])
    assert r.returncode == 2 and "colour_grading: unknown key" in r.stderr and str(bad) in r.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", SCENE_NAMES)
def test_every_scene_builds_and_renders(name, tmp_path):
    code = (
        "import sys, numpy as np, importlib\n"
        "from datagen.config import resolve_scene\n"
        "from datagen import render as R\n"
        "from scene_format.cameras import intrinsics_from_fov\n"
        "from datagen.rig import rig_poses\n"
        f"cfg = resolve_scene('{name}', {{'render': {{'width': 48, 'height': 36, 'samples': 1}}}})\n"
        "R.reset_scene(); R.setup_render(cfg)\n"
        f"importlib.import_module('blender_scenes.{name}').build(cfg)\n"
        "cams = R.make_cameras(1, intrinsics_from_fov(48, 36, cfg.camera.fov_x_deg))\n"
        "R.set_time(0.5); R.set_pose(cams[0], rig_poses(cfg.camera, np.array([0.5]))[0, 0])\n"
        "img = R.ViewRenderer().render(cams[0])\n"
        "np.save(sys.argv[1], img)\n"
    )
    out = tmp_path / "img.npy"
    r = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    img = np.load(out)
    assert img.shape == (36, 48, 3) and np.all(np.isfinite(img)) and img.std() > 0.01


def test_dataset_reader_on_the_tiny_scene(tiny, tmp_path):
    from scene_format.reader import DatasetError, SceneDataset

    ds = SceneDataset(tiny)
    assert ds.n_cameras == 2 and ds.duration_us == 4000 and ds.intrinsics.width == 64
    train, test = ds.frames("train"), ds.frames("test")
    assert len(test) > 0 and all(f.index % ds.config.frames.test_every == 0 for f in test)
    img = ds.load_image(test[0].path)
    assert img.shape == (48, 64, 3) and 0 <= img.min() and img.max() <= 1
    assert ds.load_image(test[0].gray_path).shape == (48, 64)
    f = train[0]
    np.testing.assert_allclose(ds.pose(f.camera, f.t_us), ds.cameras[f.camera].c2w[f.t_us * 3 // 1000], atol=1e-9)
    blurred = ds.blurred_frames("strong")
    first, last = blurred[0].exposure_us
    assert first <= blurred[0].t_us <= last and blurred[0].path.exists()
    assert ds.event_file(1).exists()
    with pytest.raises(DatasetError, match="no blur level 'huge'"):
        ds.blurred_frames("huge")
    with pytest.raises(DatasetError, match="no manifest.json"):
        SceneDataset(tmp_path)


def test_dataset_command_prints_the_blur_levels_it_measured(tmp_path):
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "dataset", "--preset", "tiny", "--out", str(tmp_path)],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    levels = json.loads((tmp_path / "cubes" / "manifest.json").read_text())["blur"]["levels"]
    for name, level in levels.items():
        row = next(line for line in r.stdout.splitlines() if line.startswith(f"| cubes | {name} |"))
        assert f"{level['median_px']:.1f} / {level['p90_px']:.1f}" in row
        assert f"{level['psnr_vs_sharp_db']['median_db']:.1f}" in row


def _dnerf_style_load(basedir: str):
    """A loader written the way D-NeRF's load_blender_data and nerfstudio's D-NeRF parser are: the three
    split files beside each other, file_path + '.png' joined to the JSON's own folder, time per frame,
    camera_angle_x for the focal length."""
    import os

    import imageio.v2 as imageio

    out = {}
    for s in ("train", "val", "test"):
        with open(os.path.join(basedir, f"transforms_{s}.json")) as fp:
            meta = json.load(fp)
        imgs = [imageio.imread(os.path.join(basedir, frame["file_path"] + ".png")) for frame in meta["frames"]]
        poses = np.array([frame["transform_matrix"] for frame in meta["frames"]], np.float32)
        times = np.array([frame["time"] for frame in meta["frames"]], np.float32)
        focal = 0.5 * imgs[0].shape[1] / np.tan(0.5 * float(meta["camera_angle_x"]))
        out[s] = (np.stack(imgs), poses, times, focal)
    return out


def test_every_transforms_file_loads_with_a_dnerf_style_loader(tiny):
    """The scene folder and every blur level's folder are D-NeRF scenes as they are: the blurred
    training frames with the sharp held-out views, paths relative to each JSON's folder."""
    from scene_format.reader import SceneDataset

    root = _dnerf_style_load(str(tiny))
    ds = SceneDataset(tiny)
    assert len(root["train"][0]) == len(ds.frames("train")) and len(root["test"][0]) == len(ds.frames("test"))
    assert np.array_equal(root["val"][1], root["test"][1]) and root["test"][2][0] == 0.0
    for level in ds.blur_levels():
        blur = _dnerf_style_load(str(tiny / "blur" / level))
        assert len(blur["train"][0]) == len(ds.blurred_frames(level)) > 0
        np.testing.assert_array_equal(blur["test"][0], root["test"][0])          # the sharp held-out views
        assert blur["train"][3] == pytest.approx(root["train"][3])
        first = ds.blurred_frames(level)[0]
        assert first.path == tiny / "blur" / level / f"cam{first.camera}" / f"{first.index:05d}.png"


def test_scenes_written_before_paths_were_relative_to_their_json_still_read(tiny, tmp_path):
    """Older scenes gave blur levels' file_path relative to the scene folder: still read right."""
    import shutil

    from scene_format.reader import SceneDataset

    scene = tmp_path / tiny.name
    shutil.copytree(tiny, scene)
    level = SceneDataset(scene).blur_levels()[0]
    tf = scene / "blur" / level / "transforms_train.json"
    meta = json.loads(tf.read_text())
    for f in meta["frames"]:
        f["file_path"] = f"./blur/{level}/" + f["file_path"][2:]
    tf.write_text(json.dumps(meta))
    recs = SceneDataset(scene).blurred_frames(level)
    assert recs and all(r.path.exists() and r.path.parent.parent.name == level for r in recs)


def _d3dgs_camera(frame: dict, fovx: float, width: int, height: int, patched: bool):
    """A world-to-pixel map the way D3DGS's readCamerasFromTransforms builds its camera (older 3DGS
    code: T = -inv(M)[:3, 3], FovX / FovY swapped), or with the two-line patch docs/design/dataset.md gives."""
    matrix = np.linalg.inv(np.array(frame["transform_matrix"]))
    R = -np.transpose(matrix[:3, :3])
    R[:, 0] = -R[:, 0]
    T = -matrix[:3, 3]
    if patched:
        T[0] = -T[0]                                   # patch line 1
    focal = width / (2 * np.tan(fovx / 2))
    fovy = 2 * np.arctan(height / (2 * focal))
    FovY, FovX = (fovy, fovx) if patched else (fovx, fovy)     # patch line 2 (upstream: FovY = fovx; FovX = fovy)
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = R.T, T                   # getWorld2View2
    fx, fy = width / (2 * np.tan(FovX / 2)), height / (2 * np.tan(FovY / 2))

    def project(p):
        c = w2c[:3, :3] @ p + w2c[:3, 3]
        return np.array([fx * c[0] / c[2] + width / 2, fy * c[1] / c[2] + height / 2]) - 0.5   # ndc2Pix
    return project


def test_d3dgs_reader_misplaces_our_cameras_and_the_documented_patch_fixes_it(tiny):
    from scene_format.cameras import project
    from scene_format.reader import SceneDataset

    ds = SceneDataset(tiny)
    meta = json.loads((tiny / "transforms_train.json").read_text())
    w, h = ds.intrinsics.width, ds.intrinsics.height
    worst = {False: 0.0, True: 0.0}
    for frame in meta["frames"]:
        c2w = ds.pose(frame["camera"], frame["timestamp_us"])
        point = c2w[:3, 3] + 3.0 * c2w[:3, 2] + 0.4 * c2w[:3, 0] + 0.3 * c2w[:3, 1]    # in view, off-centre
        truth = project(ds.intrinsics.K, c2w, point[None])[0][0] - 0.5                # 3DGS: pixel centres at integers
        for patched in (False, True):
            got = _d3dgs_camera(frame, meta["camera_angle_x"], w, h, patched)(point)
            worst[patched] = max(worst[patched], float(np.abs(got - truth).max()))
    assert worst[True] < 1e-6 and worst[False] > 2.0


def test_a_preset_asking_for_formats_writes_them_beside_the_hdf5_and_check_verifies_them(tmp_path):
    """`formats:` in a preset: every camera as AEDAT4 and EVT 3.0 and the scene as a ROS bag under
    exports/, the same events as the canonical HDF5, listed in the manifest (SHA-256) so `check`
    verifies them; the fingerprint ignores the field, so a complete scene that gains a format gets
    only that export, without being generated again."""
    from eventio.formats import read_recording, same_events

    plain = tmp_path / "plain.yaml"
    plain.write_text((ROOT / "configs" / "datasets" / "tiny.yaml").read_text())
    assert generate(tmp_path / "d", preset=str(plain)).returncode == 0
    scene = tmp_path / "d" / "cubes"
    before = json.loads((scene / "manifest.json").read_text())
    asks = tmp_path / "formats.yaml"
    asks.write_text(plain.read_text().replace("overrides:\n", "overrides:\n  formats: [aedat4, evt3, rosbag]\n"))
    r = generate(tmp_path / "d", preset=str(asks))
    assert r.returncode == 0 and "complete, skipped" in r.stdout, r.stderr[-1500:]
    after = json.loads((scene / "manifest.json").read_text())
    assert after["config_sha256"] == before["config_sha256"] and after["created_unix"] == before["created_unix"]
    assert set(after["exports"]) == {"aedat4", "evt3", "rosbag"}
    assert after["exports"]["rosbag"] == ["exports/cubes.bag"]
    for k in range(2):
        ours = read_events(scene / "events" / f"cam{k}.h5")
        for fmt, ext in (("aedat4", "aedat4"), ("evt3", "raw")):
            rel = f"exports/{fmt}/cam{k}.{ext}"
            assert rel in after["exports"][fmt] and after["files"][rel]["bytes"] == (scene / rel).stat().st_size
            assert same_events(read_recording(scene / rel)[0], ours), rel
    for rel in after["exports"]["rosbag"]:
        assert rel in after["files"]
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "check", str(scene)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0 and "OK" in r.stdout, r.stdout + r.stderr
    (scene / "exports" / "evt3" / "cam1.raw").write_bytes(b"tampered")
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "check", str(scene)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "exports/evt3/cam1.raw" in (r.stdout + r.stderr)
    bad = tmp_path / "bad.yaml"
    bad.write_text(plain.read_text().replace("overrides:\n", "overrides:\n  formats: [aedat5]\n"))
    r = generate(tmp_path / "e", preset=str(bad))
    assert r.returncode == 2 and "formats: 'aedat5' is not an extra event format" in r.stderr
    assert not (tmp_path / "e").exists()
