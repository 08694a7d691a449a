"""E2VID / FireNet: voxel grids, the networks, the official checkpoint layout, simulated training data."""
import math

import numpy as np
import pytest
import torch

from e2vid.networks import FIRENET, NetConfig, Reconstructor, build_network, pad_to_multiple
from e2vid.official import CheckpointError, infer_config, load_checkpoint, save_checkpoint
from e2vid.reconstruct import hpf_log_frames, reconstruct_frames, split_windows
from e2vid.synth import SynthConfig, flow_grid, make_sequence, similarity
from e2vid.voxel import normalize_voxel, voxel_grid, voxel_grid_ref
from simulator import make_events


# ---------------------------------------------------------------- voxel grid

def test_voxel_grid_hand_computed():
    # 3 bins over t in [100, 300]: t* = 2 (t - 100) / 200
    t = np.array([100, 150, 200, 300])
    x = np.array([0, 1, 1, 2])
    y = np.array([0, 0, 1, 1])
    p = np.array([1, -1, 1, 1])
    want = np.zeros((3, 2, 3), np.float32)
    want[0, 0, 0] = 1.0                       # t* = 0
    want[0, 0, 1] = -0.5; want[1, 0, 1] = -0.5   # t* = 0.5
    want[1, 1, 1] = 1.0                       # t* = 1
    want[2, 1, 2] = 1.0                       # t* = 2 (last bin, nothing spills past it)
    for fn in (voxel_grid, voxel_grid_ref):
        np.testing.assert_allclose(fn(t, x, y, p, 3, 3, 2), want, atol=1e-7)


def test_voxel_grid_fast_equals_reference_and_preserves_polarity_sum():
    rng = np.random.default_rng(0)
    n = 2000
    t = np.sort(rng.integers(0, 10_000, n))
    x, y, p = rng.integers(0, 40, n), rng.integers(0, 30, n), rng.choice([-1, 1], n)
    fast, ref = voxel_grid(t, x, y, p, 5, 40, 30), voxel_grid_ref(t, x, y, p, 5, 40, 30)
    np.testing.assert_allclose(fast, ref, atol=1e-5)
    per_pixel = np.zeros((30, 40))
    np.add.at(per_pixel, (y, x), p)
    np.testing.assert_allclose(fast.sum(0), per_pixel, atol=1e-4)


def test_voxel_grid_empty_and_single_timestamp():
    assert not voxel_grid(np.array([], np.int64), [], [], [], 5, 4, 3).any()
    g = voxel_grid(np.array([7, 7]), np.array([1, 2]), np.array([0, 0]), np.array([1, -1]), 5, 4, 3)
    assert g[0, 0, 1] == 1 and g[0, 0, 2] == -1 and g[1:].sum() == 0   # zero span: all in bin 0


def test_normalize_voxel_nonzero_statistics():
    g = torch.zeros(5, 6, 7)
    g[0, 1, 2], g[1, 3, 3], g[4, 5, 6], g[2, 0, 0] = 3.0, -1.0, 2.0, 0.5
    out = normalize_voxel(g)
    nz = out[g != 0]
    assert abs(float(nz.mean())) < 1e-6 and abs(float(nz.std(unbiased=False)) - 1) < 1e-5
    assert (out[g == 0] == 0).all()
    assert (normalize_voxel(torch.zeros(5, 4, 4)) == 0).all()
    const = torch.zeros(5, 4, 4); const[0, 0, 0] = const[1, 1, 1] = 2.0
    assert torch.isfinite(normalize_voxel(const)).all()


# ---------------------------------------------------------------- networks

