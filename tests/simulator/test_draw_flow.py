"""`e4dgs draw-events --flow`: a scene's ground-truth flow drawn over an event window."""
import numpy as np

from e4dgs.cli import main
from eventio.representations import event_frame, overlay_flow


def test_arrows_start_at_the_pixel_centres_and_point_along_the_flow():
    from eventio import EventStream, empty_events

    frame = event_frame(EventStream(empty_events(), 16, 16))
    flow = np.zeros((16, 16, 2))
    flow[..., 0] = 3.0
    img = overlay_flow(frame, flow, np.ones((16, 16), bool), scale=4, step_px=8)
    ys, xs = np.nonzero(_green(img))
    assert len(ys) and np.all(np.minimum(np.abs(ys - 18), np.abs(ys - 50)) <= 4)   # rows of pixels 4 and 12 (+0.5) x 4
    assert xs.min() >= 4 * 4 - 1 and xs.max() <= (12 + 0.5 + 3) * 4 + 1            # from the centre to 3 px right
    none = overlay_flow(frame, flow, np.zeros((16, 16), bool), scale=4)
    assert not _green(none).any()


def _green(img: np.ndarray) -> np.ndarray:
    """Pixels of the arrows' green (anti-aliased over white or event colours)."""
    r, g, b = (img[..., c].astype(int) for c in range(3))
    return (g > r + 40) & (g > b + 40)


def test_the_command_draws_a_scenes_flow_and_refuses_one_of_another_size(gt_scene, tmp_path, capsys):
    events = gt_scene / "events" / "cam0.h5"
    flow = gt_scene / "ground_truth" / "flow" / "cam0" / "00001.png"
    assert main(["draw-events", str(events), "--t0", "1ms", "--t1", "2ms", "--flow", str(flow),
                 "--out", str(tmp_path / "a.png")]) == 0
    assert main(["draw-events", str(events), "--t0", "1ms", "--t1", "2ms", "--out", str(tmp_path / "b.png")]) == 0
    import cv2

    a, b = cv2.imread(str(tmp_path / "a.png")), cv2.imread(str(tmp_path / "b.png"))
    assert a.shape == b.shape and _green(a[..., ::-1]).sum() > 20 and not _green(b[..., ::-1]).any()
    np.savez(tmp_path / "small.npz", forward_px=np.zeros((4, 4, 2), np.float32), valid=np.ones((4, 4), bool))
    try:
        main(["draw-events", str(events), "--flow", str(tmp_path / "small.npz"), "--out", str(tmp_path / "c.png")])
    except SystemExit as exc:
        assert "--flow" in str(exc) and "4x4 pixels, the events 64x48" in str(exc)
    else:
        raise AssertionError("a flow of another size was drawn")
    assert not (tmp_path / "c.png").exists()


def test_huge_or_nan_flow_is_drawn_or_refused_clearly(tmp_path):
    """A flow far past the picture is drawn to its edge, a NaN arrow is skipped, and a flow file with NaN
    at a valid pixel is refused naming the file; an EXR given as a flow is refused, not OpenCV's error."""
    import pytest

    from common.flow import read_flow
    from eventio import EventStream, empty_events

    frame = event_frame(EventStream(empty_events(), 16, 16))
    flow = np.full((16, 16, 2), 1e12)
    flow[4, 4] = np.nan
    img = overlay_flow(frame, flow, np.ones((16, 16), bool), scale=2)
    assert _green(img).any()
    np.savez(tmp_path / "nan.npz", forward_px=flow.astype(np.float32), valid=np.ones((16, 16), bool))
    with pytest.raises(ValueError, match="nan.npz.*non-finite"):
        read_flow(tmp_path / "nan.npz")
    (tmp_path / "depth.exr").write_bytes(b"\x76\x2f\x31\x01" + b"\0" * 64)
    with pytest.raises(ValueError, match="depth.exr.*expected a DSEC-Flow 16-bit PNG"):
        read_flow(tmp_path / "depth.exr")
    with pytest.raises(ValueError, match="no such flow file"):
        read_flow(tmp_path / "none.png")


def test_plain_pictures_keep_their_scale(gt_scene, tmp_path):
    import cv2

    events = gt_scene / "events" / "cam0.h5"
    assert main(["draw-events", str(events), "--t0", "1ms", "--t1", "2ms", "--plain", "--scale", "4",
                 "--out", str(tmp_path / "p.png")]) == 0
    assert cv2.imread(str(tmp_path / "p.png")).shape[:2] == (48 * 4, 64 * 4)
