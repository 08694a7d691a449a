"""The benchmark harness: metrics against analytic cases and scikit-image, the runner end to end on
the tiny dataset (with a resume after a simulated kill), and report generation from stored rows."""
import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from bench_cells import LABELS, MAIN_CELLS, described
from benchmark.config import BenchConfig, CellSpec, load_bench
from benchmark.grid import jobs
from common.metrics.image import psnr, score_pairs, ssim
from benchmark.report import write_report
from benchmark.runner import read_results, run_bench
from common.config import ConfigError, build_config


# ---------------------------------------------------------------- metrics

def _ssim_reference(a, b, sigma=1.5, c1=0.01 ** 2, c2=0.03 ** 2):
    """Wang et al.'s SSIM with a Gaussian window, written out (population statistics), mean over the
    image minus a border of 3.5 sigma (where scikit-image crops its mean)."""
    f = lambda x: gaussian_filter(x, sigma, truncate=3.5, mode="reflect")  # noqa: E731
    mu_a, mu_b = f(a), f(b)
    va, vb, cov = f(a * a) - mu_a ** 2, f(b * b) - mu_b ** 2, f(a * b) - mu_a * mu_b
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (va + vb + c2))
    pad = (int(3.5 * sigma + 0.5) * 2 + 1 - 1) // 2
    return float(s[pad:-pad, pad:-pad].mean())


def test_psnr_analytic():
    a = np.full((16, 16), 0.5)
    assert psnr(a, a) == math.inf
    b = a + 0.1            # MSE 0.01 -> 20 dB
    assert psnr(b, a) == pytest.approx(20.0, abs=1e-9)
    assert score_pairs([(a, a), (b, a)], lpips_net=None)["psnr"] == pytest.approx((100 + 20) / 2)


def test_luma_psnr_ignores_chroma_and_equals_psnr_on_gray():
    from common.color import linear_to_srgb, srgb_to_linear
    from common.metrics.image import luma

    gt = np.full((16, 16, 3), 0.2)                                # linear light
    d = 0.005                                                     # shift R up, B down at equal luminance
    pred = gt + np.array([d / 0.2126, 0.0, -d / 0.0722])
    s = score_pairs([(linear_to_srgb(pred), linear_to_srgb(gt))], lpips_net=None)
    assert s["psnr"] < 40 and s["psnr_luma"] == pytest.approx(100.0)   # a chroma error, no luma error
    assert np.allclose(srgb_to_linear(luma(linear_to_srgb(gt)))[..., 0], 0.2)
    a = np.full((16, 16, 1), 0.5)
    g = score_pairs([(a + 0.1, a)], lpips_net=None)                 # gray: the same number
    assert g["psnr_luma"] == g["psnr"] == pytest.approx(20.0)


def test_psnr_is_per_image_then_averaged():
    a = np.zeros((16, 16))
    pairs = [(a + 0.1, a), (a + 0.01, a)]        # 20 dB and 40 dB
    assert score_pairs(pairs, lpips_net=None)["psnr"] == pytest.approx(30.0)   # a pooled MSE would give ~23 dB


def test_ssim_constant_images():
    a, b = np.full((32, 32), 0.2), np.full((32, 32), 0.6)
    c1 = 0.01 ** 2
    assert ssim(a, a) == pytest.approx(1.0)
    assert ssim(a, b) == pytest.approx((2 * 0.2 * 0.6 + c1) / (0.2 ** 2 + 0.6 ** 2 + c1), rel=1e-6)


def test_ssim_matches_a_written_out_reference_and_colour_is_mean_of_channels():
    rng = np.random.default_rng(0)
    a = gaussian_filter(rng.random((48, 64)), 2)
    b = np.clip(a + 0.05 * rng.standard_normal(a.shape), 0, 1)
    assert ssim(a, b) == pytest.approx(_ssim_reference(a, b), abs=1e-6)
    rgb_a, rgb_b = np.stack([a, a ** 2, 1 - a], -1), np.stack([b, b ** 2, 1 - b], -1)
    want = np.mean([ssim(rgb_a[..., c], rgb_b[..., c]) for c in range(3)])
    assert ssim(rgb_a, rgb_b) == pytest.approx(want, rel=1e-9)
    assert ssim(a[..., None], b[..., None]) == pytest.approx(ssim(a, b))


# ---------------------------------------------------------------- presets

def test_shipped_presets_load_and_cover_every_method():
    for name in ("quick", "paper"):
        cfg = load_bench(name)
        keys = [j.key for j in jobs(cfg)]
        assert len(keys) == len(set(keys))
        assert {j.cell for j in jobs(cfg) if j.study == "main"} == set(MAIN_CELLS)
    assert len(load_bench("paper").scenes) == 8