@pytest.mark.parametrize("cfg", [NetConfig(), FIRENET], ids=["e2vid", "firenet"])
def test_network_runs_at_sensor_size_and_keeps_state(cfg):
    torch.manual_seed(0)
    net = build_network(cfg)
    g = torch.Generator().manual_seed(1)
    v1, v2 = torch.randn(5, 260, 346, generator=g), torch.randn(5, 260, 346, generator=g)
    rec = Reconstructor(net)
    a = rec(v1)
    assert a.shape == (260, 346) and torch.isfinite(a).all() and a.min() >= 0 and a.max() <= 1
    assert rec.states is not None
    # the raw output (before the display clamp) depends on the state the previous call left
    x2, (l, r, t, b) = pad_to_multiple(v2[None], net.multiple)
    with torch.no_grad():
        after_v1, _ = net(x2, rec.states)
        fresh, _ = net(x2, None)
    assert not torch.allclose(after_v1, fresh)
    rec.reset()
    rec(v2)
    with torch.no_grad():
        _, fresh_states = net(x2, None)
    first = lambda s: s[0][0] if isinstance(s[0], tuple) else s[0]  # noqa: E731 (LSTM state is (h, c))
    assert torch.allclose(first(rec.states), first(fresh_states))


def test_pad_to_multiple_reflects_and_crops_back():
    x = torch.arange(2 * 5 * 7, dtype=torch.float32).view(1, 2, 5, 7)
    y, (l, r, t, b) = pad_to_multiple(x, 4)
    assert y.shape[-2:] == (8, 8) and (l + r, t + b) == (1, 3)
    assert torch.equal(y[..., t:t + 5, l:l + 7], x)


def _official_lightweight_state(norm: bool) -> dict:
    """A random state dict laid out as the official E2VID_lightweight (written out by hand)."""
    g = torch.Generator().manual_seed(0)
    r = lambda *s: torch.randn(*s, generator=g) * 0.05  # noqa: E731
    sd = {}

    def conv(prefix, cout, cin, k, transposed=False, normed=True):
        sd[prefix + ".weight"] = r(cin, cout, k, k) if transposed else r(cout, cin, k, k)
        if norm and normed:
            sd[prefix.rsplit(".", 1)[0] + ".norm_layer.weight"] = 1 + r(cout)
            sd[prefix.rsplit(".", 1)[0] + ".norm_layer.bias"] = r(cout)
            sd[prefix.rsplit(".", 1)[0] + ".norm_layer.running_mean"] = r(cout)
            sd[prefix.rsplit(".", 1)[0] + ".norm_layer.running_var"] = 1 + r(cout).abs()
            sd[prefix.rsplit(".", 1)[0] + ".norm_layer.num_batches_tracked"] = torch.tensor(7)
        else:
            sd[prefix + ".bias"] = r(cout)

    u = "unetrecurrent"
    conv(f"{u}.head.conv2d", 32, 5, 5, normed=False)      # the official head never takes the norm
    for i, (cin, cout) in enumerate([(32, 64), (64, 128), (128, 256)]):
        conv(f"{u}.encoders.{i}.conv.conv2d", cout, cin, 5)
        sd[f"{u}.encoders.{i}.recurrent_block.Gates.weight"] = r(4 * cout, 2 * cout, 3, 3)
        sd[f"{u}.encoders.{i}.recurrent_block.Gates.bias"] = r(4 * cout)
    for j in range(2):
        for c in (1, 2):
            sd[f"{u}.resblocks.{j}.conv{c}.weight"] = r(256, 256, 3, 3)
            if norm:
                for k, v in (("weight", 1 + r(256)), ("bias", r(256)), ("running_mean", r(256)),
                             ("running_var", 1 + r(256).abs()), ("num_batches_tracked", torch.tensor(7))):
                    sd[f"{u}.resblocks.{j}.bn{c}.{k}"] = v
            else:
                sd[f"{u}.resblocks.{j}.conv{c}.bias"] = r(256)
    for i, (cin, cout) in enumerate([(256, 128), (128, 64), (64, 32)]):
        conv(f"{u}.decoders.{i}.transposed_conv2d", cout, cin, 5, transposed=True)
    conv(f"{u}.pred.conv2d", 1, 32, 1)
    return sd


