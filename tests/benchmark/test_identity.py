"""A row says what made it, and nothing stale is reused: a job's identity covers its resolved config,
its inputs, the scene's content and the code version; a row made by another identity trains again
(or, with --reuse-older, is kept and marked); every score re-derives from the renders it kept
(`e4dgs verify`), and an edited render is named."""
import functools
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmark.config import BenchConfig, CellSpec
from benchmark.grid import current_rows, jobs
from benchmark.report import write_report
from benchmark.runner import read_results, run_bench
from common import provenance
from common.config import build_config
from e4dgs.cli import main as e4dgs

REPO = Path(__file__).resolve().parents[2]
TINY = {"train.iterations": 12, "train.scale_schedule": False, "train.warm_up": 200, "train.densify.enabled": False,
        "train.init.n_points_object": 300, "train.checkpoint_every": 6, "train.snapshots": [1.0]}


def _cfg(scene: Path, seeds: int = 1) -> BenchConfig:
    cells = {"d3dgs_sharp": CellSpec("d3dgs", "D3DGS (sharp RGB)", overrides={**TINY, "frames": "sharp"}),
             "e4dgs": CellSpec("e4dgs", "E-4DGS (events)", overrides=TINY)}
    return build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [scene.name], "cells": cells,
                                      "lpips_net": "alex", "seeds": seeds})


@pytest.fixture(scope="module")
def benched(motion_scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("runs")
    run_bench(_cfg(motion_scene), "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=lambda s: None)
    (out / "bench.json").write_text(json.dumps({"preset": "tiny", "dataset": "tiny_motion"}))
    return out


def _source_copy(tmp_path: Path) -> Path:
    root = tmp_path / "src"
    for pkg in provenance.CODE_PACKAGES:
        shutil.copytree(REPO / pkg, root / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    for m in provenance.CODE_MODULES:
        (root / m).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / m, root / m)
    return root


def test_the_code_version_follows_the_code_that_makes_numbers_and_nothing_else(tmp_path):
    root = _source_copy(tmp_path)
    before = provenance.code_version(root)
    assert before == provenance.code_version(REPO)                # an installed copy: same code, same version
    (root / "README.md").write_text("docs change")                # not code
    (root / "recon" / "__pycache__").mkdir(exist_ok=True)
    assert provenance.code_version.__wrapped__(root) == before
    config = root / "recon" / "config.py"
    text = config.read_text()
    assert "    grad_threshold: float = 2e-4" in text
    config.write_text(text.replace("    grad_threshold: float = 2e-4", "    grad_threshold: float = 3e-4"))
    assert provenance.code_version.__wrapped__(root) != before    # one default changed: another version


def test_an_unchanged_tree_reuses_every_row_and_a_changed_default_trains_again(benched, motion_scene, tmp_path,
                                                                               monkeypatch):
    """The recon/config.py default edited in a copy of the sources; the bench's identity reads that copy."""
    from benchmark import job_run

    out = tmp_path / "runs"
    shutil.copytree(benched, out)
    cfg = _cfg(motion_scene)
    trained = []
    real = job_run.run_job
    monkeypatch.setattr(job_run, "run_job", lambda job, *a, **k: trained.append(job.key) or real(job, *a, **k))
    run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=lambda s: None)
    assert trained == []                                          # unchanged: every row reused

    root = _source_copy(tmp_path)
    config = root / "recon" / "config.py"
    config.write_text(config.read_text().replace("    grad_threshold: float = 2e-4", "    grad_threshold: float = 3e-4"))
    edited = functools.partial(provenance.code_version.__wrapped__, root)
    monkeypatch.setattr(provenance, "code_version", edited)
    before = {r["key"]: r for r in read_results(out / "results.jsonl")}
    logs = []
    run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=logs.append, reuse_older=True)
    assert trained == [] and any("--reuse-older keeps 2 row(s)" in line for line in logs)
    kept, stale = current_rows(cfg, list(before.values()), motion_scene.parent, reuse_older=True)
    assert not stale and all(r["older"].startswith(f"code {before[r['key']]['code_version'][:8]}") for r in kept)
    write_report(kept, tmp_path / "tables", "", cfg)
    board = (tmp_path / "tables" / "leaderboard.md").read_text()
    assert board.count("†") >= 6 and "Kept from another version with `--reuse-older`" in board
    assert current_rows(cfg, list(before.values()), motion_scene.parent)[0] == []      # without: not in the tables

    run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=logs.append)
    assert sorted(trained) == sorted(before)                      # by default: every affected job trains again
    after = {r["key"]: r for r in read_results(out / "results.jsonl")}
    assert all(after[k]["code_version"] == edited()[:16] != before[k]["code_version"] for k in before)
    assert all(after[k]["run_dir"] != before[k]["run_dir"] for k in before)          # a new training folder


