"""`e4dgs score` and `e4dgs testviews`: outside renders scored by the leaderboard's protocol.

A bundled method's renders, written to a folder and scored, give its benchmark row's numbers; an
outside method that reads only the exported files scores what a hand computation says; bad renders
are refused with one line naming the file, and nothing is appended."""
import json
import math
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmark.config import BenchConfig, CellSpec
from benchmark.runner import read_results, run_bench
from benchmark.score import score_renders
from benchmark.testviews import test_views as views_of
from common.config import build_config
from common.imageio import write_exr
from scene_format.reader import SceneDataset
from e4dgs.cli import main as e4dgs
from recon.cli import render_test_views
from recon.model import load

TINY = {"train.iterations": 12, "train.scale_schedule": False, "train.warm_up": 200, "train.densify.enabled": False,
        "train.init.n_points_object": 300, "train.checkpoint_every": 6, "train.snapshots": [0.5, 1.0]}


@pytest.fixture(scope="module")
def benched(motion_scene, tmp_path_factory):
    """A tiny bench of one RGB cell and one events-only cell: (results folder, rows by cell)."""
    cells = {"d3dgs_sharp": CellSpec("d3dgs", "D3DGS (sharp RGB)", overrides={**TINY, "frames": "sharp"}),
             "e4dgs": CellSpec("e4dgs", "E-4DGS (events)", overrides=TINY)}
    cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name], "cells": cells,
                                     "lpips_net": "alex"})
    out = tmp_path_factory.mktemp("runs")
    rows = run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=lambda s: None)
    return out, {r["cell"]: r for r in rows}


@pytest.mark.parametrize("cell,inputs", [("d3dgs_sharp", "rgb"), ("e4dgs", "events")])
def test_bundled_renders_scored_from_a_folder_equal_the_benchmark_row(benched, motion_scene, tmp_path, cell, inputs):
    out, rows = benched
    row = rows[cell]
    renders = tmp_path / "renders"
    n = render_test_views(load(out / row["run_dir"]), motion_scene, renders / motion_scene.name, "exr")
    assert n == row["n_test_images"]
    (ext,) = score_renders(motion_scene.parent, renders, f"outside_{cell}", inputs, lpips_net="alex", log=lambda s: None)
    # the row scores the 16-bit views it keeps (recon.view_record), these the float EXRs: 1/65535 apart
    for k in ("psnr", "psnr_luma", "ssim", "lpips", "psnr_dyn", "ssim_dyn", "lpips_dyn"):
        assert ext[k] == pytest.approx(row[k], abs=1e-4), k
    assert ext["external"] and ext["inputs"] == row["inputs"] and ext["scene"] == row["scene"]


def test_score_cli_appends_external_rows_and_the_leaderboard_shows_them(benched, motion_scene, tmp_path):
    out, rows = benched
    renders = tmp_path / "renders"
    for seconds in ("", "snapshots/2.5"):
        render_test_views(load(out / rows["e4dgs"]["run_dir"]), motion_scene, renders / motion_scene.name / seconds, "png")
    results = tmp_path / "results.jsonl"
    results.write_text("".join(json.dumps(r) + "\n" for r in rows.values()))
    assert e4dgs(["score", "--data", str(motion_scene.parent), str(renders), "--name", "mine",
                  "--label", "My method (events)", "--inputs", "events", "--train-seconds", "5", "--lpips", "none",
                  "--out", str(tmp_path)]) == 0
    stored = {r["key"]: r for r in read_results(results)}
    mine = stored[f"main/{motion_scene.name}/mine"]
    assert len(stored) == 3 and mine["external"] and mine["wall_s"] == 5.0
    assert [p["wall_s"] for p in mine["snapshots"]] == [2.5, 5.0]
    # its scored views are kept in the results folder: `e4dgs verify` re-derives the row like a bench row's
    assert mine["views_dir"] == f"external/mine/{motion_scene.name}/views"
    verify = ["verify", str(tmp_path), "--data", str(motion_scene.parent), "--keys", mine["key"]]
    assert e4dgs(verify) == 0
    doc = json.loads((tmp_path / mine["views_dir"] / "views.json").read_text())
    png = tmp_path / mine["views_dir"] / doc["views"][0]["render"]
    png.write_bytes(png.read_bytes()[:-20] + b"\0" * 20)
    assert e4dgs(verify) == 1
    assert mine["snapshots"][0]["psnr"] == pytest.approx(mine["psnr"], abs=0.5)   # 8-bit PNG of the same model
    board = (tmp_path / "leaderboard.md").read_text()
    assert "| My method (events) |" in board and "Scored from outside renders" in board
    # scoring again replaces its rows instead of adding more
    assert e4dgs(["score", "--data", str(motion_scene.parent), str(renders), "--name", "mine",
                  "--inputs", "events", "--lpips", "none", "--out", str(tmp_path)]) == 0
    assert len(read_results(results)) == 3