@pytest.mark.parametrize("norm", [False, True], ids=["no-norm", "batch-norm"])
def test_official_e2vid_checkpoint_loads_key_for_key(tmp_path, norm):
    sd = _official_lightweight_state(norm)
    path = tmp_path / "E2VID_lightweight.pth.tar"
    torch.save({"arch": "E2VIDRecurrent", "model": {"num_bins": 5, "num_encoders": 3}, "state_dict":
                {("module." + k if i % 2 else k): v for i, (k, v) in enumerate(sd.items())}}, path)
    net, extra = load_checkpoint(path)
    assert net.cfg.arch == "e2vid" and net.cfg.num_encoders == 3 and net.cfg.base_num_channels == 32
    assert net.cfg.norm == ("BN" if norm else "none") and not net.cfg.use_upsample_conv
    assert extra["arch"] == "E2VIDRecurrent"
    got = net.state_dict()
    assert set(got) == set(sd)
    for k, v in sd.items():
        assert torch.equal(got[k], v), k
    out = Reconstructor(net)(torch.randn(5, 60, 90))
    assert out.shape == (60, 90) and torch.isfinite(out).all()


def test_official_firenet_keys_and_roundtrip(tmp_path):
    c = 16
    sd = {"head.conv2d.weight": torch.randn(c, 5, 3, 3), "head.conv2d.bias": torch.randn(c),
          "pred.conv2d.weight": torch.randn(1, c, 1, 1), "pred.conv2d.bias": torch.randn(1)}
    for gname in ("G1", "G2"):
        for gate in ("reset_gate", "update_gate", "out_gate"):
            sd[f"{gname}.{gate}.weight"] = torch.randn(c, 2 * c, 3, 3)
            sd[f"{gname}.{gate}.bias"] = torch.randn(c)
    for rname in ("R1", "R2"):
        for k in (1, 2):
            sd[f"{rname}.conv{k}.weight"] = torch.randn(c, c, 3, 3)
            sd[f"{rname}.conv{k}.bias"] = torch.randn(c)
    cfg = infer_config(sd)
    assert cfg.arch == "firenet" and cfg.base_num_channels == 16 and cfg.kernel_size == 3
    path = tmp_path / "firenet.pth"
    torch.save({"state_dict": sd}, path)
    net, _ = load_checkpoint(path)
    assert set(net.state_dict()) == set(sd)
    out = save_checkpoint(tmp_path / "again.pth", net, note="x")
    net2, extra = load_checkpoint(out)
    assert extra["note"] == "x" and extra["arch"] == "FireNet"
    for k, v in net.state_dict().items():
        assert torch.equal(net2.state_dict()[k], v)


def test_foreign_checkpoint_is_refused(tmp_path):
    path = tmp_path / "x.pth"
    torch.save({"state_dict": {"encoder.weight": torch.zeros(3)}}, path)
    with pytest.raises(CheckpointError, match="x.pth"):
        load_checkpoint(path)
    sd = _official_lightweight_state(False)
    del sd["unetrecurrent.pred.conv2d.bias"]
    torch.save({"state_dict": sd}, path)
    with pytest.raises(CheckpointError, match="missing"):
        load_checkpoint(path)
    (tmp_path / "junk.pth").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="junk.pth"):
        load_checkpoint(tmp_path / "junk.pth")


# ---------------------------------------------------------------- windows and the high-pass filter

def test_split_windows_cover_every_event_once():
    t = np.sort(np.random.default_rng(0).integers(0, 1000, 500))
    wins = list(split_windows(t, np.array([100, 400, 1000]), events_per_window=60))
    assert wins[0][0] == 0 and wins[-1][1] == len(t)
    assert all(a[1] == b[0] for a, b in zip(wins, wins[1:]))
    assert all(i1 - i0 <= 60 for i0, i1, _ in wins)
    due = [k for _, _, k in wins if k >= 0]
    assert due == [0, 1, 2]
    ends = [i1 for i0, i1, k in wins if k >= 0]
    assert ends == list(np.searchsorted(t, [100, 400, 1000], side="right"))


