"""The scene folder's reader: the frozen description reconstruction reads."""
import dataclasses
import re

import numpy as np
import pytest

from datagen.config import resolve_scene
from scene_format.reader import SceneDescription


def test_the_description_holds_what_reconstruction_reads_and_is_frozen():
    cfg = resolve_scene("garage", {"lighting": {"background": [0.5, 0.25, 2.0], "exposure": 0.8},
                                   "camera": {"radius": 3.5, "target": [0.1, -0.2, 1.0]}})
    d = SceneDescription.of(cfg)
    assert (d.name, d.kind) == ("garage", "room")
    assert d.background_linear == pytest.approx((0.4, 0.2, 1.0))          # colour x exposure, clipped to 1
    assert d.rig_target == (0.1, -0.2, 1.0) and d.rig_radius_m == 3.5
    assert d.blur_levels == tuple(cfg.blur.levels) and isinstance(d.blur_levels, tuple)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.kind = "object"
    assert all(isinstance(c, float) for c in d.background_linear) and np.isfinite(d.background_linear).all()


@pytest.mark.parametrize("edit,words", [
    (lambda t: t.update(frames=5), "frames: expected a list of frames, got int"),
    (lambda t: t["frames"][1].update(camera="0"), "frames[1].camera: expected a camera index, got '0'"),
    (lambda t: t["frames"][0].update(camera=9), "frames[0].camera: 9 is not one of the scene's"),
    (lambda t: t["frames"][0].pop("file_path"), "frames[0].file_path: expected a frame path, got None"),
    (lambda t: t["frames"].__setitem__(0, 7), "frames[0]: expected a mapping of its fields, got int"),
], ids=["frames-number", "camera-text", "camera-range", "no-file", "frame-number"])
def test_a_hand_edited_transforms_file_is_refused_naming_the_field(gt_scene, tmp_path, edit, words, capsys):
    """A number where a list belongs, a text where an index belongs: DatasetError from the reader and
    one line from the commands that read the split (testviews, train), never a TypeError."""
    import json
    import shutil

    from e4dgs.cli import main
    from scene_format.reader import DatasetError, SceneDataset

    scene = tmp_path / "data" / "cubes"
    shutil.copytree(gt_scene, scene)
    doc = json.loads((scene / "transforms_test.json").read_text())
    edit(doc)
    (scene / "transforms_test.json").write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match=re.escape(words)):
        SceneDataset(scene).frames("test")
    try:
        rc = main(["testviews", str(scene), "--out", str(tmp_path / "views")])
    except SystemExit as exc:
        rc, _ = 1, print(exc.code, file=__import__("sys").stderr)
    err = capsys.readouterr().err
    assert rc == 1 and words in err and "internal error" not in err, err


@pytest.mark.parametrize("folder", ["gray", "rgb"])
def test_a_training_frame_of_another_size_is_refused_when_loaded_naming_it(gt_scene, tmp_path, folder):
    """A gray or RGB frame of the wrong size fails where it is read (recon.dataset_views.load_frame),
    naming the file, not later where a loss meets it."""
    import shutil

    import cv2

    from recon.dataset_views import load_frame
    from scene_format.reader import DatasetError, SceneDataset

    scene = tmp_path / "cubes"
    shutil.copytree(gt_scene, scene)
    ds = SceneDataset(scene)
    rec = ds.frames("train")[0]
    path = rec.gray_path if folder == "gray" else rec.path
    cv2.imwrite(str(path), np.zeros((5, 7) if folder == "gray" else (5, 7, 3), np.uint8))
    with pytest.raises(DatasetError, match=re.escape(f"{path}: 7x5 pixels, the scene's cameras are 64x48")):
        load_frame(ds, rec, 1 if folder == "gray" else 3)
