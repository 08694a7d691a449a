"""scene_format.manifest: the typed facts of a scene folder's manifest.json, and its naming."""
import json

import pytest

from scene_format.manifest import SceneManifest
from scene_format.naming import SHUTTER_LEVEL, split_variant, variant_name


def test_a_variants_facts_by_hand(tmp_path):
    (tmp_path / "dynamic").mkdir()
    (tmp_path / "dynamic" / "masks.json").write_text("{}")
    raw = {"scene": "garage", "counts": {"events_per_camera": [10, 30]}, "events_per_second_per_camera": [100, 300],
           "speed": {"factor": 4}, "blur": {"levels": {SHUTTER_LEVEL: {
               "n_frames": 24, "exposure_ms": 2.0, "median_px": 7.5, "p90_px": 9.0, "target_px": None,
               "per_camera": [{"median_px": 7.0}, {"median_px": 8.0}], "psnr_vs_sharp_db": {"median_db": 27.5}}}}}
    facts = SceneManifest.from_dict(raw, tmp_path)
    assert facts.speed == 4.0 and facts.has_masks and facts.mean_events_per_second == 200.0
    assert facts.shutter.n_frames == 24 and facts.shutter.per_camera_median_px == (7.0, 8.0)
    assert facts.shutter.psnr_vs_sharp_db == 27.5
    plain = SceneManifest.from_dict({"counts": {}}, tmp_path / "lego")
    assert plain.scene == "lego" and plain.speed == 1.0 and plain.shutter is None and not plain.has_masks
    assert plain.mean_events_per_second == 0


def test_the_generated_scenes_facts_are_its_manifests(motion_scene):
    from scene_format.reader import SceneDataset

    ds = SceneDataset(motion_scene)
    raw = json.loads((motion_scene / "manifest.json").read_text())
    facts = ds.facts
    assert facts.events_per_camera == tuple(raw["counts"]["events_per_camera"])
    assert list(facts.blur) == list(raw["blur"]["levels"])
    for name, level in facts.blur.items():
        assert level.median_px == raw["blur"]["levels"][name]["median_px"]
        assert level.exposure_ms == pytest.approx(raw["blur"]["levels"][name]["exposure_ms"])


@pytest.mark.parametrize("scene,speed,name", [("garage", 4.0, "garage_x4"), ("hinge", 31.6, "hinge_x31.6"),
                                              ("my_x_scene", 2.5, "my_x_scene_x2.5")])
def test_variant_names_round_trip(scene, speed, name):
    assert variant_name(scene, speed) == name and split_variant(name) == (scene, speed)
    assert split_variant(scene) == (scene, 1.0)