def test_preset_errors_name_the_key(tmp_path):
    bad = tmp_path / "b.yaml"
    bad.write_text("scenes: [a]\ncells: {}\n")
    with pytest.raises(ConfigError, match="at least one cell"):
        load_bench(bad)
    bad.write_text("scenes: [a]\ncells: {mine: {method: d3dgs}}\nblur: {scene: a, cells: [d3dgs_blur]}\n")
    with pytest.raises(ConfigError, match="blur.cells: 'd3dgs_blur' is not a cell"):
        load_bench(bad)
    bad.write_text("scenes: [a]\ncells: {mine: {method: d3dgs}}\nspeed: {scenes: [a], speeds: [1, 2], cells: [mine]}\n")
    with pytest.raises(ConfigError, match="speed.reference: 'd3dgs_sharp' is not a cell"):
        load_bench(bad)
    bad.write_text("scenes: [a]\ncells: {mine: {method: no_such_method}}\n")
    with pytest.raises(ConfigError, match="cells.mine.method: unknown method 'no_such_method'"):
        jobs(load_bench(bad))
    bad.write_text("scenes: [a]\nsceens: [b]\n")
    with pytest.raises(ConfigError, match="sceens"):
        load_bench(bad)


def test_cells_order_and_labels_come_from_the_preset(tmp_path):
    """Any set of cells: the YAML's order is the jobs' (and the leaderboard's) order, labels and
    inputs travel with the jobs into their rows."""
    p = tmp_path / "p.yaml"
    p.write_text("scenes: [a]\ncells:\n  zz_events: {method: e4dgs, label: Mine on events}\n"
                 "  aa_rgb: {method: d3dgs}\n")
    cfg = load_bench(p)
    js = jobs(cfg)
    assert [j.cell for j in js] == ["zz_events", "aa_rgb"]
    ident = [j.identity() for j in js]
    assert [(i["label"], i["inputs"]) for i in ident] == [("Mine on events", ["events"]), ("aa_rgb", ["rgb"])]


# ---------------------------------------------------------------- the runner, end to end

TINY_TRAIN = {"train.iterations": 12, "train.scale_schedule": False, "train.warm_up": 200,
              "train.densify.enabled": False, "train.init.n_points_object": 300, "train.checkpoint_every": 5,
              "train.snapshots": [0.5, 1.0]}


def _tiny_bench(motion_scene) -> BenchConfig:
    cells = {
        "d3dgs_sharp": CellSpec("d3dgs", overrides={**TINY_TRAIN, "frames": "sharp"}),
        "d3dgs_blur": CellSpec("d3dgs", overrides={**TINY_TRAIN, "frames": "strong"}),
        "deblur_d3dgs": CellSpec("deblur_d3dgs", overrides={**TINY_TRAIN, "frames": "strong", "blur_samples": 3}),
        "e2vid_d3dgs": CellSpec("e2vid_d3dgs", overrides=TINY_TRAIN),
        "e4dgs": CellSpec("e4dgs", overrides=TINY_TRAIN),
        "e4dgs_rgb": CellSpec("e4dgs_rgb", overrides={**TINY_TRAIN, "rgb_frames": "strong"}),
    }
    return build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name], "cells": cells,
                                      "blur": {"scene": motion_scene.name, "levels": ["mild", "strong"],
                                               "cells": ["d3dgs_blur", "deblur_d3dgs", "e4dgs"]},
                                      "ablation": {"scene": motion_scene.name, "switches": {"w/o AES": {"events.aes": False}}},
                                      "lpips_net": "alex"})


def test_bench_end_to_end_with_resume(motion_scene, tmp_path, monkeypatch):
    from benchmark import job_run as runner     # the serial executor's per-job work

    cfg = _tiny_bench(motion_scene)
    out = tmp_path / "runs"
    real = runner.run_job
    calls = []

    def killed_after_two(job, *a, **k):
        if len(calls) == 2:
            raise KeyboardInterrupt          # a kill between jobs
        calls.append(job.key)
        return real(job, *a, **k)

    monkeypatch.setattr(runner, "run_job", killed_after_two)
    with pytest.raises(KeyboardInterrupt):
        run_bench(cfg, "tiny", motion_scene.parent, out, progress=False, log=lambda s: None)
    first = read_results(out / "results.jsonl")
    assert [r["key"] for r in first] == calls

    resumed = []
    monkeypatch.setattr(runner, "run_job", lambda job, *a, **k: resumed.append(job.key) or real(job, *a, **k))
    rows = run_bench(cfg, "tiny", motion_scene.parent, out, progress=False, log=lambda s: None)
    assert not set(resumed) & set(calls)                     # finished jobs are reused, not retrained
    by_key = {r["key"]: r for r in rows}                     # a folder two jobs share is trained and scored once
    full, main_e4dgs = by_key[f"ablation/{motion_scene.name}/e4dgs/full/seed0"], by_key[f"main/{motion_scene.name}/e4dgs"]
    assert full["key"] not in calls + resumed and full["scored_as"] == main_e4dgs["key"] and full["eval_s"] == 0.0
    assert (full["psnr"], full["lpips"], full["run_dir"]) == (main_e4dgs["psnr"], main_e4dgs["lpips"], main_e4dgs["run_dir"])
    keys = {r["key"] for r in rows}
    assert {f"main/{motion_scene.name}/{c}" for c in MAIN_CELLS} <= keys
    assert f"blur/{motion_scene.name}/d3dgs_blur/mild" in keys and f"blur/{motion_scene.name}/deblur_d3dgs/mild" in keys and f"ablation/{motion_scene.name}/e4dgs/w/o AES/seed0" in keys
    assert not any(k.startswith("blur/") and "/e4dgs/" in k for k in keys)   # events-only: blur cannot matter
    for r in rows:
        assert r["iterations"] == 12 and np.isfinite([r["psnr"], r["ssim"], r["lpips"], r["psnr_luma"]]).all()
        assert r["channels"] == (1 if r["method"] in ("e4dgs", "e2vid_d3dgs") else 3)
        if r["channels"] == 1:                                   # gray methods: luma is their own score
            assert r["psnr_luma"] == pytest.approx(r["psnr"])
        # the main study's curves are scored on every test view; the studies keep the final point only
        scored_in_main = r["study"] == "main" or str(r.get("scored_as", "")).startswith("main/")
        assert [s["iteration"] for s in r["snapshots"]] == ([6, 12] if scored_in_main else [12])
        assert r["versions"]["torch"]
    paths = write_report(rows, out)
    assert (out / "leaderboard.md").exists() and (out / "accuracy_vs_time.png").stat().st_size > 1000
    assert {p.name for p in paths} >= {"leaderboard.md", "leaderboard.csv", "blur.md", "ablation.md"}