def test_hpf_integrates_and_forgets():
    ev = make_events([10, 20, 30], [1, 1, 0], [0, 0, 0], [1, 1, -1])
    # no forgetting: log steps add up
    out = hpf_log_frames(ev, 2, 1, np.array([30]), cutoff_rad_s=0.0, contrast=0.2)
    np.testing.assert_allclose(out[0, 0], [-0.2, 0.4], atol=1e-6)
    # forgetting: each step decays by exp(-alpha (t_end - t_i))
    a = 1000.0
    out = hpf_log_frames(ev, 2, 1, np.array([30, 1030]), cutoff_rad_s=a, contrast=0.2)
    want = 0.2 * (math.exp(-a * 20e-6) + math.exp(-a * 10e-6))
    assert out[0, 0, 1] == pytest.approx(want, rel=1e-6)
    assert out[1, 0, 1] == pytest.approx(want * math.exp(-a * 1000e-6), rel=1e-6)
    empty = hpf_log_frames(ev[:0], 2, 1, np.array([5, 10]))
    assert not empty.any()


def test_reconstruct_frames_outputs_at_requested_times():
    torch.manual_seed(0)
    ev = make_events(np.arange(0, 1000, 5), np.arange(200) % 16, np.arange(200) % 12, np.where(np.arange(200) % 3, 1, -1))
    frames = reconstruct_frames(Reconstructor(build_network(FIRENET)), ev, 16, 12, np.array([0, 300, 999]), 50)
    assert frames.shape == (3, 12, 16) and np.isfinite(frames).all()


# ---------------------------------------------------------------- simulated training data

def test_make_sequence_is_deterministic_and_shaped():
    cfg = SynthConfig(height=32, width=40, n_steps=3, substeps=4)
    a, b = make_sequence(5, cfg), make_sequence(5, cfg)
    assert a.voxels.shape == (3, 5, 32, 40) and a.targets.shape == (3, 1, 32, 40) and a.flow.shape == (3, 32, 40, 2)
    assert torch.equal(a.voxels, b.voxels) and torch.equal(a.targets, b.targets)
    assert not torch.equal(a.voxels, make_sequence(6, cfg).voxels)
    assert a.targets.min() >= 0 and a.targets.max() <= 1 and torch.isfinite(a.voxels).all()


def test_flow_grid_maps_pixels_to_their_previous_position():
    """A pure translation by (dx, dy) per step: pixel p came from p - (dx, dy)."""
    H, W = 8, 10
    c = np.array([W / 2, H / 2])
    prev = similarity(np.array([20.0, 20.0]), 0.0, 1.0, c)
    now = similarity(np.array([22.0, 19.0]), 0.0, 1.0, c)   # canvas centre moved -> image content moves (-2, +1)
    g = flow_grid(prev, now, H, W)
    px = (g[..., 0] + 1) * W / 2 - 0.5
    py = (g[..., 1] + 1) * H / 2 - 0.5
    yy, xx = np.mgrid[0:H, 0:W]
    np.testing.assert_allclose(px, xx + 2, atol=1e-5)
    np.testing.assert_allclose(py, yy - 1, atol=1e-5)


# ---------------------------------------------------------------- training

def _tiny_train_cfg(**kw):
    from e2vid.train import E2VIDTrainConfig
    base = dict(iterations=6, batch_size=2, checkpoint_every=2, lpips_net="alex", lpips_start=3, threads=1, tbptt=2,
                monitor_every=3, monitor_sequences=1, monitor_size=(24, 24), data_workers=0,
                synth=SynthConfig(height=32, width=32, n_steps=3, substeps=4))
    return E2VIDTrainConfig(**{**base, **kw})


