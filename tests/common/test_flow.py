"""common.flow: DSEC-Flow PNGs, flow and depth pictures."""
import numpy as np
import pytest

from common.flow import decode_dsec_flow, depth_to_rgb, encode_dsec_flow, flow_to_rgb, read_flow
from common.imageio import write_png


def test_dsec_encoding_round_trips_to_half_a_step_and_refuses_what_does_not_fit():
    rng = np.random.default_rng(0)
    flow = rng.uniform(-250, 250, (6, 7, 2))
    valid = rng.random((6, 7)) > 0.3
    back, v = decode_dsec_flow(encode_dsec_flow(flow, valid))
    assert np.array_equal(v, valid) and np.abs(back - flow)[valid].max() <= 0.5 / 128
    assert np.all(back[~valid] == 0)
    with pytest.raises(ValueError, match="does not fit"):
        encode_dsec_flow(np.full((1, 1, 2), 300.0), np.ones((1, 1), bool))


def test_a_written_flow_png_reads_back_and_a_wrong_file_is_named(tmp_path):
    flow = np.zeros((4, 5, 2))
    flow[..., 0], flow[..., 1] = 1.25, -3.5
    valid = np.ones((4, 5), bool)
    valid[0, 0] = False
    write_png(tmp_path / "f.png", encode_dsec_flow(flow, valid))
    back, v = read_flow(tmp_path / "f.png")
    assert np.array_equal(v, valid) and np.allclose(back[valid], [1.25, -3.5])
    write_png(tmp_path / "g.png", np.zeros((4, 5, 3), np.uint8))
    with pytest.raises(ValueError, match="g.png: expected a DSEC-Flow 16-bit PNG"):
        read_flow(tmp_path / "g.png")
    np.savez(tmp_path / "h.npz", forward_px=flow.astype(np.float32), valid=valid)
    assert np.allclose(read_flow(tmp_path / "h.npz")[0], flow)


def test_the_colour_wheel_gives_direction_as_hue_and_speed_as_saturation():
    flow = np.array([[[4.0, 0.0], [0.0, 4.0], [-2.0, 0.0], [0.0, 0.0]]])
    rgb = flow_to_rgb(flow, np.array([[True, True, True, False]]))
    assert rgb[0, 0].tolist() == [255, 0, 0]                 # +x at full speed: red
    assert rgb[0, 2, 0] < rgb[0, 2, 1] == rgb[0, 2, 2]        # -x: cyan-ish, half saturated
    assert rgb[0, 3].tolist() == [0, 0, 0]                   # invalid: black


def test_depth_pictures_are_bright_near_dark_far_and_black_where_nothing_is_seen():
    rgb = depth_to_rgb(np.array([[1.0, 2.0, 0.0]], np.float32))
    assert rgb[0, 0].sum() > rgb[0, 1].sum() and rgb[0, 2].tolist() == [0, 0, 0]