# ---------------------------------------------------------------- reports from stored rows

def _row(study, scene, cell, psnr_db, variant="", ssim_v=0.9, lpips_v=0.1, seed=None):
    return described({"key": "/".join(p for p in (study, scene, cell, variant, "" if seed is None else f"seed{seed}") if p),
            "study": study, "scene": scene, "cell": cell, "variant": variant, "seed": seed, "psnr": psnr_db, "ssim": ssim_v, "lpips": lpips_v, "lpips_net": "vgg", "iterations": 10,
            "wall_s": 100.0, "n_gaussians": 1000, "snapshots": [{"iteration": 5, "wall_s": 50.0, "psnr": psnr_db - 1},
                                                              {"iteration": 10, "wall_s": 100.0, "psnr": psnr_db}]})


def test_report_from_stored_results(tmp_path):
    rows = []
    for scene, base in (("a", 20.0), ("b", 22.0)):
        for k, cell in enumerate(MAIN_CELLS):
            rows.append({**_row("main", scene, cell, base + k, lpips_v=0.5 - 0.1 * k), "psnr_luma": 40.0 - k - base})
    del rows[0]["psnr_luma"]                                     # a row recorded before the luma score
    rows += [_row("blur", "a", "d3dgs_blur", 19.0, "mild"), _row("blur", "a", "d3dgs_blur", 17.0, "strong"),
             _row("ablation", "a", "e4dgs", 22.0, "full", seed=0), _row("ablation", "a", "e4dgs", 24.0, "full", seed=1),
             _row("ablation", "a", "e4dgs", 21.0, "w/o TV", seed=0), _row("ablation", "a", "e4dgs", 22.0, "w/o TV", seed=1)]
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    write_report(read_results(tmp_path / "results.jsonl"), tmp_path, "# title")
    md = (tmp_path / "leaderboard.md").read_text()
    line = next(l for l in md.splitlines() if l.startswith("| E-4DGS (events + blurred RGB)"))
    assert "**25.00**" in line and "**27.00**" in line and "**26.00**" in line   # best PSNR: a, b, average
    second = next(l for l in md.splitlines() if l.startswith("| E-4DGS (events) |"))
    assert "<u>24.00</u>" in second and "<u>0.100</u>" in second
    luma = md.split("### The same target")[1]
    first = next(l for l in luma.splitlines() if l.startswith(f"| {LABELS[MAIN_CELLS[0]]} |"))
    assert first == f"| {LABELS[MAIN_CELLS[0]]} | – | **18.00** | – |"      # no luma for a: no average
    assert f"| {LABELS[MAIN_CELLS[1]]} | **19.00** | <u>17.00</u> | **18.00** |" in luma
    board = json.loads((tmp_path / "leaderboard.json").read_text())
    assert board["e4dgs_rgb"]["average"]["psnr"] == pytest.approx(26.0) and set(board["e4dgs"]["scenes"]) == {"a", "b"}
    csv_lines = (tmp_path / "leaderboard.csv").read_text().splitlines()
    assert csv_lines[0].startswith("method,label,a_psnr") and len(csv_lines) == 7
    blur = (tmp_path / "blur.md").read_text()
    assert "19.00" in blur and "17.00" in blur and "24.00" in blur       # events-only row from the main run
    ablation = (tmp_path / "ablation.md").read_text()
    full = next(l for l in ablation.splitlines() if l.startswith("| full |"))
    no_tv = next(l for l in ablation.splitlines() if l.startswith("| w/o TV |"))
    assert "| 2 | 23.00 ± 1.41 |" in full                         # mean ± sample std over the seeds
    assert "| 2 | 21.50 ± 0.71 | -1.50 |" in no_tv
    assert "5 @ 50 s → 19.00" in (tmp_path / "accuracy_vs_time.md").read_text()


