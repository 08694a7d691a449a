"""E-4DGS on the tiny moving scene: events-only training recovers held-out frames, and every
ablation switch changes exactly what it says."""
import math

import numpy as np
import pytest
import torch

import recon
from common.config import ConfigError
from scene_format.reader import SceneDataset
from recon.scoring import evaluate_psnr
from recon.methods.e4dgs import E4DGS, E4DGSRGB
from recon.trainer import Trainer
from recon.dataset_views import dataset_camera

SMALL = {"train.init.n_points_object": 2000, "train.precision": "float32", "train.lr.feature": 0.01,
         "train.snapshots": [1.0], "train.checkpoint_every": 5000}
TRAIN_ITERS = 1000   # with densification off to stay fast: ~50 s on 2 cores
# stated target: held-out PSNR after colour correction (gain >= 0). Measured: the untrained model
# (points in the background's colour, a flat image after correction) 25.05 dB, 27.92 after 1,000
# iterations (26.96 when points started mid-grey)
HELD_OUT_PSNR_MIN = 27.0
OVER_UNTRAINED_DB = 2.0


def trainer_for(scene, tmp_path, method="e4dgs", **overrides):
    cfg = recon.resolve_config(method, overrides={**SMALL, **overrides})
    tr = Trainer(recon.get_method(method)(SceneDataset(scene), cfg), tmp_path / method, progress=False)
    tr.setup()
    return tr


def test_events_only_training_recovers_held_out_frames(motion_scene, tmp_path):
    ds = SceneDataset(motion_scene)
    untrained = trainer_for(motion_scene, tmp_path / "u")
    before = evaluate_psnr(untrained.method.eval_pairs(untrained.model, ds.frames("test")))
    model = recon.fit(motion_scene, "e4dgs", overrides={**SMALL, "train.iterations": TRAIN_ITERS,
                                                        "train.densify.enabled": False},
                      out_dir=tmp_path / "run", progress=False).model
    method = E4DGS(ds, recon.resolve_config("e4dgs"))
    after = evaluate_psnr(method.eval_pairs(model, ds.frames("test")))
    assert model.meta.channels == 1 and model.meta.method == "e4dgs"
    assert after >= HELD_OUT_PSNR_MIN and after > before + OVER_UNTRAINED_DB, (before, after)


def test_ess_switch_fixes_the_count_and_drops_the_jitter(motion_scene, tmp_path):
    on = trainer_for(motion_scene, tmp_path / "on")
    off = trainer_for(motion_scene, tmp_path / "off", **{"events.ess": False})
    rng = np.random.default_rng(0)
    counts_on = {len(on.method.sampler.sample(rng)) for _ in range(30)}
    counts_off = {off.method.sampler.sample(rng).x.size for _ in range(30)}
    lo, hi = on.method.n_range
    assert len(counts_on) > 5 and min(counts_on) >= lo - 50 and max(counts_on) <= hi + 50
    fixed = round((lo + hi) / 2)
    assert all(abs(c - fixed) <= 50 for c in counts_off)          # ties at the window ends only
    # without ESS, event-free pixels carry exactly zero
    win = off.method.sampler.sample(rng)
    loss_a, _ = off.method.event_loss(off, [win])
    loss_b, _ = off.method.event_loss(off, [win])
    assert loss_a.item() == loss_b.item()                          # no random jitter drawn
    loss_c, _ = on.method.event_loss(on, [win])
    loss_d, _ = on.method.event_loss(on, [win])
    assert loss_c.item() != loss_d.item()                          # jitter drawn per step


def test_aes_switch_learns_or_freezes_the_threshold(motion_scene, tmp_path):
    for aes in (True, False):
        tr = trainer_for(motion_scene, tmp_path / str(aes), **{"events.aes": aes})
        for it in range(1, 6):
            loss, _ = tr.method.step(tr, it)
            loss.backward()
            tr.optimizer.step()
            tr.optimizer.zero_grad()
        c = tr.method.c_hat.item()
        if aes:
            assert c != pytest.approx(0.15, abs=1e-6) and c > 0
        else:
            assert c == pytest.approx(0.15, abs=1e-7)
            assert all(g["name"] != "c_hat" for g in tr.optimizer.param_groups)