def test_train_e2vid_resumes_to_the_same_weights(tmp_path, monkeypatch):
    from e2vid import train as tr

    full = tr.E2VIDTrainer(_tiny_train_cfg(), tmp_path / "full", progress=False)
    full.run()

    calls = {"n": 0}
    real = tr.make_batch

    def dying(*a, **k):
        calls["n"] += 1
        if calls["n"] == 4:          # killed during iteration 4: the checkpoint holds iteration 2
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(tr, "make_batch", dying)
    with pytest.raises(KeyboardInterrupt):
        tr.E2VIDTrainer(_tiny_train_cfg(), tmp_path / "killed", progress=False).run()
    monkeypatch.setattr(tr, "make_batch", real)
    resumed = tr.E2VIDTrainer(_tiny_train_cfg(), tmp_path / "killed", progress=False)
    resumed.run()
    assert [r["iteration"] for r in resumed.log] == list(range(1, 7))
    assert [r["iteration"] for r in resumed.log if "monitor_corr" in r] == [3, 6]
    assert all(-1 <= r["monitor_corr"] <= 1 for r in resumed.log if "monitor_corr" in r)
    # LPIPS counts from lpips_start (iteration index 3, logged as iteration 4) on
    assert [r["lpips"] > 0 for r in resumed.log] == [False] * 3 + [True] * 3
    for k, v in full.net.state_dict().items():
        torch.testing.assert_close(resumed.net.state_dict()[k], v, rtol=1e-5, atol=1e-6)
    # the kept weights are the best by monitor correlation, and use_best loads them
    best = max((r for r in resumed.log if "monitor_corr" in r), key=lambda r: r["monitor_corr"])
    assert resumed.use_best() == {"iteration": best["iteration"], "monitor_corr": best["monitor_corr"]}
    # another config in the same folder is refused, not silently mixed
    with pytest.raises(ValueError, match="different config"):
        tr.E2VIDTrainer(_tiny_train_cfg(lr=5e-4), tmp_path / "killed", progress=False).run()


def test_training_loss_terms_are_finite_and_temporal_term_sees_motion():
    from e2vid.train import E2VIDTrainConfig, sequence_loss
    net = build_network(FIRENET)
    seq = make_sequence(3, SynthConfig(height=32, width=32, n_steps=3, substeps=4))
    batch = type(seq)(seq.voxels[:, None], seq.targets[:, None], seq.flow[:, None], seq.n_events[:, None])
    loss, parts, _, _ = sequence_loss(net, batch, E2VIDTrainConfig(lambda_lpips=0.0), None)
    assert torch.isfinite(loss) and parts["l1"] > 0 and parts["tc"] >= 0
    loss.backward()
    assert all(torch.isfinite(p.grad).all() for p in net.parameters() if p.grad is not None)


def test_chunked_loss_with_carried_state_equals_the_whole_sequence_loss():
    # truncated BPTT changes the gradients, never the forward values: chunks [0, 2) and [2, 5) with the
    # state and last output carried give the same per-step losses as one pass over [0, 5)
    from e2vid.train import E2VIDTrainConfig, sequence_loss
    torch.manual_seed(0)
    net = build_network(FIRENET)
    seq = make_sequence(4, SynthConfig(height=32, width=32, n_steps=5, substeps=4))
    batch = type(seq)(seq.voxels[:, None], seq.targets[:, None], seq.flow[:, None], seq.n_events[:, None])
    cfg = E2VIDTrainConfig(lambda_lpips=0.0)
    with torch.no_grad():
        whole, parts, _, _ = sequence_loss(net, batch, cfg, None)
        a, pa, st, prev = sequence_loss(net, batch, cfg, None, 0, 2)
        b, pb, _, _ = sequence_loss(net, batch, cfg, None, 2, 5, st, prev)
    torch.testing.assert_close(whole, (2 * a + 3 * b) / 5)
    assert parts["tc"] == pytest.approx((2 * pa["tc"] + 3 * pb["tc"]) / 5) and pb["tc"] > 0