def test_ablation_seeds_vary_the_seed_axes_and_seed_0_is_the_main_run():
    cells = {c: CellSpec("e4dgs" if c.startswith("e4dgs") else "d3dgs") for c in MAIN_CELLS}
    cfg = build_config(BenchConfig, {"scenes": ["s"], "cells": cells,
                                     "ablation": {"scene": "s", "seeds": [0, 3],
                                                  "switches": {"w/o AES": {"events.aes": False}}}})
    abl = [j for j in jobs(cfg) if j.study == "ablation"]
    assert sorted(j.key for j in abl) == ["ablation/s/e4dgs/full/seed0", "ablation/s/e4dgs/full/seed3",
                                          "ablation/s/e4dgs/w/o AES/seed0", "ablation/s/e4dgs/w/o AES/seed3"]
    by = {j.key: j for j in abl}
    assert by["ablation/s/e4dgs/w/o AES/seed3"].overrides == {"events.aes": False, "train.seed": 3, "train.init.seed": 3}
    only_train = build_config(BenchConfig, {"scenes": ["s"], "cells": cells, "seed_axes": ["train"], "seeds": 2})
    assert next(j for j in jobs(only_train) if j.key == "main/s/e4dgs/seed1").overrides == {"train.seed": 1}
    with pytest.raises(ConfigError, match="seed_axes"):
        build_config(BenchConfig, {"scenes": ["s"], "cells": cells, "seed_axes": ["weather"]})
    assert by["ablation/s/e4dgs/w/o AES/seed0"].overrides == {"events.aes": False}
    main = next(j for j in jobs(cfg) if j.key == "main/s/e4dgs")
    assert by["ablation/s/e4dgs/full/seed0"].config_hash() == main.config_hash()   # trained once
    with pytest.raises(ConfigError, match="ablation.seeds"):
        build_config(BenchConfig, {"scenes": ["s"], "cells": cells, "ablation": {"scene": "s", "seeds": [1, 1]}})


def test_scene_overrides_change_one_cell_on_one_scene_in_every_study():
    cells = {c: CellSpec("e4dgs" if c.startswith("e4dgs") else "d3dgs", overrides={"train.iterations": 300})
             for c in MAIN_CELLS}
    raw = {"scenes": ["a", "b"], "cells": cells, "blur": {"scene": "b", "cells": ["d3dgs_blur"]},
           "ablation": {"scene": "b", "switches": {"w/o TV": {"events.lambda_tv": 0.0}}},
           "scene_overrides": {"b": {"d3dgs_blur": {"train.iterations": 120}, "e4dgs": {"train.iterations": 90}}}}
    by = {j.key: j for j in jobs(build_config(BenchConfig, raw))}
    assert by["main/a/d3dgs_blur"].overrides == {"train.iterations": 300}           # other scenes untouched
    assert by["main/b/d3dgs_blur"].overrides == {"train.iterations": 120}
    assert by["main/b/d3dgs_sharp"].overrides == {"train.iterations": 300}         # other cells untouched
    assert by["blur/b/d3dgs_blur/mild"].overrides == {"train.iterations": 120, "frames": "mild"}
    assert by["ablation/b/e4dgs/w/o TV/seed0"].overrides == {"train.iterations": 90, "events.lambda_tv": 0.0}
    assert by["ablation/b/e4dgs/full/seed0"].config_hash() == by["main/b/e4dgs"].config_hash()
    with pytest.raises(ConfigError, match="scene_overrides: 'c'"):
        build_config(BenchConfig, {**raw, "scene_overrides": {"c": {}}})
    with pytest.raises(ConfigError, match="scene_overrides.b: 'd3dgs'"):
        build_config(BenchConfig, {**raw, "scene_overrides": {"b": {"d3dgs": {}}}})


def test_a_scene_subset_runs_when_another_scene_has_overrides(motion_scene, tmp_path):
    """`e4dgs bench --scenes hinge` on a preset whose scene_overrides name other scenes (the quick one)."""
    cfg = _tiny_bench(motion_scene)
    cfg = build_config(BenchConfig, {"dataset": cfg.dataset, "scenes": [motion_scene.name, "elsewhere"],
                                     "cells": cfg.cells, "lpips_net": "alex",
                                     "scene_overrides": {"elsewhere": {"e4dgs": {"train.iterations": 5}}}})
    rows = run_bench(cfg, "tiny", motion_scene.parent, tmp_path, scenes=[motion_scene.name], cells=["e4dgs"],
                     studies=("main",), progress=False, log=lambda s: None)
    assert [(r["scene"], r["iterations"]) for r in rows] == [(motion_scene.name, 12)]


def test_report_refuses_empty_results(tmp_path):
    with pytest.raises(ValueError, match="no results"):
        write_report([], tmp_path)