# ---------------------------------------------------------------- an outside method, no project imports

OUTSIDE = '''
import json, sys
from pathlib import Path
import cv2, numpy as np

scene, out, tv_file = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3])
tv = json.loads(tv_file.read_text())
train = json.loads((scene / "transforms_train.json").read_text())["frames"]
for v in tv["views"]:                      # nearest training frame of the same camera, copied as the render
    best = min((f for f in train if f["camera"] == v["camera"]), key=lambda f: abs(f["time"] - v["time"]))
    img = cv2.imread(str(scene / (best["file_path"] + ".png")), cv2.IMREAD_UNCHANGED)
    assert img.shape[:2] == (tv["height"], tv["width"])
    path = out / scene.name / (v["file"] + ".png")
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img)
mine = {"benchmark", "recon", "datagen", "common", "simulator", "e2vid", "e4dgs", "blender_scenes"}
assert not mine & {m.split(".")[0] for m in sys.modules}, "imported the project"
'''


def test_an_outside_method_reading_only_exported_files_scores_what_a_hand_computation_says(motion_scene, tmp_path):
    before = sorted(p.relative_to(motion_scene) for p in motion_scene.rglob("*"))
    assert e4dgs(["testviews", str(motion_scene), "--out", str(tmp_path / "tv")]) == 0
    assert sorted(p.relative_to(motion_scene) for p in motion_scene.rglob("*")) == before    # the dataset untouched
    tv_file = tmp_path / "tv" / motion_scene.name / "testviews.json"
    tv = json.loads(tv_file.read_text())
    ds = SceneDataset(motion_scene)
    assert len(tv["views"]) == len(ds.frames("test")) and tv["width"] == ds.intrinsics.width
    v = tv["views"][-1]
    assert np.allclose(np.linalg.inv(v["w2c"]), ds.pose(v["camera"], v["timestamp_us"]), atol=1e-9)
    assert v["time_s"] == pytest.approx(v["timestamp_us"] * 1e-6) and v["ground_truth"]["rgb"] == f"rgb/cam{v['camera']}/{v['index']:05d}.png"
    script = tmp_path / "outside.py"
    script.write_text(OUTSIDE)
    r = subprocess.run([sys.executable, "-I", str(script), str(motion_scene), str(tmp_path / "renders"), str(tv_file)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    (row,) = score_renders(motion_scene.parent, tmp_path / "renders", "nearest_frame", "rgb", lpips_net=None,
                           log=lambda s: None)
    psnrs = []                              # by hand: mean over views of 10 log10(1 / MSE) of the 8-bit images
    for view in tv["views"]:
        a = cv2.imread(str(tmp_path / "renders" / motion_scene.name / (view["file"] + ".png"))).astype(np.float64) / 255
        b = cv2.imread(str(motion_scene / view["ground_truth"]["rgb"])).astype(np.float64) / 255
        mse = np.mean((a - b) ** 2)
        psnrs.append(min(100.0, 10 * math.log10(1 / mse)) if mse > 0 else 100.0)
    assert row["psnr"] == pytest.approx(np.mean(psnrs), abs=1e-4)


def test_testviews_refuses_a_folder_without_scenes(tmp_path, capsys):
    assert e4dgs(["testviews", str(tmp_path)]) == 1
    assert "neither a generated scene nor a dataset root" in capsys.readouterr().err


# ---------------------------------------------------------------- bad renders

def _good(motion_scene, root: Path, channels: int = 3) -> Path:
    """A complete, valid renders folder (the ground truth itself) for the tiny scene."""
    ds = SceneDataset(motion_scene)
    for rec in ds.frames("test"):
        p = root / motion_scene.name / (rec.stem + ".png")
        p.parent.mkdir(parents=True, exist_ok=True)
        img = cv2.imread(str(rec.path if channels == 3 else rec.gray_path), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(p), img)
    return root / motion_scene.name


def _break(kind: str, scene: Path) -> tuple[str, str]:
    """Damage a good renders folder one way; returns (what the error line must contain, its file)."""
    first = sorted(scene.glob("cam0/*.png"))[0]
    if kind == "missing":
        first.unlink()
        return "missing", first.name
    if kind == "extra":
        (scene / "cam0" / "notes.txt").write_text("x")
        return "not a render of a test view", "notes.txt"
    if kind == "doubled":
        write_exr(first.with_suffix(".exr"), np.zeros((4, 4, 3), np.float32))
        return "a second render of view", first.stem
    if kind == "mis-sized":
        cv2.imwrite(str(first), np.zeros((10, 12, 3), np.uint8))
        return "12x10 pixels", first.name
    if kind == "wrong-channel":
        cv2.imwrite(str(first), np.zeros(cv2.imread(str(first)).shape[:2], np.uint8))
        return "gray (1 channel); expected colour", first.name
    if kind == "alpha":
        img = cv2.imread(str(first))
        cv2.imwrite(str(first), np.concatenate([img, np.full(img.shape[:2] + (1,), 255, np.uint8)], 2))
        return "alpha channel", first.name
    if kind == "corrupt":
        first.write_bytes(b"\x89PNG\r\n\x1a\n broken")
        return "cannot read", first.name
    h, w = cv2.imread(str(first)).shape[:2]
    first.unlink()
    img = np.full((h, w, 3), 0.5, np.float32)
    if kind == "non-finite":
        img[3, 4, 1] = np.nan
        write_exr(first.with_suffix(".exr"), img)
        return "non-finite", first.stem + ".exr"
    if kind == "out-of-range":
        img[0, 0, 0] = 1.7
        write_exr(first.with_suffix(".exr"), img)
        return "values from 0.5 to 1.7", first.stem + ".exr"
    if kind == "unknown-scene":
        (scene.parent / "no_such_scene").mkdir()
        return "is not a scene of the dataset", "no_such_scene"
    if kind == "bad-snapshot":
        (scene / "snapshots" / "late").mkdir(parents=True)
        return "folder named by training seconds", "late"
    raise AssertionError(kind)


KINDS = ("missing", "extra", "doubled", "mis-sized", "wrong-channel", "alpha", "corrupt", "non-finite",
         "out-of-range", "unknown-scene", "bad-snapshot")


@pytest.mark.parametrize("kind", KINDS)
def test_bad_renders_are_refused_in_one_line_and_nothing_is_appended(motion_scene, tmp_path, capsys, kind):
    scene = _good(motion_scene, tmp_path / "renders")
    results = tmp_path / "out" / "results.jsonl"
    results.parent.mkdir()
    results.write_text('{"key": "main/a/x", "study": "main", "scene": "a", "cell": "x"}\n')
    before = results.read_bytes()
    words, name = _break(kind, scene)
    capsys.readouterr()
    rc = e4dgs(["score", "--data", str(motion_scene.parent), str(tmp_path / "renders"), "--name", "m",
                "--inputs", "rgb", "--lpips", "none", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 1 and len(err.splitlines()) == 1 and words in err and name in err, err
    assert results.read_bytes() == before and sorted(p.name for p in results.parent.iterdir()) == ["results.jsonl"]


def test_gray_renders_of_an_events_only_method_are_accepted_and_a_clashing_name_is_refused(benched, motion_scene, tmp_path, capsys):
    out, _ = benched
    _good(motion_scene, tmp_path / "renders", channels=1)
    assert e4dgs(["score", "--data", str(motion_scene.parent), str(tmp_path / "renders"), "--name", "gt",
                  "--inputs", "events", "--lpips", "none", "--out", str(tmp_path / "o")]) == 0
    (row,) = read_results(tmp_path / "o" / "results.jsonl")
    assert row["psnr"] == 100.0                 # the ground truth itself, after the gain / offset fit: exact
    (out / "bench.json").write_text(json.dumps({"preset": "quick"}))
    capsys.readouterr()
    assert e4dgs(["score", "--data", str(motion_scene.parent), str(tmp_path / "renders"), "--name", "e4dgs",
                  "--inputs", "events", "--lpips", "none", "--out", str(out)]) == 1
    assert "'e4dgs' is a cell of the preset" in capsys.readouterr().err
