"""Scene YAMLs, presets and the blur bookkeeping (no Blender needed)."""
import numpy as np
import pytest

from datagen.blur import BlurStack, exposure_window
from datagen.config import SCENE_NAMES, load_preset, resolve_scene
from common.config import ConfigError


def test_every_scene_yaml_loads_with_every_preset():
    for preset in ("quick", "paper"):
        p = load_preset(preset)
        assert set(p.scenes) == set(SCENE_NAMES)
        for name in p.scenes:
            cfg = resolve_scene(name, p.overrides)
            assert cfg.name == name and cfg.kind in ("object", "room")
            assert cfg.render.width == 346 and cfg.render.height == 260 and cfg.render.fps == 3000
            assert cfg.camera.n_cameras == 6
    kinds = {name: resolve_scene(name).kind for name in SCENE_NAMES}
    assert [n for n, k in kinds.items() if k == "room"] == ["capsule", "restroom", "garage"]


def test_every_scene_declares_ordered_blur_levels_and_shake():
    for name in SCENE_NAMES:
        cfg = resolve_scene(name)
        assert cfg.blur.levels == ["mild", "medium", "strong"]
        px = [cfg.blur.target_px[level] for level in cfg.blur.levels]
        assert px == sorted(px) and cfg.camera.shake.rms_deg > 0
    for preset in ("tiny", "tiny_motion"):
        cfg = resolve_scene("cubes", load_preset(preset).overrides)
        assert cfg.blur.max_exposure_ms <= 1e3 * cfg.duration_s  # every candidate exposure fits in the clip


def test_preset_overrides_are_merged_into_the_scene():
    quick = resolve_scene("lego", load_preset("quick").overrides)
    full = resolve_scene("lego")
    assert quick.duration_s < full.duration_s and quick.camera == full.camera
    assert quick.n_timestamps == round(quick.duration_s * 3000) + 1


@pytest.mark.parametrize("text, words", [
    ("name: x\nkind: object\nfoo: 1\n", "foo: unknown key"),
    ("name: x\nkind: object\ncamera: {radius: 2, fov: 40}\n", "camera.fov: unknown key"),
    ("name: x\nkind: garden\n", "kind: expected one of"),
    ("name: x\nkind: object\nblur: {target_px: {mild: -1}}\n", "blur.target_px.mild"),
    ("name: x\nkind: object\nblur: {target_px: {mild: 5, medium: 5}}\n", "blur.target_px: two levels share"),
    ("name: x\nkind: object\nblur_ms: {mild: 2.0}\n", "blur_ms: unknown key"),
    ("name: x\nkind: object\ncamera: {shake: {rms_deg: 20}}\n", "camera.shake.rms_deg"),
    ("name: x\nkind: object\ncamera: {shake: {min_hz: 30, max_hz: 10}}\n", "camera.shake.max_hz"),
    ("name: x\nkind: object\nsensor: {pos_threshold: 0}\n", "sensor.pos_threshold"),
    ("name: x\nkind: object\nrender: {engine: workbench, samples: 7}\n", "render.samples"),
    ("name: x\nkind: object\nrender: {adaptive_px: -1}\n", "render.adaptive_px: expected 0"),
    ("name: x\nkind: object\nrender: {adaptive_px: 50}\n", "render.adaptive_px: expected 0"),
    ("name: x\nkind: object\nrender: {max_stride: 0}\n", "render.max_stride"),
    ("name: x\nkind: object\nformats: [aedat4, aedat4]\n", "formats: a format is named twice"),
    ("name: x\nkind: object\nformats: [h5]\n", "formats: 'h5' is not an extra event format"),
    ("name: x\nkind: object\nblur: {fit: maybe}\n", "blur.fit"),
])
def test_bad_scene_yaml_names_file_and_key(tmp_path, text, words):
    p = tmp_path / "scene.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError, match=words) as err:
        resolve_scene("x", scene_file=p)
    assert str(p) in str(err.value)


def test_unknown_scene_and_preset_are_clear_errors(tmp_path):
    with pytest.raises(ConfigError, match="unknown scene 'kitchen'"):
        resolve_scene("kitchen")
    with pytest.raises(ConfigError, match="unknown dataset preset 'huge'.*known presets"):
        load_preset("huge")
    bad = tmp_path / "p.yaml"
    bad.write_text("scenes: [lego, kitchen]\n")
    with pytest.raises(ConfigError, match="kitchen"):
        load_preset(bad)


def test_exposure_windows_stay_inside_the_clip():
    assert exposure_window(50, 15, 301) == (43, 57)
    assert exposure_window(0, 15, 301) == (0, 14)        # shifted, not shortened
    assert exposure_window(300, 15, 301) == (286, 300)
    assert exposure_window(5, 30, 12) == (0, 11)         # longer than the clip: the whole clip


def test_blur_stack_means_equal_numpy_means(rng):
    frames = rng.random((12, 4, 5, 3)).astype(np.float32)
    windows = {0: (0, 2), 1: (2, 7), 2: (9, 11)}
    stack = BlurStack(windows)
    done = {}
    for i, f in enumerate(frames):
        done.update(dict(stack.add(i, f)))
        if i == 5:  # checkpoint and restore half-way
            state = stack.state("b__")
            stack = BlurStack(windows)
            stack.load_state(state, "b__")
    assert set(done) == {0, 1, 2} and not stack.sums
    for key, (a, b) in windows.items():
        np.testing.assert_allclose(done[key], frames[a:b + 1].mean(0), rtol=1e-6)


@pytest.mark.parametrize("name", ["../../escaped", "a/b", ".hidden", "", "a\\b"])
def test_a_scene_name_must_be_a_plain_folder_name(name):
    """The scene is written to <out>/<name>: a name with a path in it would write outside --out."""
    from common.config import ConfigError, from_dict
    from scene_format.config import SceneConfig

    with pytest.raises(ConfigError, match="name: expected a folder name"):
        from_dict(SceneConfig, {"name": name, "kind": "object"})
    assert from_dict(SceneConfig, {"name": "hinge_x37.6", "kind": "object"}).name == "hinge_x37.6"


def test_a_scene_fingerprint_follows_its_config_not_the_release(monkeypatch):
    """A new release that writes the same files keeps every finished dataset; a folder written by 0.2
    (whose fingerprint hashed the release) is still recognised; another config is not."""
    import common
    from datagen.scene_folder import config_fingerprint, same_config

    cfg = resolve_scene("cubes", load_preset("tiny").overrides)
    before = config_fingerprint(cfg)
    monkeypatch.setattr(common, "__version__", "0.3.0")
    assert config_fingerprint(cfg) == before
    old = {"config_sha256": config_fingerprint(cfg, "0.2.0"), "versions": {"toolkit": "0.2.0"}}
    assert old["config_sha256"] != before and same_config(old, cfg) and same_config({"config_sha256": before}, cfg)
    other = resolve_scene("cubes", {**load_preset("tiny").overrides, "seed": 12345})
    assert config_fingerprint(other) != before and not same_config(old, other)
    assert not same_config({"config_sha256": before, "versions": {"toolkit": 7}}, other)
