"""The scene folder's reader: the frozen description reconstruction reads."""
import dataclasses

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
