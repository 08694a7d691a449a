"""The moving pixels' share of a scene's events (datagen.summary): the pure share and density ratio
solved by hand, and the scene-level figures on the tiny motion scene."""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from datagen.summary import density_ratio, event_share, moving_event_share, moving_event_table

ROOT = Path(__file__).resolve().parents[2]


def test_event_share_counts_the_events_on_masked_pixels():
    mask = np.zeros((4, 5), bool)
    mask[1, 2] = mask[3, 4] = True                    # 2 of 20 pixels
    x = np.array([2, 2, 4, 0, 1, 2])
    y = np.array([1, 1, 3, 0, 0, 2])                  # 3 of 6 events on the mask
    px, ev = event_share(x, y, mask)
    assert px == 0.1 and ev == 0.5
    assert event_share(x[:0], y[:0], mask) == (0.1, 0.0)


def test_density_ratio_is_one_for_uniform_events_and_grows_with_the_moving_events():
    assert math.isclose(density_ratio(0.15, 0.15), 1.0)
    # 10 % of the pixels with half the events: 5 events per moving pixel-share against 0.5 / 0.9
    assert math.isclose(density_ratio(0.1, 0.5), 5.0 / (0.5 / 0.9))
    assert density_ratio(0.1, 1.0) == math.inf
    assert math.isnan(density_ratio(0.0, 0.0))


def test_moving_event_share_of_a_scene(motion_scene):
    meta = json.loads((motion_scene / "dynamic" / "masks.json").read_text())
    moving_views = [v for v in meta["views"] if v["dynamic_fraction"] > 0]
    r = moving_event_share(motion_scene)
    assert r["views"] == len(moving_views) > 0
    assert math.isclose(r["pixel_share"], np.mean([v["dynamic_fraction"] for v in moving_views]), rel_tol=1e-3)
    assert 0.0 < r["event_share"] < 1.0 and r["events_per_view"] > 0
    assert r["density_ratio"] > 1.0                   # the cubes move against a static background: they fire more
    empty = moving_event_share(motion_scene, half_window_us=0)          # an empty window holds no events
    assert empty["events_per_view"] == 0 and empty["event_share"] == 0.0


def test_the_summary_tool_prints_the_moving_event_table(motion_scene):
    table = moving_event_table(motion_scene.parent)
    assert f"| {motion_scene.name} |" in table
    r = subprocess.run([sys.executable, "-m", "tools.dataset_summary", str(motion_scene.parent), "--moving-events"],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "events per moving / static pixel" in r.stdout