def test_bench_report_cli_regenerates_without_training(tmp_path):
    from e4dgs.cli import main

    from scene_format.manifest import masks_digest

    hashes = {j.key: j.config_hash() for j in jobs(load_bench("quick"))}    # rows of the preset's own jobs
    masks = masks_digest(Path("data") / "quick" / "lego")       # "none" unless this checkout generated it
    rows = [{**_row("main", "lego", c, 20.0 + k), "config_hash": hashes[f"main/lego/{c}"], "masks": masks}
            for k, c in enumerate(MAIN_CELLS)]
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    assert main(["bench", "--preset", "quick", "--out", str(tmp_path), "--report"]) == 0
    md = (tmp_path / "leaderboard.md").read_text()
    assert "`quick` preset" in md and "2-core CPU" in md and "**25.00**" in md
    with pytest.raises(SystemExit, match="nosuch"):
        main(["bench", "--preset", "nosuch", "--report"])
    with pytest.raises(SystemExit, match="not in preset"):
        main(["bench", "--preset", "quick", "--scenes", "atlantis", "--out", str(tmp_path)])


def test_bench_train_breakdown_times_every_part_inside_an_iteration():
    """The training benchmark's timers: raster forward/backward and MLP forward/backward are all seen
    inside one deformed render's forward + backward, each shorter than the whole, and undone after."""
    import time

    import torch

    from tools.bench_train import PARTS, Clock, instrument
    from recon.deform import DeformationField
    from recon.gaussians import GaussianModel
    from recon.raster import Camera
    from recon.render import render_at

    from recon.render import render_views_times

    clock = Clock()
    original = DeformationField.forward, DeformationField.forward_times
    restore = instrument(clock)
    try:
        g = GaussianModel.from_points(np.random.default_rng(0).uniform(-0.5, 0.5, (300, 3)), channels=1)
        field = DeformationField()
        cam = Camera(torch.tensor([[60.0, 0, 32], [0, 60.0, 24], [0, 0, 1]]),
                     torch.tensor([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 3], [0, 0, 0, 1]]), 64, 48)
        # one time (render_at: forward), and E-4DGS's two ends of a window in one call (forward_times)
        for precision, times in [("float32", None), ("bfloat16", None), ("float32", [0.4, 0.5]), ("bfloat16", [0.4, 0.5])]:
            clock.parts = dict.fromkeys(PARTS, 0.0)
            t0 = time.perf_counter()
            if times is None:
                images = [render_at(g, field, cam, 0.4, torch.zeros(1), "cpu", precision).image]
            else:
                images = [o[0].image for o in render_views_times(g, field, [[cam], [cam]], times, torch.zeros(1),
                                                                   "cpu", precision)]
            (sum(im.square().mean() for im in images) + g.means.sum() * 0).backward()
            total = time.perf_counter() - t0
            seen = ("raster_fwd", "raster_bwd", "mlp_fwd", "mlp_bwd")     # an MLP render: no trajectory, data or Adam
            assert all(0 < clock.parts[p] < total for p in seen), (precision, clock.parts)
            assert all(clock.parts[p] == 0 for p in PARTS if p not in seen), clock.parts
            assert not clock.mlp_started
    finally:
        restore()
    assert (DeformationField.forward, DeformationField.forward_times) == original


def test_bench_train_times_a_trained_state_with_its_data_and_optimiser(motion_scene, tmp_path):
    """--model: the worker's trainer holds the saved Gaussians (and the saved field where it is the
    worker's), and an E-4DGS iteration there times its event data, its trajectories and Adam."""
    import torch

    import recon
    from recon.event_windows import WindowSampler
    from recon.trajectory import TrajectoryField
    from tools import bench_train as bt

    over = {"train.iterations": 6, "train.warm_up": 2, "train.scale_schedule": False, "train.init.kind": "cube",
            "train.init.n_points_object": 300, "train.snapshots": [1.0], "train.densify.enabled": False,
            "train.deform_field.kind": "trajectory"}
    saved = recon.fit(motion_scene, "e4dgs", overrides=over, out_dir=tmp_path / "run", progress=False).model
    sample, deform = WindowSampler.sample, TrajectoryField.deform
    clock = bt.Clock()
    restore = bt.instrument(clock)
    try:
        for kind in ("trajectory", "mlp"):
            trainer = bt.build_trainer(str(motion_scene), "e4dgs", 300, "late", str(tmp_path / kind),
                                       {"train.deform_field.kind": kind}, str(tmp_path / "run" / "model.pt"))
            assert len(trainer.model) == len(saved)
            assert torch.equal(trainer.model.gaussians.means.detach().cpu(), saved.gaussians.means.detach().cpu())
            row = bt.one_iteration(trainer, clock)
            assert row["data"] > 0 and row["optimiser"] > 0 and row["raster_fwd"] > 0
            assert (row["trajectory_fwd"] > 0) == (kind == "trajectory") and (row["mlp_fwd"] > 0) == (kind == "mlp")
            if kind == "trajectory":     # the saved trajectories came with it
                assert torch.equal(trainer.model.gaussians.motion.detach().cpu(), saved.gaussians.motion.detach().cpu())
    finally:
        restore()
    assert WindowSampler.sample is sample and TrajectoryField.deform is deform


