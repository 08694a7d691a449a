"""common.frame_interpolation: the bilinear warp against its reference, the in-between frame of a
translation at every fraction, its end points, and the optical flow of a translating texture."""
import numpy as np
import pytest

from common.frame_interpolation import in_between, optical_flow, warp, warp_ref


def blob(x0: float, y0: float, shape=(40, 56)) -> np.ndarray:
    ys, xs = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    return (0.2 + 0.7 * np.exp(-((xs - x0) ** 2 + (ys - y0) ** 2) / (2 * 4.0 ** 2))).astype(np.float32)


def test_the_warp_equals_its_reference_inside_and_beyond_the_edges():
    rng = np.random.default_rng(0)
    image = rng.random((23, 31)).astype(np.float32)
    flow = (rng.normal(0, 6, (23, 31, 2))).astype(np.float32)        # many samples fall off the image
    # OpenCV rounds the sample position to 1/32 px: off by at most 1/64 of a neighbour difference (<= 1)
    np.testing.assert_allclose(warp(image, flow), warp_ref(image, flow), atol=1 / 64 + 1e-5)
    smooth = np.add.outer(np.arange(23.0), np.arange(31.0)).astype(np.float32) / 100   # slope 0.01 / px
    np.testing.assert_allclose(warp(smooth, flow), warp_ref(smooth, flow), atol=2 * 0.01 / 64 + 1e-6)
    assert np.array_equal(warp_ref(image, np.zeros((23, 31, 2), np.float32)), image)


def test_a_whole_pixel_shift_moves_the_image_by_that_many_pixels():
    image = np.arange(20, dtype=np.float32).reshape(4, 5)
    flow = np.zeros((4, 5, 2), np.float32)
    flow[..., 0] = 1.0                                               # sample one pixel to the right
    np.testing.assert_allclose(warp_ref(image, flow)[:, :4], image[:, 1:])
    np.testing.assert_allclose(warp_ref(image, flow)[:, 4], image[:, 4])   # clamped at the edge


@pytest.mark.parametrize("w", [0.0, 0.25, 0.5, 0.8, 1.0])
def test_a_translating_blob_is_at_w_times_its_displacement(w):
    d = np.array([6.0, -3.0], np.float32)
    a, b = blob(24, 20), blob(24 + d[0], 20 + d[1])
    f_ab = np.broadcast_to(d, a.shape + (2,)).copy()
    got = in_between(a, b, f_ab, -f_ab, w)
    np.testing.assert_allclose(got, blob(24 + w * d[0], 20 + w * d[1]), atol=0.02)


def test_the_end_points_are_the_frames_themselves():
    rng = np.random.default_rng(1)
    a, b = rng.random((6, 7)).astype(np.float32), rng.random((6, 7)).astype(np.float32)
    f = rng.normal(0, 2, (6, 7, 2)).astype(np.float32)
    assert np.array_equal(in_between(a, b, f, -f, 0.0), a) and np.array_equal(in_between(a, b, f, -f, 1.0), b)
    assert in_between(a, b, f, -f, 0.0) is not a                      # a copy, never the caller's frame
    with pytest.raises(ValueError, match=r"fraction must lie in \[0, 1\], got 1.5"):
        in_between(a, b, f, -f, 1.5)


def test_the_flow_of_a_translating_texture_is_its_displacement():
    rng = np.random.default_rng(2)
    import cv2

    tex = cv2.GaussianBlur(rng.random((80, 100)).astype(np.float32), (0, 0), 2.0)
    a, b = tex[10:70, 10:90], tex[10:70, 13:93]                     # b(x) = a(x + 3): a(x) = b(x - 3)
    f = optical_flow(a, b)
    inner = f[15:45, 20:60]
    np.testing.assert_allclose(np.median(inner[..., 0]), -3.0, atol=0.3)
    np.testing.assert_allclose(np.median(inner[..., 1]), 0.0, atol=0.3)


def test_frames_too_small_for_the_flow_are_named():
    with pytest.raises(ValueError, match="frames of 5 x 4 px are too small for DIS flow"):
        optical_flow(np.zeros((4, 5), np.float32), np.ones((4, 5), np.float32))