def test_tv_switch_changes_the_loss_by_its_term(motion_scene, tmp_path):
    from recon import event_supervision as ev

    # mid-grey points: a background-coloured start renders no edges, so its TV would be 0
    mid = {"events.ess": False, "train.init.color": "mid"}
    with_tv = trainer_for(motion_scene, tmp_path / "tv", **mid)
    no_tv = trainer_for(motion_scene, tmp_path / "notv", **mid, **{"events.lambda_tv": 0.0})
    no_tv.model = with_tv.model
    win = with_tv.method.sampler.sample(np.random.default_rng(1))
    a, renders = with_tv.method.event_loss(with_tv, [win])
    b, _ = no_tv.method.event_loss(no_tv, [win])
    tv = ev.tv_loss(renders[1][0].image)
    assert a.item() == pytest.approx(b.item() + 0.005 * tv.item(), rel=1e-6)
    assert tv.item() > 0


def test_iip_switch_prunes_by_importance_only_when_on(motion_scene, tmp_path):
    on = trainer_for(motion_scene, tmp_path / "on", **{"train.iterations": 4000})
    off = trainer_for(motion_scene, tmp_path / "off", **{"train.iterations": 4000, "events.iip": False})
    interval = on.tcfg.scaled(on.cfg.events.iip_interval)
    start = on.tcfg.scaled(on.cfg.events.iip_start)
    at = (start // interval + 1) * interval
    assert on.method.prune_mask(on, at - 1) is None and off.method.prune_mask(off, at) is None
    assert on.method.prune_mask(on, interval) is None                  # before iip_start
    mask = on.method.prune_mask(on, at)
    w = on.method.importance(on.model)
    assert mask.dtype == torch.bool and mask.shape == (len(on.model),)
    assert torch.equal(mask, w < 0.015) and 0 < int(mask.sum()) < len(on.model)
    # importance is the max over cameras and times of the rasterizer's max_weight
    out = on.model.render_output(dataset_camera(on.dataset, 0, 0), 0.0)
    assert torch.all(w >= out.max_weight - 1e-7)


def test_no_opacity_reset_and_children_inherit_the_deformation_input(motion_scene, tmp_path):
    tr = trainer_for(motion_scene, tmp_path)
    assert not tr.cfg.train.densify.opacity_reset
    g = tr.model.gaussians
    assert torch.equal(g.anchors, g.means)
    parent = int(torch.argmax(g.scales.max(1).values))
    anchor = g.anchors[parent].clone()
    mask = torch.zeros(len(g), dtype=torch.bool)
    mask[parent] = True
    g.split_selected(mask, 2, tr.optimizer, torch.Generator().manual_seed(0))
    assert torch.equal(g.anchors[-2:], anchor.expand(2, 3))          # children read the parent's input
    assert not torch.equal(g.means[-2], g.means[-1])                 # though they sit elsewhere
    off = trainer_for(motion_scene, tmp_path / "off", **{"events.inherit_deformation": False})
    assert off.model.gaussians.anchors is None


def test_rgb_variant_renders_blur_as_the_mean_over_the_exposure(motion_scene, tmp_path):
    tr = trainer_for(motion_scene, tmp_path, "e4dgs_rgb", **{"rgb_frames": "strong", "rgb_samples": 4})
    assert isinstance(tr.method, E4DGSRGB) and tr.model.meta.channels == 3
    view = tr.method.blur_views[0]
    rec = SceneDataset(motion_scene).blurred_frames("strong")[0]
    assert len(view.cameras) == 4
    assert view.times[0] == pytest.approx(rec.exposure_us[0] / tr.dataset.duration_us)
    assert view.times[-1] == pytest.approx(rec.exposure_us[1] / tr.dataset.duration_us)
    loss, renders = tr.method.step(tr, 1)
    assert len(renders) == 2 + 4 and math.isfinite(loss.item())
    # rgb_every 3: the blurred frame joins iterations 3, 6, ... only; the others are events-only steps
    every = trainer_for(motion_scene, tmp_path / "e", "e4dgs_rgb", **{"rgb_frames": "strong", "rgb_samples": 4,
                                                                      "rgb_every": 3})
    assert [len(every.method.step(every, it)[1]) for it in (1, 2, 3, 4, 6)] == [2, 2, 6, 2, 6]
    with pytest.raises(ConfigError, match="rgb_every"):
        recon.resolve_config("e4dgs_rgb", overrides={"rgb_every": 0})
    centre = trainer_for(motion_scene, tmp_path / "c", "e4dgs_rgb", **{"rgb_frames": "strong", "rgb_render": "centre"})
    assert len(centre.method.blur_views[0].cameras) == 1
    assert centre.method.blur_views[0].times[0] == pytest.approx(rec.time, abs=1e-4)


def test_multi_view_step_supervises_the_same_time_window_on_distinct_cameras(motion_scene, tmp_path):
    """views_per_step: the other cameras' windows cover the first window's interval exactly (their
    events are the file's events in (t_start, t_end]); the deformation runs once for both end points
    and every camera; the loss is the mean of the single-camera losses; too many cameras is an error."""
    from eventio.h5io import read_events

    tr = trainer_for(motion_scene, tmp_path, **{"events.views_per_step": 2, "events.noise_sigma": 0.0})
    tr.model.meta.deform_enabled = True
    ds = tr.dataset
    streams = [read_events(ds.event_file(k)).events for k in range(ds.n_cameras)]
    rng = np.random.default_rng(5)
    for _ in range(5):
        windows = tr.method.sampler.sample_views(rng, 2)
        assert sorted(w.camera for w in windows) == [0, 1]
        assert len({(w.t_start_us, w.t_end_us) for w in windows}) == 1
        for w in windows:
            ev = streams[w.camera]
            inside = (ev["t"] > w.t_start_us) & (ev["t"] <= w.t_end_us)
            np.testing.assert_array_equal(np.sort(ev["x"][inside].astype(int) * 100 + ev["y"][inside]),
                                          np.sort(w.x.astype(int) * 100 + w.y))
    calls = []
    field_times = tr.model.deform.forward_times
    tr.model.deform.forward_times = lambda x, times: calls.append(list(times)) or field_times(x, times)
    loss, renders = tr.method.event_loss(tr, windows)
    t_s, t_e = (w / ds.duration_us for w in (windows[0].t_start_us, windows[0].t_end_us))
    assert calls == [[pytest.approx(t_s), pytest.approx(t_e)]] and len(renders) == 4   # 1 call, 2 end points x 2 cameras
    single = [tr.method.event_loss(tr, [w])[0].item() for w in windows]
    assert loss.item() == pytest.approx(np.mean(single), rel=1e-6)
    tr.model.deform.forward_times = field_times
    loss.backward()
    assert tr.model.gaussians.means.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="views_per_step"):
        trainer_for(motion_scene, tmp_path / "x", **{"events.views_per_step": 3})