def test_a_bad_override_is_refused_before_any_job_runs(motion_scene, tmp_path):
    cfg = _tiny_bench(motion_scene)
    cells = dict(cfg.cells)
    cells["e4dgs"] = CellSpec("e4dgs", overrides={**TINY_TRAIN, "events.lamda_tv": 0.1})   # typo, in a later cell
    cfg = build_config(BenchConfig, {**{k: getattr(cfg, k) for k in ("dataset", "scenes", "lpips_net")},
                                     "cells": cells})
    with pytest.raises(ConfigError, match="bench job main/.*/e4dgs .*events.lamda_tv: unknown key"):
        run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "out", progress=False, log=lambda s: None)
    assert not (tmp_path / "out").exists()                  # nothing trained, nothing written


def test_the_blur_study_sets_the_level_through_each_methods_own_field(motion_scene):
    blur = {j.cell: j.overrides for j in jobs(_tiny_bench(motion_scene)) if j.study == "blur" and j.variant == "mild"}
    assert blur["d3dgs_blur"]["frames"] == "mild" and blur["deblur_d3dgs"]["frames"] == "mild"
    assert "e4dgs" not in blur                                # events only: one run stands for every level


def test_a_method_s_input_files_are_part_of_its_run_folder(tmp_path):
    """E2VID + D3DGS's weights are an input (Method.input_files): other weights, another folder; the
    digest is the file's, under the key the folder hash always used."""
    from e2vid.weights import default_weights_path
    from recon.methods import get_method

    other = tmp_path / "other.pt"
    other.write_bytes(default_weights_path().read_bytes() + b"\0")
    cells = {"e2vid_d3dgs": CellSpec("e2vid_d3dgs"), "e2vid_other": CellSpec("e2vid_d3dgs", overrides={"weights": str(other)}),
             "e4dgs": CellSpec("e4dgs")}
    by = {j.cell: j for j in jobs(build_config(BenchConfig, {"scenes": ["s"], "cells": cells}))}
    assert by["e2vid_d3dgs"].folder != by["e2vid_other"].folder
    assert by["e2vid_d3dgs"]._input_digests() == {
        "weights_sha256": __import__("hashlib").sha256(default_weights_path().read_bytes()).hexdigest()}
    assert by["e4dgs"]._input_digests() == {} and get_method("d3dgs").input_digests(None) == {}


def test_results_rows_are_typed_where_they_are_read_and_written(tmp_path):
    from benchmark.rows import read_results, write_results

    good = _row("main", "s", "d3dgs_sharp", 20.0)
    path = tmp_path / "results.jsonl"
    write_results(path, [good, {**_row("main", "s", "e4dgs", 0.0), "status": "failed", "error": "x"}])
    assert [r["key"] for r in read_results(path)] == ["main/s/d3dgs_sharp", "main/s/e4dgs"]
    for bad, words in (({**good, "psnr": "21.3"}, r":1: psnr: expected a number, got '21.3'"),
                       ({**good, "iterations": 1.5}, r":1: iterations: expected a number or null, got 1.5"),
                       ({**good, "psnr": True}, r":1: psnr: expected a number, got True"),
                       ({k: v for k, v in good.items() if k != "ssim"}, r":1: missing ssim"),
                       ({**good, "snapshots": [{"iteration": 5, "psnr": None}]}, r"snapshots\[0\]: psnr: expected a number"),
                       ([1, 2], r":1: expected a JSON object")):
        path.write_text(json.dumps(bad) + "\n")
        with pytest.raises(ValueError, match=words):
            read_results(path)
    path.write_text(json.dumps(good) + "\n")
    with pytest.raises(ValueError, match=r"row 2 to write \(main/s/d3dgs_blur\): psnr"):
        write_results(path, [good, {**_row("main", "s", "d3dgs_blur", 1.0), "psnr": float("nan")}])
    assert json.loads(path.read_text()) == good          # nothing written when a row is wrong


def test_report_names_the_cpu_and_only_real_speed_variants_and_plots_without_warnings(tmp_path):
    import warnings

    from benchmark.report import leaderboard, plot_accuracy_vs_time

    rows = [{**_row("main", "a", cell, 20.0 + k), "speed": speed, "cpu": "AMD EPYC (avx2 fma)", "precision": "float32"}
            for k, (cell, speed) in enumerate(zip(MAIN_CELLS, (None, 1.0, 37.6, 1, None, None)))]
    md, _ = leaderboard(rows)
    assert "Train times measured on: AMD EPYC (avx2 fma), deformation in float32." in md
    speeds = next(line for line in md.splitlines() if line.startswith("Speed variants:"))
    assert "x37.6" in speeds and "x1 " not in speeds and "x1;" not in speeds and speeds.count(" at x") == 1
    md, _ = leaderboard([{**r, "speed": 1.0} for r in rows])
    assert "Speed variants:" not in md                 # every cell on the scene itself: nothing to say
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # "No artists with labels found to put in legend"
        plot_accuracy_vs_time([{**r, "snapshots": []} for r in rows], tmp_path / "a.png")
    assert (tmp_path / "a.png").stat().st_size > 1000


