"""E-4DGS building blocks: event count maps, the event loss and its hard cases, ESS windows read by
index, colour correction, and that every ablation switch changes what it says."""
import math

import numpy as np
import pytest
import torch

import recon
from scene_format.reader import SceneDataset
from recon import event_supervision as ev
from eventio.representations import count_image
from common.color_correction import correct_colors, fit_gain_offset
from recon.event_windows import EventSource
from recon.methods.e4dgs import E4DGS, PAPER_PIXELS
from eventio.h5io import read_events


def test_count_image_is_the_per_pixel_sum_of_polarities(rng):
    n = 5000
    x, y = rng.integers(0, 7, n), rng.integers(0, 5, n)
    p = rng.choice([-1, 1], n)
    cm = count_image(x, y, p, 7, 5)
    expected = np.zeros((5, 7))
    for xi, yi, pi in zip(x, y, p):
        expected[yi, xi] += pi
    np.testing.assert_array_equal(cm, expected)
    de, hits = ev.event_maps(x, y, p, 7, 5, c_pos=0.3, c_neg=0.1)
    pos = np.zeros((5, 7))
    neg = np.zeros((5, 7))
    np.add.at(pos, (y[p > 0], x[p > 0]), 1)
    np.add.at(neg, (y[p < 0], x[p < 0]), 1)
    np.testing.assert_allclose(de, 0.3 * pos - 0.1 * neg)
    np.testing.assert_array_equal(hits, (pos + neg) > 0)
    # an empty window: zeros, nothing triggered
    de0, hits0 = ev.event_maps(np.array([], int), np.array([], int), np.array([], int), 7, 5, 0.2, 0.2)
    assert not de0.any() and not hits0.any()


def test_gt_counts_jitter_only_event_free_pixels():
    de = np.array([[0.4, 0.0], [0.0, -0.2]])
    hits = np.array([[True, False], [False, True]])
    n = ev.gt_counts(de, hits, 0.2, 0.0, None)
    np.testing.assert_allclose(n, [[2, 0], [0, -1]])
    noisy = ev.gt_counts(np.zeros((200, 200)), np.zeros((200, 200), bool), 0.2, 0.02, np.random.default_rng(0))
    assert abs(noisy.std() - 0.02 / 0.2) < 0.005 and abs(noisy.mean()) < 0.005
    kept = ev.gt_counts(de, hits, 0.2, 0.02, np.random.default_rng(0))
    assert kept[0, 0] == pytest.approx(2) and kept[1, 1] == pytest.approx(-1)


def test_event_loss_matches_the_event_model_and_is_zero_at_the_truth():
    # a brightening of exactly 3 thresholds at one pixel, nothing elsewhere
    c = 0.2
    l0 = torch.zeros(4, 5)
    l1 = l0.clone()
    l1[2, 3] = 3 * c
    n_pred = ev.predicted_counts(l0, l1, torch.tensor(c))
    n_gt = torch.zeros(4, 5)
    n_gt[2, 3] = 3
    torch.testing.assert_close(n_pred, n_gt)
    assert ev.recon_loss(n_gt, n_pred).item() == pytest.approx(1e-3)       # sqrt(0 + eps^2)
    assert ev.recon_loss(n_gt, torch.zeros(4, 5)).item() == pytest.approx((math.sqrt(9 + 1e-6) + 19e-3) / 20)


