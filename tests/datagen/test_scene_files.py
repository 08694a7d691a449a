"""Scenes from a user's file: a built-in scene saved to .blend and generated from the file gives the
same frames and events; the worked examples (an armature-rigged figure, a glTF asset) generate; bad
files are refused with one line naming the file, leaving nothing behind."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
TINY_PRESET = """scenes: [cubes]
overrides:
  duration_s: 0.01
  render: {width: 64, height: 48, samples: 5}
  camera: {n_cameras: 2}
  frames: {keep_every: 3, test_every: 2}
"""


def _run(args, cwd=ROOT):
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd)


def _bpy(script: str, tmp_path: Path) -> None:
    p = tmp_path / "make.py"
    p.write_text(script)
    r = _run([str(p)], cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]


SAVE_BUILTIN = """
from pathlib import Path
import bpy
from datagen import render as R
from scene_format.cameras import intrinsics_from_fov
from datagen.config import resolve_scene
cfg = resolve_scene("blur_plane", scene_file=Path(r"{root}") / "blender_scenes" / "blur_plane.yaml")
R.build_scene(cfg, intrinsics_from_fov(64, 48, 50.0))
for o in [o for o in bpy.data.objects if o.type == "CAMERA"]:
    bpy.data.objects.remove(o)
bpy.ops.wm.save_as_mainfile(filepath="board.blend")
"""


def test_a_builtin_scene_saved_to_blend_generates_the_same_frames_and_events(tmp_path):
    import h5py
    import yaml

    _bpy(SAVE_BUILTIN.format(root=ROOT), tmp_path)
    builtin = yaml.safe_load((ROOT / "blender_scenes" / "blur_plane.yaml").read_text())
    from_file = {**builtin, "name": "board", "source": {"file": "board.blend", "rig": "config"}}
    (tmp_path / "board.yaml").write_text(yaml.safe_dump(from_file))
    preset = tmp_path / "p.yaml"
    preset.write_text("scenes: [blur_plane]\n")
    r1 = _run(["-m", "datagen.generate", "--scene", "blur_plane", "--scene-config",
               str(ROOT / "blender_scenes" / "blur_plane.yaml"), "--preset", str(preset), "--out", str(tmp_path / "a"),
               "--no-progress"])
    r2 = _run(["-m", "e4dgs.cli", "dataset", "--scene-config", str(tmp_path / "board.yaml"), "--preset", str(preset),
               "--out", str(tmp_path / "b")])
    assert r1.returncode == 0 and r2.returncode == 0, r1.stderr[-1500:] + r2.stderr[-1500:]
    a, b = tmp_path / "a" / "blur_plane", tmp_path / "b" / "board"
    pngs = sorted(p.relative_to(a) for p in (a / "rgb").rglob("*.png"))
    assert pngs and all((a / p).read_bytes() == (b / p).read_bytes() for p in pngs)
    with h5py.File(a / "events" / "cam0.h5") as fa, h5py.File(b / "events" / "cam0.h5") as fb:
        assert len(fa["events/t"]) > 100
        for k in ("t", "x", "y", "p"):
            np.testing.assert_array_equal(fa[f"events/{k}"][:], fb[f"events/{k}"][:])
    ma, mb = (json.loads((d / "manifest.json").read_text())["blur"]["levels"] for d in (a, b))
    assert ma == mb


def test_the_worked_examples_generate(tmp_path):
    """examples/scenes/make_scenes.py: the armature-rigged walker (its skin deforms) and the glTF spinner."""
    r = _run([str(ROOT / "examples" / "scenes" / "make_scenes.py"), str(tmp_path / "files")])
    assert r.returncode == 0, r.stderr[-1500:]
    preset = tmp_path / "p.yaml"
    preset.write_text(TINY_PRESET)
    walker = tmp_path / "walker.yaml"
    walker.write_text("name: walker\nkind: object\nsource: {file: files/walker.blend}\n"
                      "render: {width: 64, height: 48}   # the targets are pixels at this size\n"
                      "blur: {target_px: {mild: 0.8, strong: 1.5}, max_exposure_ms: 4.0, sample_stride_px: 2}\n")
    r = _run(["-m", "e4dgs.cli", "dataset", "--scene-config", str(walker), "--scene-file",     # both, side by side
              str(tmp_path / "files" / "spinner.glb"), "--jobs", "2", "--preset", str(preset), "--out", str(tmp_path / "data")])
    assert r.returncode == 0, r.stderr[-2000:]
    assert "2 of 2 scene(s) done" in r.stdout and "blur levels" in r.stdout
    m = json.loads((tmp_path / "data" / "walker" / "manifest.json").read_text())
    assert set(m["blur"]["levels"]) == {"mild", "strong"} and m["counts"]["timestamps"] == 31
    assert all(abs(lv["median_px"] / lv["target_px"] - 1) < 0.15 for lv in m["blur"]["levels"].values())
    fractions = [v["dynamic_fraction"] for v in json.loads((tmp_path / "data" / "walker" / "dynamic" / "masks.json")
                                                           .read_text())["views"]]
    assert min(fractions) > 0.002                   # the figure moves in every view; the ground does not
    cfg = (tmp_path / "data" / "walker" / "scene.yaml").read_text()
    assert "frame_end: 49.0" in cfg and "fps: 24.0" in cfg
    assert (tmp_path / "data" / "spinner" / "manifest.json").exists()
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "spinner.glb").write_bytes((tmp_path / "files" / "spinner.glb").read_bytes())
    r = _run(["-m", "e4dgs.cli", "dataset", "--scene-file", str(tmp_path / "files" / "spinner.glb"), "--scene-file",
              str(tmp_path / "other" / "spinner.glb"), "--preset", str(preset), "--out", str(tmp_path / "data")])
    assert r.returncode != 0 and "spinner.glb: scene name 'spinner' is already taken" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    # The built-in tiny preset (64 x 48) takes both examples as the README writes them: the walker
    # YAML's 2 / 4 / 8 px (at the default 346 px width) scale to 64 / 346 of that, and the spinner,
    # with no targets of its own, has the preset's 2 / 4.5 / 9 px fitted to its reach.
    (tmp_path / "ex").mkdir()
    (tmp_path / "ex" / "walker.yaml").write_text((ROOT / "examples" / "scenes" / "walker.yaml").read_text())
    (tmp_path / "ex" / "out").symlink_to(tmp_path / "files")
    r = _run(["-m", "e4dgs.cli", "dataset", "--preset", "tiny", "--scene-config", str(tmp_path / "ex" / "walker.yaml"),
              "--scene-file", str(tmp_path / "files" / "spinner.glb"), "--out", str(tmp_path / "tiny")], cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    walker_levels = json.loads((tmp_path / "tiny" / "walker" / "manifest.json").read_text())["blur"]["levels"]
    assert walker_levels["strong"]["declared_target_px"] == pytest.approx(8.0 * 64 / 346)
    spinner_levels = json.loads((tmp_path / "tiny" / "spinner" / "manifest.json").read_text())["blur"]["levels"]
    assert spinner_levels["strong"]["declared_target_px"] == 9.0 and spinner_levels["strong"]["target_px"] < 9.0
    ratios = [lv["target_px"] / lv["declared_target_px"] for lv in spinner_levels.values()]
    assert max(ratios) - min(ratios) < 1e-9                                       # one factor: the ladder keeps its ratios
    for levels in (walker_levels, spinner_levels):                                # distinct, increasing exposures
        frames = [levels[k]["n_frames"] for k in ("mild", "medium", "strong")]
        assert frames == sorted(set(frames))
    assert "spinner: blur targets fitted to this scene and size" in r.stdout


STATIC = """
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
{body}
bpy.ops.wm.save_as_mainfile(filepath="{name}.blend")
"""
CUBE = "bpy.ops.mesh.primitive_cube_add(size=1.0)\n"


@pytest.mark.parametrize("kind", ["missing", "not-blender", "corrupt-blend", "corrupt-glb", "unsupported", "no-mesh",
                                  "no-animation", "empty-range", "out-of-view"])
def test_bad_scene_files_are_refused_in_one_line_leaving_nothing(tmp_path, kind):
    preset = tmp_path / "p.yaml"
    preset.write_text(TINY_PRESET)
    extra = []
    if kind == "missing":
        f, words = tmp_path / "nowhere.blend", "no such file"
    elif kind == "not-blender":
        f, words = tmp_path / "notes.blend", "not a Blender file"
        f.write_text("hello")
    elif kind == "corrupt-blend":
        f, words = tmp_path / "broken.blend", "Blender cannot read it"
        f.write_bytes(b"BLENDER-v500" + b"\x00" * 64)
    elif kind == "corrupt-glb":
        f, words = tmp_path / "broken.glb", "Blender cannot read it"
        f.write_bytes(b"glTF\x02\x00\x00\x00garbage")
    elif kind == "unsupported":
        f, words = tmp_path / "mesh.ply", "is not a format Blender imports headless"
        f.write_text("ply\n")
    elif kind == "no-mesh":
        _bpy(STATIC.format(body="", name="empty"), tmp_path)
        f, words = tmp_path / "empty.blend", "no mesh to render"
    elif kind == "no-animation":
        _bpy(STATIC.format(body=CUBE, name="still"), tmp_path)
        f, words = tmp_path / "still.blend", "nothing moves in frames 1 .. 250"
    elif kind == "empty-range":
        _bpy(STATIC.format(body=CUBE + "bpy.context.scene.frame_end = 1\n", name="flat"), tmp_path)
        f, words = tmp_path / "flat.blend", "empty frame range (1 .. 1)"
    else:                                   # the rig's cameras look away from the moving cube
        body = CUBE + ("o = bpy.context.active_object\no.keyframe_insert('location', frame=1)\n"
                       "o.location.x = 1.0\no.keyframe_insert('location', frame=20)\n")
        _bpy(STATIC.format(body=body, name="away"), tmp_path)
        cfg = tmp_path / "away.yaml"
        cfg.write_text("name: away\nkind: object\nsource: {file: away.blend, rig: config}\n"
                       "camera: {radius: 4.0, height: 1.0, target: [50.0, 50.0, 0.0]}\n")
        f, words, extra = tmp_path / "away.blend", "keeps only 0 % of the moving content in view", ["--scene-config", str(cfg)]
    args = ["-m", "e4dgs.cli", "dataset", "--preset", str(preset), "--out", str(tmp_path / "data")]
    r = _run(args + (extra or ["--scene-file", str(f)]))
    lines = [ln for ln in r.stderr.strip().splitlines() if ln.startswith("error")]
    assert r.returncode != 0 and len(lines) == 1 and words in lines[0] and f.name in lines[0], r.stderr[-1500:]
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").iterdir())


CAMS = """
import bpy, math
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_cube_add(size=1.0)
o = bpy.context.active_object
o.keyframe_insert('location', frame=1)
o.location.x = 0.5
o.keyframe_insert('location', frame=20)
bpy.context.scene.frame_end = 20
cam = bpy.data.objects.new("CamA", bpy.data.cameras.new("CamA"))
bpy.context.scene.collection.objects.link(cam)
cam.data.lens, cam.data.sensor_width = 30.0, 36.0
cam.location, cam.rotation_euler = (0.0, -5.0, 0.0), (math.pi / 2, 0.0, 0.0)
cam.keyframe_insert('location', frame=1)
cam.location = (1.0, -5.0, 0.0)
cam.keyframe_insert('location', frame=20)
bpy.ops.wm.save_as_mainfile(filepath="cams.blend")
"""


def test_the_files_own_cameras_film_it(tmp_path):
    """source.cameras: the file's animated camera, its lens, its poses in cameras.json (OpenCV axes);
    a camera name the file lacks is refused naming the file's cameras."""
    import math

    _bpy(CAMS, tmp_path)
    preset = tmp_path / "p.yaml"
    preset.write_text(TINY_PRESET)
    cfg = tmp_path / "cams.yaml"
    cfg.write_text("name: cams\nkind: object\nsource: {file: cams.blend, cameras: [CamA]}\n")
    r = _run(["-m", "e4dgs.cli", "dataset", "--scene-config", str(cfg), "--preset", str(preset),
              "--out", str(tmp_path / "data")])
    assert r.returncode == 0, r.stderr[-2000:]
    cams = json.loads((tmp_path / "data" / "cams" / "cameras.json").read_text())
    assert len(cams["cameras"]) == 1
    fx = cams["intrinsics"]["fx"]
    assert fx == pytest.approx(64 / 2 / math.tan(math.atan(36.0 / 60.0)), rel=1e-9)     # lens 30 mm on 36 mm
    c2w = np.array(cams["cameras"][0]["c2w_opencv"])
    np.testing.assert_allclose(c2w[0, :3, 3], [0.0, -5.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(c2w[-1, :3, 3], [1.0, -5.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(c2w[0, :3, 2], [0.0, 1.0, 0.0], atol=1e-6)          # looking along +y at the cube
    cfg.write_text("name: cams\nkind: object\nsource: {file: cams.blend, cameras: [CamB]}\n")
    r = _run(["-m", "e4dgs.cli", "dataset", "--scene-config", str(cfg), "--preset", str(preset),
              "--out", str(tmp_path / "other")])
    assert r.returncode != 0 and "no camera object 'CamB' (the file's cameras: CamA)" in r.stderr


def test_a_top_level_file_key_is_short_for_source_file(tmp_path):
    from common.config import ConfigError
    from datagen.config import resolve_scene

    long = tmp_path / "long.yaml"
    long.write_text("name: w\nkind: object\nsource: {file: w.blend, rig: config}\n")
    short = tmp_path / "short.yaml"
    short.write_text("name: w\nkind: object\nfile: w.blend\nsource: {rig: config}\n")
    assert resolve_scene("w", scene_file=short) == resolve_scene("w", scene_file=long)
    both = tmp_path / "both.yaml"
    both.write_text("name: w\nfile: a.blend\nsource: {file: b.blend}\n")
    with pytest.raises(ConfigError, match="file: given twice"):
        resolve_scene("w", scene_file=both)


EXPORT = """
import sys, bpy
sys.path.insert(0, r"{examples}")
import make_scenes
from pathlib import Path
make_scenes.spinner(Path("."))
bpy.ops.export_scene.fbx(filepath="spinner.fbx", bake_anim=True)
bpy.ops.wm.usd_export(filepath="spinner.usdc", export_animation=True)
bpy.ops.wm.alembic_export(filepath="spinner.abc", start=1, end=25)
bpy.ops.wm.obj_export(filepath="spinner.obj")
"""


def test_fbx_usd_and_alembic_scenes_generate_and_an_obj_without_animation_is_refused(tmp_path):
    """The glTF example exported by Blender to the other formats it imports headless: each becomes a
    complete dataset with the same rig; OBJ carries no animation, so it is refused as a still scene."""
    _bpy(EXPORT.format(examples=ROOT / "examples" / "scenes"), tmp_path)
    preset = tmp_path / "p.yaml"
    preset.write_text(TINY_PRESET)
    r = _run(["-m", "e4dgs.cli", "dataset", "--scene-file", str(tmp_path / "spinner.fbx"), "--scene-file",
              str(tmp_path / "spinner.usdc"), "--preset", str(preset), "--out", str(tmp_path / "a")], cwd=tmp_path)
    assert r.returncode != 0 and "already taken" in r.stderr                 # one stem, one folder
    rigs = []
    for ext in ("fbx", "usdc", "abc"):
        out = tmp_path / f"data_{ext}"
        r = _run(["-m", "e4dgs.cli", "dataset", "--scene-file", str(tmp_path / f"spinner.{ext}"), "--preset",
                  str(preset), "--out", str(out)], cwd=tmp_path)
        assert r.returncode == 0, (ext, r.stderr[-1500:])
        m = json.loads((out / "spinner" / "manifest.json").read_text())
        assert m["counts"]["timestamps"] == 31 and min(m["counts"]["events_per_camera"]) > 100
        rigs.append(next(ln for ln in r.stdout.splitlines() if "rig target" in ln).split("; ")[1])
    assert len(set(rigs)) == 1, rigs                                          # same bounds, same rig
    r = _run(["-m", "e4dgs.cli", "dataset", "--scene-file", str(tmp_path / "spinner.obj"), "--preset", str(preset),
              "--out", str(tmp_path / "data_obj")], cwd=tmp_path)
    assert r.returncode == 1 and "spinner.obj: nothing moves" in r.stderr


def test_a_scene_yamls_own_blur_targets_outlive_a_presets():
    """The tiny preset's 2 / 4.5 / 9 px targets are chosen for its cubes; a user's scene YAML that names
    its own targets keeps them under any preset, which still sizes the clip."""
    from datagen.config import load_preset
    from datagen.scene_file import own_scene_data

    tiny = load_preset("tiny")
    raw = {"name": "walker", "kind": "object", "file": "out/walker.blend",
           "blur": {"target_px": {"mild": 2.0, "medium": 4.0, "strong": 8.0}}}
    data = own_scene_data(raw, tiny.scene("walker"))
    s = 64 / 346                                    # written for the default width, rendered at the preset's
    assert data["blur"]["target_px"] == pytest.approx({"mild": 2.0 * s, "medium": 4.0 * s, "strong": 8.0 * s})
    assert data["blur"]["fit"] is True                           # written for another size: closest exposures
    assert data["blur"]["max_exposure_ms"] == 4.0 and data["duration_s"] == 0.004      # the rest is the preset's
    assert data["render"]["width"] == 64
    at_own_width = own_scene_data({**raw, "render": {"width": 64}}, tiny.scene("walker"))
    assert at_own_width["blur"]["target_px"] == {"mild": 2.0, "medium": 4.0, "strong": 8.0}
    assert not at_own_width["blur"].get("fit")                   # at their own size: exact, or refused
    plain = own_scene_data({"name": "spinner", "kind": "object"}, tiny.scene("spinner"))
    assert plain["blur"]["target_px"] == {"mild": 2.0, "medium": 4.5, "strong": 9.0}   # no targets of its own
    assert plain["blur"]["fit"] is True                                                  # ... so the preset's, fitted


def test_fit_targets_scales_the_ladder_to_the_longest_exposure_only_when_out_of_reach():
    from datagen.blur_geometry import fit_targets
    medians = np.array([0.0, 1.0, 2.0, 3.0, np.nan])          # exposures of 1..5 frames, the longest unmeasured
    targets = {"mild": 2.0, "medium": 4.5, "strong": 9.0}
    fitted, f = fit_targets(medians, targets, 0.15)
    assert f == pytest.approx(3.0 / 9.0) and fitted["strong"] == pytest.approx(3.0)
    assert fitted["mild"] / fitted["strong"] == pytest.approx(2.0 / 9.0)
    same, f1 = fit_targets(medians, {"mild": 1.0, "strong": 3.4}, 0.15)            # 3.4 <= 3 x 1.15: reachable
    assert f1 == 1.0 and same == {"mild": 1.0, "strong": 3.4}
    from common.config import ConfigError
    from datagen.blur_geometry import choose_exposures
    close = {"mild": 1.9, "medium": 2.1}                   # both closest to the 3-frame exposure (2 px)
    with pytest.raises(ConfigError, match="same exposure"):
        choose_exposures(medians, close, 0.15, 3000.0, "s", "the clip")
    got = choose_exposures(medians, close, 0.15, 3000.0, "s", "the clip", strict=False)
    assert [c.n_frames for c in got] == [3, 4]              # the stronger takes the closest longer one
    assert [c.n_frames for c in choose_exposures(medians, {"mild": 0.2}, 0.15, 3000.0, "s", "the clip",
                                                 strict=False)] == [2]          # a miss of 5x is not refused