def test_loss_scales_switch_pools_the_count_maps_and_scale_1_is_the_paper_loss(motion_scene, tmp_path):
    from recon import event_supervision as ev

    base = {"events.ess": False, "events.lambda_tv": 0.0}
    px = trainer_for(motion_scene, tmp_path / "px", **base)
    pooled = trainer_for(motion_scene, tmp_path / "pool", **base, **{"events.loss_scales": [1, 4]})
    pooled.model = px.model
    win = px.method.sampler.sample(np.random.default_rng(2))
    a, renders = px.method.event_loss(px, [win])
    b, _ = pooled.method.event_loss(pooled, [win])
    # rebuild both terms by hand from the same renders
    intr = px.dataset.intrinsics
    de, hits = ev.event_maps(win.x, win.y, win.p, intr.width, intr.height, px.method.c_pos, px.method.c_neg)
    n_gt = torch.from_numpy(ev.gt_counts(de, hits, px.method.c_ref, 0.0, None))
    n_pred = ev.predicted_counts(px.method.log_intensity(renders[0][0].image),
                                 px.method.log_intensity(renders[1][0].image), px.method.c_hat)
    fine = ev.recon_loss(n_gt, n_pred)
    coarse = ev.recon_loss(*(torch.nn.functional.avg_pool2d(m[None, None], 4, ceil_mode=True)[0, 0]
                             for m in (n_gt, n_pred)))
    assert a.item() == pytest.approx(fine.item(), rel=1e-5)
    assert b.item() == pytest.approx((fine.item() + coarse.item()) / 2, rel=1e-5)
    assert coarse.item() < fine.item()
    with pytest.raises(Exception, match="loss_scales"):
        recon.resolve_config("e4dgs", overrides={"events.loss_scales": [0]})