@pytest.mark.parametrize("case", ["c_near_zero", "empty_window", "black_render", "million_events"])
def test_event_loss_and_gradients_stay_finite(case, rng):
    h, w = 260, 346
    img_s = torch.rand(h, w, 1, requires_grad=True)
    img_e = torch.rand(h, w, 1, requires_grad=True)
    log_c = torch.tensor(math.log(0.15), requires_grad=True)
    x = y = p = np.array([], int)
    if case == "c_near_zero":
        log_c = torch.tensor(math.log(1e-8), requires_grad=True)
    if case == "black_render":
        img_s = torch.zeros(h, w, 1, requires_grad=True)
        img_e = torch.zeros(h, w, 1, requires_grad=True)
    if case == "million_events":
        n = 1_000_000
        x, y, p = rng.integers(0, w, n), rng.integers(0, h, n), rng.choice([-1, 1], n)
    de, hits = ev.event_maps(x, y, p, w, h, 0.2, 0.2)
    n_gt = torch.from_numpy(ev.gt_counts(de, hits, 0.2, 0.02, rng))
    if case == "million_events":
        assert hits.mean() > 0.99 and abs(float(n_gt.sum()) - float(p.sum()) / 1.0) < 1e-3 * len(p)

    def L(img):
        return ev.log_response_t(ev.luminance_t(ev.srgb_to_linear_t(img)), "log", 1e-3)

    n_pred = ev.predicted_counts(L(img_s), L(img_e), torch.exp(log_c))
    loss = ev.recon_loss(n_gt, n_pred) + 0.005 * ev.tv_loss(img_e)
    loss.backward()
    assert torch.isfinite(loss)
    for t in (img_s, img_e, log_c):
        assert torch.isfinite(t.grad).all()
    if case == "black_render":  # log(0 + eps) is finite; equal renders predict no events
        assert float(n_pred.detach().abs().max()) == 0.0


def test_multiscale_loss_compares_block_means_of_the_counts():
    n_gt = torch.zeros(8, 12)
    n_gt[0::2, 0::2] = 2.0            # a texture whose 2x2 blocks each hold one 2-count pixel
    pred_flat = torch.full((8, 12), 0.5, requires_grad=True)    # the block mean, unresolved texture
    eps = 1e-3
    fine = ev.multiscale_recon_loss(n_gt, pred_flat, (1,), eps)
    assert fine.item() == pytest.approx(ev.recon_loss(n_gt, pred_flat, eps).item())
    assert fine.item() == pytest.approx((1.5 + 3 * 0.5) / 4, abs=1e-5)
    coarse = ev.multiscale_recon_loss(n_gt, pred_flat, (2,), eps)
    assert coarse.item() == pytest.approx(eps, rel=1e-3)          # block means agree: only eps is left
    both = ev.multiscale_recon_loss(n_gt, pred_flat, (1, 2), eps)
    assert both.item() == pytest.approx((fine.item() + coarse.item()) / 2)
    # a wrong overall level is seen at every scale; 5x5 blocks do not divide 8x12 and still average
    off = torch.full((8, 12), 1.5)
    assert ev.multiscale_recon_loss(n_gt, off, (5,), eps).item() > 0.5
    both.backward()
    assert torch.isfinite(pred_flat.grad).all()


def test_linlog_response_matches_the_simulator():
    from simulator.pixel import linlog_response

    i = np.linspace(0, 2, 101)
    np.testing.assert_allclose(ev.log_response_t(torch.from_numpy(i), "linlog", linlog_threshold_dn=20.0,
                                                 dn_per_unit=255.0).numpy(), linlog_response(i, 20.0, 255.0))
    with pytest.raises(ValueError, match="unknown response mode"):
        ev.log_response_t(torch.zeros(1), "gamma")