def test_bench_help_lists_every_shipped_preset(capsys):
    from e4dgs.cli import main

    with pytest.raises(SystemExit):
        main(["bench", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "quick | paper | tiny, or a bench YAML file" in text


def test_the_old_gpu_preset_is_the_paper_preset_with_every_cell_on_cuda():
    """paper_gpu.yaml copied paper.yaml; it is now `--preset paper --set train.device=cuda --set
    train.backend=gsplat`, and the old name keeps working until 0.3 with a deprecation line."""
    from benchmark.config import load_bench
    from common.config_files import DeprecatedName

    with pytest.warns(DeprecatedName, match="--preset paper --set train.device=cuda --set train.backend=gsplat"):
        old = load_bench("paper_gpu")
    new = load_bench("paper", {"train.device": "cuda", "train.backend": "gsplat"})
    assert old == new and old.scenes == load_bench("paper").scenes
    for name, cell in new.cells.items():
        assert cell.overrides["train.device"] == "cuda" and cell.overrides["train.backend"] == "gsplat", name
        assert {k: v for k, v in cell.overrides.items() if not k.startswith("train.")} == \
            {k: v for k, v in load_bench("paper").cells[name].overrides.items() if not k.startswith("train.")}


@pytest.mark.parametrize("cell", ["d3dgs_sharp", "e2vid_d3dgs"])
def test_a_job_resolves_its_config_once_opens_its_scene_once_and_never_reads_its_log_back(motion_scene, tmp_path,
                                                                                         monkeypatch, cell):
    """One bench job's reads, counted by patching the readers (before this was tidied: the config
    resolved 5 times, the scene opened twice, manifest.json read 3 times, log.jsonl read back once and
    the job's config hash computed 8 times)."""
    import builtins
    import collections
    import io

    import recon.api as api
    import scene_format.reader as reader
    from benchmark.grid import Job

    from benchmark.grid import _resolved

    _resolved.cache_clear()                  # configs resolved by earlier tests of this process
    counts = collections.Counter()
    real_open, real_resolve, real_init = builtins.open, api.resolve_config, reader.SceneDataset.__init__
    real_hash = Job._config_hash.func

    def counting_open(file, mode="r", *a, **k):
        if "r" in mode and str(file).endswith(("manifest.json", "log.jsonl", "scene.yaml", "cameras.json",
                                               "/quick.yaml")):
            counts[Path(str(file)).name] += 1
        return real_open(file, mode, *a, **k)

    def resolve(*a, **k):
        counts["resolve_config"] += 1
        return real_resolve(*a, **k)

    def opened(self, *a, **k):
        counts["SceneDataset"] += 1
        real_init(self, *a, **k)

    def hashed(self):
        counts["config_hash"] += 1
        return real_hash(self)

    monkeypatch.setattr(builtins, "open", counting_open)
    monkeypatch.setattr(io, "open", counting_open)                 # pathlib's read_text / read_bytes
    monkeypatch.setattr(api, "resolve_config", resolve)
    monkeypatch.setattr(reader.SceneDataset, "__init__", opened)
    cached = functools.cached_property(hashed)
    cached.__set_name__(Job, "_config_hash")
    monkeypatch.setattr(Job, "_config_hash", cached)
    spec = (CellSpec("d3dgs", overrides={**TINY_TRAIN, "frames": "sharp"}) if cell == "d3dgs_sharp" else
            CellSpec("e2vid_d3dgs", config="e2vid_d3dgs/quick",
                     overrides={**TINY_TRAIN, "train.coarse_to_fine.factors": [], "train.coarse_to_fine.until": []}))
    cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name], "cells": {cell: spec}})
    rows = run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "runs", studies=("main",), progress=False,
                     log=lambda s: None)
    assert [r["cell"] for r in rows] == [cell] and rows[0].get("status") != "failed", rows[0].get("error")
    # manifest.json twice: the job's identity digests the scene's content before it trains, then the scene opens;
    # the recipe file (E2VID + D3DGS's) once, where its config is resolved
    recipe = {"quick.yaml": 1} if cell == "e2vid_d3dgs" else {}
    assert counts == {"resolve_config": 1, "SceneDataset": 1, "config_hash": 1, "manifest.json": 2,
                      "scene.yaml": 1, "cameras.json": 1, **recipe}, counts
    counts.clear()                       # the report step reads rows, not recipe files or scenes
    write_report(rows, tmp_path / "tables", "", cfg)
    assert counts == {}, counts


