"""The viewer's panels show a scene's depth and flow beside its frames when it has ground truth."""
import numpy as np

from common.flow import depth_to_rgb, flow_to_rgb
from scene_format.reader import SceneDataset
from viewer.panels import ScenePanels


def test_depth_and_flow_panels_follow_the_frame_shown(gt_scene):
    d = SceneDataset(gt_scene)
    panels = ScenePanels(d)
    rec = panels.sharp_frame(1, 1500)
    shown = {p.title.split(",")[0].split(" ")[0]: p for p in panels.at(1, 1500, 500)}
    assert {"sharp", "events", "depth", "flow"} <= set(shown)
    gt = d.ground_truth(1, rec.index)
    assert np.array_equal(shown["depth"].image, depth_to_rgb(gt.depth_m))
    assert np.array_equal(shown["flow"].image, flow_to_rgb(gt.flow_px, gt.flow_valid))
    assert f"flow to frame {rec.index + 1}" in shown["flow"].title
    last = panels.sharp[1][-1]                       # the last kept frame has no later frame: its velocity
    titles = [p.title for p in panels.at(1, last.t_us, 500)]
    assert any(t.startswith("image velocity") for t in titles)
    panels.close()


def test_a_scene_without_ground_truth_shows_no_such_panels(motion_scene):
    panels = ScenePanels(SceneDataset(motion_scene))
    titles = [p.title for p in panels.at(0, 1000, 500)]
    assert not any(t.startswith(("depth", "flow", "image velocity")) for t in titles)
    panels.close()
