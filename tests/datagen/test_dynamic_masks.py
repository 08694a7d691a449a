"""Dynamic-region masks and the scores over them: the motion of surface points solved by hand, the
masked metrics' invariants, the generator's masks on a board that moves everywhere, `e4dgs masks`
reproducing the generator's, and the benchmark scoring old rows again without training."""
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from common.metrics.image import psnr_region, score_pairs, ssim, ssim_with_region
from common.metrics.lpips import lpips_with_region
from scene_format.cameras import intrinsics_from_fov, look_at_opencv
from datagen.dynamic import THRESHOLD_PX, mask_image, surface_motion_px

ROOT = Path(__file__).resolve().parents[2]
FPS = 3000.0


def test_surface_motion_of_a_translating_and_a_turning_part_solved_by_hand():
    """Part 0 slides along y at v m/s; part 1 turns about the z axis through its own point. Seen from
    4 m at the view's time index i, part 0 moved fx * v * max(i, T-1-i) / (fps * 4) px at most; the
    point on part 1's axis never moves."""
    T, v, i = 31, 30.0, 10
    fx = intrinsics_from_fov(346, 260, 50.0).fx
    c2w = look_at_opencv((4.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    mats = np.tile(np.eye(4), (T, 2, 1, 1))
    mats[:, 0, 1, 3] = v * np.arange(T) / FPS
    ang = np.linspace(0, 1.0, T)
    mats[:, 1, 0, 0], mats[:, 1, 0, 1], mats[:, 1, 1, 0], mats[:, 1, 1, 1] = np.cos(ang), -np.sin(ang), np.sin(ang), np.cos(ang)
    local = np.array([[0.0, 0.2, 0.3], [0.0, -0.5, 0.1], [0.0, 0.0, 0.4]])
    px = surface_motion_px(local, np.array([0, 0, 1]), mats, c2w, fx, i, chunk=7)
    expected = fx * v * max(i, T - 1 - i) / FPS / 4.0
    np.testing.assert_allclose(px[:2], expected, rtol=1e-9)
    assert px[2] == pytest.approx(0.0, abs=1e-9)
    hit = np.array([False, True, True, False, True, False])            # a 3x2 image, 3 rays hit
    m = mask_image(hit, np.array([THRESHOLD_PX, 0.5, 9.0]), 3, 2)
    assert m.tolist() == [[False, True, False], [False, True, False]]


def _pair(rng, h=40, w=48, c=3):
    gt = rng.uniform(0.2, 0.8, (h, w, c)).astype(np.float32)
    pred = np.clip(gt + rng.normal(0, 0.05, gt.shape), 0, 1).astype(np.float32)
    return pred, gt


def test_region_scores_of_a_full_mask_are_the_whole_image_scores(rng):
    pred, gt = _pair(rng)
    ones = np.ones(gt.shape[:2], bool)
    s, s_dyn = ssim_with_region(pred, gt, ones)
    assert s_dyn == pytest.approx(s, abs=1e-12) and s == pytest.approx(ssim(pred, gt), abs=1e-12)
    whole, region = lpips_with_region(pred, gt, "alex", ones)
    assert region == pytest.approx(whole, abs=1e-6)
    out = score_pairs([(pred, gt)], lpips_net=None, masks=[ones])
    assert out["psnr_dyn"] == pytest.approx(out["psnr"], abs=1e-9) and out["dyn_fraction"] == 1.0


def test_region_scores_see_only_the_masked_pixels(rng):
    pred, gt = _pair(rng)
    mask = np.zeros(gt.shape[:2], bool)
    mask[10:30, 12:36] = True
    exact_inside = np.where(mask[..., None], gt, pred)                  # errors only outside the region
    assert psnr_region(exact_inside, gt, mask) == 100.0
    worse = np.where(mask[..., None], np.clip(gt + 0.2, 0, 1), gt)      # errors only inside
    out = score_pairs([(worse, gt), (gt, gt)], lpips_net=None, masks=[mask, None])
    mse_in = float(np.mean((np.clip(gt + 0.2, 0, 1) - gt)[mask] ** 2))
    assert out["psnr_dyn"] == pytest.approx(10 * np.log10(1 / mse_in), abs=1e-6)
    assert out["n_dyn_images"] == 1 and out["dyn_fraction"] == pytest.approx(mask.mean() / 2)
    assert out["psnr_dyn"] < out["psnr"]                                # the static part dilutes the whole image
    assert score_pairs([(worse, gt)], lpips_net=None).keys().isdisjoint({"psnr_dyn", "ssim_dyn"})


def _generate(out: Path, yaml: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", yaml.stem, "--preset",
                           str(ROOT / "configs" / "datasets" / "paper.yaml"), "--out", str(out), "--no-progress",
                           "--scene-config", str(yaml)], capture_output=True, text=True, cwd=ROOT)


def test_a_board_moving_everywhere_is_dynamic_everywhere_and_e4dgs_masks_reproduces_the_generator(tmp_path):
    """blur_plane: a board filling the view slides 2 m over the clip, every visible point moves >= 1 m
    (fx * 1 / 3.99 ~ 8.6 px at 64 px wide): every pixel of every test view is dynamic."""
    r = _generate(tmp_path, ROOT / "blender_scenes" / "blur_plane.yaml")
    assert r.returncode == 0, r.stderr
    scene = tmp_path / "blur_plane"
    meta = json.loads((scene / "dynamic" / "masks.json").read_text())
    assert meta["threshold_px"] == THRESHOLD_PX and meta["views"]
    assert all(v["dynamic_fraction"] == 1.0 for v in meta["views"])
    manifest = json.loads((scene / "manifest.json").read_text())
    assert "dynamic/masks.json" in manifest["files"]
    generated = {p.relative_to(scene): p.read_bytes() for p in (scene / "dynamic").rglob("*") if p.is_file()}
    sheet = cv2.imread(str(scene / "preview" / "contact_sheet.png"))
    assert sheet.shape[1] == 64 * (3 + len(manifest["blur"]["levels"]))   # sharp | levels | events | dynamic
    import shutil
    shutil.rmtree(scene / "dynamic")
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "masks", str(tmp_path)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    again = {p.relative_to(scene): p.read_bytes() for p in (scene / "dynamic").rglob("*") if p.is_file()}
    assert again == generated


def test_masks_of_a_scene_with_static_and_moving_parts(motion_scene):
    """tiny_motion cubes: only the cubes move; their pixels are a proper part of each view."""
    from scene_format.reader import SceneDataset

    ds = SceneDataset(motion_scene)
    fractions = [ds.dynamic_mask(r).mean() for r in ds.frames("test")]
    assert all(0.02 < f < 0.9 for f in fractions)


def test_rows_without_region_scores_are_scored_again_without_training(motion_scene, tmp_path):
    from benchmark.config import BenchConfig, CellSpec
    from benchmark.runner import read_results, run_bench, write_results
    from common.config import build_config

    tiny = {"train.iterations": 8, "train.scale_schedule": False, "train.warm_up": 200, "train.densify.enabled": False,
            "train.init.n_points_object": 200, "train.snapshots": [1.0]}
    cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name], "lpips_net": "alex",
                                     "cells": {"s": CellSpec("d3dgs", overrides={**tiny, "frames": "sharp"})}})
    out = tmp_path / "runs"
    (row,) = run_bench(cfg, "t", motion_scene.parent, out, studies=("main",), progress=False, log=lambda s: None)
    assert {"psnr_dyn", "ssim_dyn", "lpips_dyn", "floor_psnr_dyn"} <= set(row)
    old = {k: v for k, v in row.items() if not k.endswith("_dyn") and k not in ("dyn_fraction", "n_dyn_images")}
    old["train_elapsed_s"] = 1234.5                                    # a row scored before masks existed
    write_results(out / "results.jsonl", [old])
    log_lines = len((out / row["run_dir"] / "log.jsonl").read_text().splitlines())
    (again,) = run_bench(cfg, "t", motion_scene.parent, out, studies=("main",), progress=False, log=lambda s: None)
    assert again["psnr_dyn"] == pytest.approx(row["psnr_dyn"], abs=1e-9) and again["psnr"] == pytest.approx(row["psnr"])
    assert again["train_elapsed_s"] == 1234.5 and "rescored_unix" in again
    assert len((out / row["run_dir"] / "log.jsonl").read_text().splitlines()) == log_lines     # nothing trained
    assert read_results(out / "results.jsonl")[0]["psnr_dyn"] == again["psnr_dyn"]