@pytest.mark.parametrize("in_memory", [False, True])
def test_windows_hold_the_drawn_count_and_match_the_file(motion_scene, in_memory):
    ds = SceneDataset(motion_scene)
    src = EventSource(ds.event_file(0))
    # load keeps the columns only when they fit; 0 bytes never fit (the disk path, as a large file)
    assert src.load(max_bytes=1 << 30 if in_memory else 0) is in_memory
    allev = read_events(ds.event_file(0)).events
    r = np.random.default_rng(3)
    for _ in range(20):
        n = int(r.integers(1, src.n // 3))
        i0 = int(r.integers(1, src.n - n + 1))
        w = src.window(0, i0, n)
        x, y, p = src.rows(i0, i0 + n)
        np.testing.assert_array_equal(x, allev["x"][i0:i0 + n])
        np.testing.assert_array_equal(p, allev["p"][i0:i0 + n])
        np.testing.assert_array_equal(src.times(i0, i0 + n), allev["t"][i0:i0 + n])
        x[:] = 0                     # what a caller does to a window does not reach the file's columns
        inside = (allev["t"] > w.t_start_us) & (allev["t"] <= w.t_end_us)
        assert len(w) == inside.sum() and abs(len(w) - n) <= np.sum(allev["t"] == w.t_end_us) + \
            np.sum(allev["t"] == w.t_start_us)
        np.testing.assert_array_equal(count_image(w.x, w.y, w.p, 64, 48),
                                      count_image(allev["x"][inside], allev["y"][inside], allev["p"][inside], 64, 48))
    src.close()


def test_window_counts_follow_the_event_rate_or_the_pixel_count(motion_scene):
    ds = SceneDataset(motion_scene)
    counts = [EventSource(ds.event_file(k)).n for k in range(ds.n_cameras)]
    smallest = min(counts)
    cfg = recon.resolve_config("e4dgs").events
    assert E4DGS.window_counts(ds, cfg, counts) == (round(0.05 * smallest), round(0.2 * smallest))
    cfg = recon.resolve_config("e4dgs", overrides={"events.window_scale": "pixels"}).events
    ratio = 64 * 48 / PAPER_PIXELS
    assert E4DGS.window_counts(ds, cfg, counts) == (round(5000 * ratio), round(10000 * ratio))
    cfg = recon.resolve_config("e4dgs", overrides={"events.window_fraction": [0.9, 1.0]}).events
    assert E4DGS.window_counts(ds, cfg, counts) == (int(0.5 * smallest),) * 2     # capped


def test_color_correction_recovers_gain_and_offset_and_handles_constants(rng):
    gt = rng.uniform(0.05, 0.95, (12, 10, 3)).astype(np.float32)
    from simulator.pixel import linear_to_srgb, srgb_to_linear

    lg = np.log(srgb_to_linear(gt) + 1e-3)
    pred = linear_to_srgb(np.exp((lg - 0.3) / 1.7) - 1e-3).astype(np.float32)   # gain 1.7, offset 0.3 away
    corrected, params = correct_colors(pred, gt)
    np.testing.assert_allclose(corrected, gt, atol=2e-3)
    assert params[0][0] == pytest.approx(1.7, rel=1e-3)
    const = np.full((12, 10, 3), 0.4, np.float32)
    out, params = correct_colors(const, gt)
    assert np.isfinite(out).all() and all(g == 1.0 for g, _ in params)
    assert fit_gain_offset(np.zeros(5), np.full(5, 2.0)) == (1.0, 2.0)
    out, _ = correct_colors(np.zeros((4, 4, 1), np.float32), np.zeros((4, 4, 1), np.float32))
    assert np.isfinite(out).all()


def test_color_correction_never_inverts_contrast(rng):
    """A contrast-inverted prediction (log intensity anti-correlated with the truth) is not flipped
    back: the fitted gain is 0 and the corrected image is the truth's mean log intensity, scoring
    no better than a flat image; a positively correlated one keeps its OLS fit."""
    from common.color_correction import LOG_EPS
    from simulator.pixel import linear_to_srgb, srgb_to_linear

    gt = rng.uniform(0.05, 0.95, (12, 10, 1)).astype(np.float32)
    lg = np.log(srgb_to_linear(gt) + LOG_EPS)
    inverted = linear_to_srgb(np.exp(-lg - 4.0) - LOG_EPS).astype(np.float32)   # exact OLS gain: -1
    out, params = correct_colors(inverted, gt)
    assert params[0] == (0.0, pytest.approx(float(lg.mean())))
    flat = linear_to_srgb(np.exp(np.full_like(lg, lg.mean())) - LOG_EPS)
    np.testing.assert_allclose(out, np.clip(flat, 0, 1), atol=1e-6)
    assert np.mean((out - gt) ** 2) > 1e-2            # the inverted image is not rescued
    g, b = fit_gain_offset(np.arange(6.0), 2.0 * np.arange(6.0) + 1.0)
    assert (g, b) == (pytest.approx(2.0), pytest.approx(1.0))
    g, b = fit_gain_offset(np.arange(6.0), -0.5 * np.arange(6.0) + 3.0)          # OLS would give -0.5
    assert (g, b) == (0.0, pytest.approx(np.mean(-0.5 * np.arange(6.0) + 3.0)))