def test_background_data_workers_train_the_same_weights_as_inline(tmp_path):
    from e2vid import train as tr
    inline = tr.E2VIDTrainer(_tiny_train_cfg(iterations=3, monitor_every=0), tmp_path / "a", progress=False).run()
    worker = tr.E2VIDTrainer(_tiny_train_cfg(iterations=3, monitor_every=0, data_workers=1), tmp_path / "b",
                             progress=False).run()
    for k, v in inline.state_dict().items():
        torch.testing.assert_close(worker.state_dict()[k], v)


# ---------------------------------------------------------------- the shipped weights and the baseline method

def test_shipped_weights_beat_an_untrained_network_on_a_heldout_clip():
    from e2vid.evaluate import evaluate_heldout
    from e2vid.weights import default_weights_path

    net, extra = load_checkpoint(default_weights_path())
    assert net.cfg.arch == "firenet" and extra["e4dgs_training"]["iterations"] > 0
    cfg = SynthConfig(height=64, width=80, n_steps=16)
    trained = evaluate_heldout(net, n_sequences=3, cfg=cfg, skip=4)
    for seed in range(3):      # untrained networks give flat or unrelated images: no correlation
        torch.manual_seed(seed)
        untrained = evaluate_heldout(build_network(net.cfg), n_sequences=3, cfg=cfg, skip=4)
        assert trained["network"]["corr"] > untrained["network"]["corr"] + 0.3
        assert trained["network_corrected"]["ssim"] > untrained["network_corrected"]["ssim"] + 0.1
    assert trained["network"]["corr"] > 0.5       # measured 0.64 (the high-pass filter: 0.72 on these clips)


def test_correlation_ignores_gain_and_offset():
    from e2vid.evaluate import correlation
    g = np.random.default_rng(0).random((8, 9))
    assert correlation(3 * g + 1, g) == pytest.approx(1.0)
    assert correlation(-g, g) == pytest.approx(-1.0)
    assert correlation(np.full_like(g, 0.4), g) == 0.0


def test_e2vid_d3dgs_end_to_end_on_the_tiny_dataset(motion_scene, tmp_path):
    import recon
    from scene_format.reader import SceneDataset
    from recon.methods.e2vid_d3dgs import E2VIDD3DGS, reconstruct_camera

    ds = SceneDataset(motion_scene)
    recs = sorted((r for r in ds.frames("train") if r.camera == 0), key=lambda r: r.t_us)
    frames = reconstruct_camera(ds, 0, [r.t_us for r in recs])
    assert frames.shape == (len(recs), 48, 64) and np.isfinite(frames).all()
    assert frames[-1].std() > 0.01                     # the last frame shows structure, not a flat grey
    model = recon.fit(motion_scene, "e2vid_d3dgs", overrides={
        "train.iterations": 30, "train.scale_schedule": False, "train.warm_up": 200, "train.densify.enabled": False,
        "train.init.n_points_object": 500}, out_dir=tmp_path / "run", progress=False).model
    assert model.meta.iteration == 30 and model.meta.channels == 1
    method = E2VIDD3DGS.scorer(ds, recon.resolve_config("e2vid_d3dgs"))
    pairs = method.eval_pairs(model, ds.frames("test")[:3])
    assert all(p.shape == g.shape == (48, 64, 1) and np.isfinite(p).all() for p, g in pairs)


def test_e2vid_cli_writes_frames(motion_scene, tmp_path):
    from e4dgs.cli import main

    out = tmp_path / "video"
    assert main(["e2vid", str(motion_scene / "events" / "cam0.h5"), "--out", str(out), "--dt-ms", "5"]) == 0
    times = [int(t) for t in (out / "timestamps.txt").read_text().split()]
    pngs = sorted(out.glob("*.png"))
    assert len(pngs) == len(times) >= 3 and times == sorted(times)
    with pytest.raises(SystemExit, match="nope.h5"):
        main(["e2vid", str(tmp_path / "nope.h5"), "--out", str(out)])