def test_the_leaderboard_and_the_speed_study_show_the_region_scores(tmp_path):
    from bench_cells import LABELS, described
    from benchmark.report import write_report
    from benchmark.speed_report import speed_tables

    def row(cell, scene, whole, dyn, study="main", speed=None):
        r = described({"key": f"{study}/{scene}/{cell}/{speed or ''}", "study": study, "scene": scene, "cell": cell,
                       "variant": f"x{speed:g}" if speed else "", "speed": speed, "psnr": whole, "ssim": 0.9,
                       "lpips": 0.2, "psnr_luma": whole, "wall_s": 10.0, "iterations": 5, "n_gaussians": 3,
                       "snapshots": [], "floor_psnr": 10.0, "floor_psnr_luma": 10.0})
        if dyn is not None:
            r.update(psnr_dyn=dyn, ssim_dyn=dyn / 40, lpips_dyn=1 / dyn, dyn_fraction=0.25, floor_psnr_dyn=9.0)
        return r

    rows = [row("d3dgs_sharp", "a", 30.0, 20.0), row("e4dgs", "a", 25.0, 22.0)]
    write_report(rows, tmp_path)
    md = (tmp_path / "leaderboard.md").read_text()
    table = md.split("### Dynamic region")[1]
    assert f"| {LABELS['e4dgs']} | **22.00** (25.00) | **22.00** (25.00) | **0.550** | **0.045** |" in table
    assert f"| {LABELS['d3dgs_sharp']} | <u>20.00</u> (30.00) |" in table and "a 25.0 %" in table
    assert "### Dynamic region" not in (write_report([row("e4dgs", "a", 25.0, None)], tmp_path) and
                                        (tmp_path / "leaderboard.md").read_text())
    speed = [row("d3dgs_blur", "a", 20.0, 15.0, "speed", 2.0), row("e4dgs", "a", 19.0, 16.0, "speed", 2.0)]
    md = speed_tables(speed)
    assert "dynamic region (paper protocol over the pixels that move)" in md
    assert f"| {LABELS['e4dgs']} | 16.00 (9.00) |" in md
    assert "dynamic region" not in speed_tables([{**r, "psnr_dyn": None} for r in speed])