def test_opacity_learning_rate_decays_to_its_final_value_only_when_set(motion_scene, tmp_path):
    decay = trainer_for(motion_scene, tmp_path / "d", **{"train.iterations": 100, "train.lr.opacity": 0.05,
                                                         "train.lr.opacity_final": 0.005})
    const = trainer_for(motion_scene, tmp_path / "c", **{"train.iterations": 100, "train.lr.opacity": 0.05})
    lr = {}
    for tr, name in ((decay, "d"), (const, "c")):
        for it in (1, 50, 100):
            tr._update_lrs(it)
            lr[name, it] = next(g["lr"] for g in tr.optimizer.param_groups if g["name"] == "opacity")
    assert lr["d", 100] == pytest.approx(0.005) and lr["d", 50] == pytest.approx(math.sqrt(0.05 * 0.005), rel=0.03)
    assert lr["c", 1] == lr["c", 50] == lr["c", 100] == pytest.approx(0.05)
    with pytest.raises(Exception, match="lr.opacity_final"):
        recon.resolve_config("e4dgs", overrides={"train.lr.opacity_final": 0.0})
    with pytest.raises(Exception, match="lr.feature"):
        recon.resolve_config("e4dgs", overrides={"train.lr.feature": -1.0})


def test_init_color_background_starts_without_any_contrast(motion_scene, tmp_path):
    """init.color: background (E-4DGS's default) gives every initial Gaussian the empty background's
    colour, so the untrained model renders the background exactly (no contrast to unlearn);
    mid-grey does not."""
    ds = SceneDataset(motion_scene)
    assert recon.resolve_config("e4dgs").train.init.color == "background"
    assert recon.resolve_config("d3dgs").train.init.color == "mid"
    for method in ("e4dgs", "e4dgs_rgb"):
        bg_tr = trainer_for(motion_scene, tmp_path / f"bg_{method}", method, **{"train.init.color": "background"})
        mid_tr = trainer_for(motion_scene, tmp_path / f"mid_{method}", method, **{"train.init.color": "mid"})
        cam = dataset_camera(ds, 0, ds.duration_us // 2)
        with torch.no_grad():
            bg_img = bg_tr.model.render(cam, 0.5)
            mid_img = mid_tr.model.render(cam, 0.5)
        background = bg_tr.model.background
        assert bg_img.shape[-1] == len(background) == (1 if method == "e4dgs" else 3)
        torch.testing.assert_close(bg_img, background.expand_as(bg_img), atol=1e-5, rtol=0)
        assert (mid_img - background).abs().max() > 0.05          # the grey points show against it
    with pytest.raises(ConfigError, match="color"):
        recon.resolve_config("e4dgs", overrides={"train.init.color": "white"})