def test_tables_leave_out_rows_of_jobs_the_preset_no_longer_has():
    """A row made under another cap or speed list stays in results.jsonl but not in the tables; the
    current jobs' rows, rows scored from outside and ablation rows of a seed chosen at run time stay."""
    from dataclasses import replace

    from benchmark.grid import current_rows

    cfg = load_bench("quick")
    from scene_format.manifest import masks_digest

    def scored(j):            # a row scored as the preset scores now (masks: "none" unless data/quick exists here)
        return {**j.identity(), "lpips_net": cfg.lpips_net, "masks": masks_digest(j.data_dir)}

    current = [scored(j) for j in jobs(cfg)]
    speed_row = next(r for r in current if r["study"] == "speed" and r["variant"] == "x26.2")
    old_speed = {**speed_row, "key": speed_row["key"].replace("x26.2", "x31.6"), "variant": "x31.6"}
    old_cap = {**current[0], "config_hash": "0" * 16}
    outside = {"key": "main/hinge/mine", "study": "main", "config_hash": "abc", "external": True}
    extra_seed = [scored(j) for j in jobs(replace(cfg, ablation=replace(cfg.ablation, seeds=(7,))))
                  if j.study == "ablation"]
    kept, stale = current_rows(cfg, current + [old_speed, old_cap, outside] + extra_seed)
    assert stale == [old_speed, old_cap]
    order = {s: i for i, s in enumerate(cfg.scenes)}
    assert kept == sorted(current + [outside] + extra_seed, key=lambda r: order.get(r.get("scene"), len(order)))
    # a scene re-run last (its rows at the end of results.jsonl) keeps its place in the tables
    first = [r for r in current if r.get("scene") == cfg.scenes[0]]
    rest = [r for r in current if r.get("scene") != cfg.scenes[0]]
    kept, _ = current_rows(cfg, rest + first)
    assert [r.get("scene") for r in kept][:len(first)] == [cfg.scenes[0]] * len(first)


def test_bench_train_times_the_mlp_at_each_precision_and_the_trajectories_beside_it():
    """train.precision is the MLP's dtype: a precision worker that kept the configs' own field (the
    trajectory, always float32) would time the same thing three times, as it once did."""
    from tools.bench_train import worker_specs

    specs = worker_specs(["auto", "float32", "bfloat16"], ["trajectory"], [2, 4])
    assert [(o.get("train.precision"), o.get("train.deform_field.kind"), f) for _, o, f in specs] == [
        ("auto", "mlp", 1), ("float32", "mlp", 1), ("bfloat16", "mlp", 1),
        (None, "trajectory", 1), (None, "trajectory", 2), (None, "trajectory", 4)]
    assert len({label for label, _, _ in specs}) == len(specs)
    assert worker_specs(None, [], []) == [("this tree", {}, 1)]      # the configs' own field and precision
    # --against pairs this tree's workers with the revision's factor by factor
    from tools.bench_train import revision_factors
    assert [f for _, _, f in worker_specs(None, [], [2, 4])] == revision_factors([2, 4]) == [1, 2, 4]
    # ... and runs with the same --set overrides, so the trees differ in their code only
    from tools.bench_train import revision_specs
    sets = {"train.deform_field.width": 96}
    assert revision_specs("abc", [2], sets) == [("abc", sets, 1), ("abc, 1/2 resolution", sets, 2)]


def test_a_study_the_preset_lacks_is_an_error_and_leaves_nothing(tmp_path, capsys):
    """`bench --studies speed` on a preset without a speed study: one clear line, exit non-zero, no
    results folder and no dataset started."""
    from e4dgs.cli import main

    out = tmp_path / "runs"
    rc = main(["bench", "--preset", "tiny", "--studies", "speed", "--out", str(out), "--data", str(tmp_path / "data")])
    err = capsys.readouterr().err
    assert rc != 0 and "no job for studies speed" in err and len(err.strip().splitlines()) == 1, err
    assert not out.exists() and not (tmp_path / "data").exists()


def test_the_sensor_axis_moves_the_event_cells_to_the_sensors_dataset(tmp_path, capsys, monkeypatch):
    """`bench --sensor davis346`: the cells whose method sees events train on <dataset>@davis346 (their
    own keys and folders), the RGB cells keep the dataset's frames, results go to runs/<preset>@<sensor>;
    an unknown sensor or a path is refused in one line."""
    from dataclasses import replace

    from benchmark.config import load_bench
    from benchmark.grid import jobs
    from e4dgs.cli import main

    cfg = replace(load_bench("quick"), sensor="davis346", seeds=2, seed_axes=("train", "noise"))
    by = {j.key: j for j in jobs(cfg) if j.study == "main"}
    assert by["main/quick@davis346/hinge/e4dgs"].dataset == "quick@davis346"
    assert by["main/quick@davis346@noise1/hinge/e4dgs/seed1"].dataset == "quick@davis346@noise1"
    assert by["main/hinge/d3dgs_sharp"].dataset == "" and by["main/quick@noise1/hinge/d3dgs_blur/seed1"]
    assert by["main/quick@davis346/hinge/e2vid_d3dgs"].folder.startswith("quick@davis346/hinge_x26.2/")
    monkeypatch.chdir(tmp_path)
    rc = main(["bench", "--preset", "tiny", "--sensor", "davis346", "--report"])
    assert rc != 0 and "runs/tiny@davis346: no results to report" in capsys.readouterr().err
    for bad, words in (("davis999", "unknown sensor 'davis999'"), ("../x", "expected the name of a sensor")):
        try:
            rc = main(["bench", "--preset", "tiny", "--sensor", bad, "--report"])
        except SystemExit as exc:
            rc, err = 2, str(exc.code)
        else:
            err = capsys.readouterr().err
        assert rc != 0 and words in err, err
    assert not (tmp_path / "runs").exists()