def test_a_recipe_change_is_never_reused_even_with_reuse_older(benched, motion_scene, tmp_path):
    cfg = _cfg(motion_scene)
    rows = read_results(benched / "results.jsonl")
    other = build_config(BenchConfig, {**json.loads(json.dumps({"dataset": "tiny_motion", "scenes": [motion_scene.name],
                                                               "lpips_net": "alex"})),
                                       "cells": {"d3dgs_sharp": CellSpec("d3dgs", overrides={**TINY, "frames": "sharp",
                                                                                             "train.iterations": 13}),
                                                 "e4dgs": cfg.cells["e4dgs"]}})
    kept, stale = current_rows(other, rows, motion_scene.parent, reuse_older=True)
    assert [r["cell"] for r in stale] == ["d3dgs_sharp"] and [r["cell"] for r in kept] == ["e4dgs"]


def test_rows_carry_the_recipe_the_machine_and_the_digest_of_their_scored_views(benched):
    rows = {r["cell"]: r for r in read_results(benched / "results.jsonl")}
    e4 = rows["e4dgs"]
    assert e4["recipe"]["iterations"] == 12 and e4["recipe"]["seed"] == 0
    assert e4["recipe"]["deform_field"] in ("mlp", "trajectory") and "coarse_to_fine" in e4["recipe"]
    assert e4["device"] == "cpu" and e4["gpu"] is None and e4["cpu"] and e4["versions"]["torch"]
    assert set(e4["identity"]) == {"config", "inputs", "dataset", "code"} and e4["code_version"] == e4["identity"]["code"]
    views = json.loads((benched / e4["views_dir"] / "views.json").read_text())
    assert len(views["views"]) == e4["n_test_images"] and views["channels"] == 1          # events only: gray
    assert np.mean([v["psnr"] for v in views["views"]]) == pytest.approx(e4["psnr"], abs=1e-12)
    assert json.loads((benched / rows["d3dgs_sharp"]["views_dir"] / "views.json").read_text())["channels"] == 3


def test_verify_matches_every_row_and_names_a_render_edited_by_one_grey_level(benched, motion_scene, tmp_path, capsys):
    out = tmp_path / "runs"
    shutil.copytree(benched, out)
    data = ["--data", str(motion_scene.parent)]
    assert e4dgs(["verify", str(out), *data]) == 0
    assert "2 row(s) match their renders, 0 do not" in capsys.readouterr().out
    row = next(r for r in read_results(out / "results.jsonl") if r["cell"] == "d3dgs_sharp")
    doc = json.loads((out / row["views_dir"] / "views.json").read_text())
    view = doc["views"][3]["view"]
    png = out / row["views_dir"] / f"{view}.png"
    original = png.read_bytes()
    img = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    img[10, 10, 0] = img[10, 10, 0] + 1 if img[10, 10, 0] < 65535 else 65534      # one grey level of 65535
    cv2.imwrite(str(png), img)
    assert e4dgs(["verify", str(out), *data]) == 1
    said = capsys.readouterr().out
    assert f"verify {row['key']}: mismatch: view {view}:" in said and "the render was changed" in said
    # the render's digest forged in views.json and the row: the recomputed scores still name the view
    from recon.view_record import sha256
    from benchmark.rows import write_results

    doc["views"][3]["render_sha256"] = sha256(png.read_bytes())
    text = json.dumps(doc, indent=1, sort_keys=True)
    (out / row["views_dir"] / "views.json").write_text(text)
    rows = read_results(out / "results.jsonl")
    for r in rows:
        if r["views_dir"] == row["views_dir"]:
            r["views_sha256"] = sha256(text.encode())
    write_results(out / "results.jsonl", rows)
    assert e4dgs(["verify", str(out), *data, "--no-lpips"]) == 1
    said = capsys.readouterr().out
    assert f"mismatch: view {view}: psnr recomputed" in said
    png.write_bytes(original)
    assert e4dgs(["verify", str(out), *data, "--keys", next(r["key"] for r in rows if r["cell"] == "e4dgs")]) == 0


def test_seeds_train_each_cell_n_times_and_the_tables_show_mean_and_spread(motion_scene, tmp_path):
    cfg = _cfg(motion_scene, seeds=2)
    assert [j.key for j in jobs(cfg)] == [f"main/{motion_scene.name}/d3dgs_sharp", f"main/{motion_scene.name}/e4dgs",
                                          f"main/{motion_scene.name}/d3dgs_sharp/seed1", f"main/{motion_scene.name}/e4dgs/seed1"]
    seeded = {j.key: j for j in jobs(cfg)}
    assert seeded[f"main/{motion_scene.name}/e4dgs/seed1"].method_config.train.seed == 1
    rows = run_bench(cfg, "tiny", motion_scene.parent, tmp_path, studies=("main",), progress=False, log=lambda s: None)
    assert len({r["run_dir"] for r in rows}) == 4 and {r["recipe"]["seed"] for r in rows} == {0, 1}
    write_report(rows, tmp_path, "", cfg)
    board = (tmp_path / "leaderboard.md").read_text()
    e4 = [r for r in rows if r["cell"] == "e4dgs"]
    sd = float(np.std([r["psnr"] for r in e4], ddof=1))
    assert f"{np.mean([r['psnr'] for r in e4]):.2f} ± {sd:.2f}" in board and "Seeds per cell: 2" in board
    # a later run of the preset at one seed keeps the seed-1 rows in its tables
    kept, stale = current_rows(_cfg(motion_scene), rows, motion_scene.parent)
    assert len(kept) == 4 and not stale