def test_weights_report_lists_the_curve_and_heldout_numbers():
    from e2vid.report import loss_curve_rows, training_report_md

    log = [{"iteration": i, "wall_s": 6.0 * i, "loss": 1.0 / i, "l1": 0.5, "lpips": 0.25, "tc": 0.01,
            **({"monitor_corr": i / 200} if i % 10 == 0 else {})} for i in range(1, 101)]
    rows = loss_curve_rows(log, n_rows=4)
    assert [r["iterations"] for r in rows] == ["1-25", "26-50", "51-75", "76-100"]
    assert rows[0]["loss"] > rows[-1]["loss"]
    assert [r["monitor_corr"] for r in rows] == [0.1, 0.25, 0.35, 0.5]     # the last check in each slice
    held = {k: {"psnr": p, "ssim": 0.5} for k, p in (("network", 17.25), ("network_corrected", 21.5),
                                                      ("hpf_corrected", 19.75))}
    held["sequences"] = {"n": 8, "steps": 24, "size": [112, 144], "skip": 4, "seed_base": 1 << 40}
    held["selected"] = {"iteration": 90, "monitor_corr": 0.45}
    md = training_report_md("firenet", 100, 600.0, log, held, "arch: firenet\n", "e4dgs train-e2vid")
    assert "iteration 90, the best monitor correlation (0.450)" in md
    assert "17.25" in md and "21.50" in md and "19.75" in md and "10.0 min" in md and "-100 |" in md


@pytest.mark.parametrize("key,value", [("tbptt", 0), ("iterations", 0), ("data_workers", -1), ("lpips_start", -5)])
def test_train_config_rejects_bad_values_naming_the_field(key, value):
    from e2vid.train import E2VIDTrainConfig
    from common.config import ConfigError, build_config
    with pytest.raises(ConfigError, match=key):
        build_config(E2VIDTrainConfig, None, {key: value})


def test_frame_times_cover_the_stream_and_end_at_its_last_event():
    from e2vid.reconstruct import frame_times_us

    default = frame_times_us(100, 19_800)
    assert len(default) == 30 and default[-1] == 19_800 and np.all(np.diff(default) > 0)
    np.testing.assert_array_equal(frame_times_us(0, 19_700, 5000), [5000, 10_000, 15_000, 19_700])
    np.testing.assert_array_equal(frame_times_us(0, 20_000, 5000), [5000, 10_000, 15_000, 20_000])
    np.testing.assert_array_equal(frame_times_us(0, 5, 1.5), [2, 3, 4, 5])      # rounded to whole us, distinct
    np.testing.assert_array_equal(frame_times_us(7, 7), [7])


def test_e2vid_refuses_steps_below_a_microsecond_and_warns_before_long_runs(motion_scene, tmp_path, capsys,
                                                                           monkeypatch):
    import e2vid.cli
    from e4dgs.cli import main

    ev = str(motion_scene / "events" / "cam0.h5")
    for args, words in ((["--dt-ms", "0.0001"], "below the event timestamps' resolution of 1 us"),
                        (["--events-per-window", "1"], "at least 100 events")):
        with pytest.raises(SystemExit, match=words):
            main(["e2vid", ev, "--out", str(tmp_path / "v"), *args])
        assert not (tmp_path / "v").exists()
    monkeypatch.setattr(e2vid.cli, "LONG_RUN_WINDOWS", 30)      # the real bound is 2,000 windows
    assert main(["e2vid", ev, "--out", str(tmp_path / "w"), "--dt-ms", "0.5"]) == 0
    err = capsys.readouterr().err
    n = len((tmp_path / "w" / "timestamps.txt").read_text().split())
    assert f"warning: {n:,} windows, about" in err and "ms each" in err and n > 30
