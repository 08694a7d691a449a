"""A row says what made it, and nothing stale is reused: a job's identity covers its resolved config,
its inputs, the scene's content and the code version; a row made by another identity trains again
(or, with --reuse-older, is kept and marked); every score re-derives from the renders it kept
(`e4dgs verify`), and an edited render is named."""
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


PACKAGES = ("common", "e4dgs", "eventio", "simulator", "scene_format", "datagen", "blender_scenes", "recon",
            "benchmark", "e2vid", "viewer")


def _source_copy(tmp_path: Path) -> Path:
    """A copy of the checkout's packages (what an installed copy holds), edited by the tests."""
    root = tmp_path / "src"
    for pkg in PACKAGES:
        shutil.copytree(REPO / pkg, root / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return root


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{path}: {old!r} not found once"
    path.write_text(text.replace(old, new))


def _versions(root: Path) -> dict[str, str]:
    return {m: provenance.code_version(root, (provenance.JOB_ENTRY, f"recon.methods.{m}"))
            for m in ("d3dgs", "e4dgs", "e2vid_d3dgs")}


def test_the_code_version_is_the_normalised_import_closure_of_what_a_job_runs(tmp_path):
    root = _source_copy(tmp_path)
    before = _versions(root)
    assert before == _versions(REPO)                   # an installed copy: same code, same version
    closure = provenance.import_closure((provenance.JOB_ENTRY, "recon.methods.e4dgs"))
    assert {"eventio.event_file", "recon.event_windows", "recon.trainer", "common.metrics.image"} <= set(closure)
    assert not [m for m in closure if m.endswith(("cli", "__main__")) or m.startswith(("e4dgs", "viewer", "datagen"))]

    # comments, docstrings and formatting: the same statements, the same version
    _edit(root / "recon" / "trainer.py", "\nclass Trainer", "\n# a comment a reviewer added\nclass Trainer")
    _edit(root / "eventio" / "event_file.py", '"""The typed boundary', '"""An edited docstring. The typed boundary')
    (root / "README.md").write_text("docs change")
    (root / "recon" / "__pycache__").mkdir(exist_ok=True)
    config = root / "recon" / "config.py"
    _edit(config, "    grad_threshold: float = 2e-4", "    grad_threshold: float = (\n        2e-4\n    )  # reformatted")
    assert _versions(root) == before
    # a command line no job imports: not in any version
    (root / "e4dgs" / "cli.py").write_text((root / "e4dgs" / "cli.py").read_text() + "\nEXTRA = 1\n")
    (root / "recon" / "cli.py").write_text((root / "recon" / "cli.py").read_text() + "\nEXTRA = 1\n")
    assert _versions(root) == before

    # a statement in the event reader (reached through recon/event_windows -> eventio/): another version
    reader = root / "eventio" / "event_file.py"
    reader.write_text(reader.read_text() + "\nFLIPPED = -1\n")
    after = _versions(root)
    assert all(after[m] != before[m] for m in after)
    # E2VID's network is imported by its method only
    reader.write_text(reader.read_text().replace("\nFLIPPED = -1\n", "\n"))
    assert _versions(root) == before
    net = root / "e2vid" / "networks.py"
    net.write_text(net.read_text() + "\nEXTRA = 1\n")
    after = _versions(root)
    assert after["e2vid_d3dgs"] != before["e2vid_d3dgs"] and after["d3dgs"] == before["d3dgs"]
    # one default changed: another version
    _edit(config, "        2e-4\n", "        3e-4\n")
    assert _versions(root)["d3dgs"] != before["d3dgs"]


BENCH_SCRIPT = """
import json, sys
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from benchmark.config import BenchConfig, CellSpec
from benchmark.runner import run_bench
from common.config import build_config
scene, out = Path(sys.argv[2]), Path(sys.argv[3])
tiny = json.loads(sys.argv[4])
cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [scene.name], "lpips_net": "alex",
                                 "cells": {"e4dgs": CellSpec("e4dgs", "E-4DGS (events)", overrides=tiny)}})
run_bench(cfg, "tiny", scene.parent, out, studies=("main",), progress=False,
          reuse_older="--reuse-older" in sys.argv)
"""


def _bench_in(root: Path, scene: Path, out: Path, *extra: str) -> str:
    """`run_bench` in a fresh process that imports the packages of `root` (what runs is the copy)."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-c", BENCH_SCRIPT, str(root), str(scene), str(out), json.dumps(TINY), *extra],
                       cwd=root, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def test_a_comment_keeps_the_row_and_a_statement_in_the_event_reader_trains_again(motion_scene, tmp_path):
    """The sources edited in a copy that the bench runs from (nothing patched): the row of an events-only
    job is kept after comments and docstrings, and trained again after one statement of eventio/ changes
    what it reads (every event's polarity flipped)."""
    root = _source_copy(tmp_path)
    out = tmp_path / "runs"
    said = _bench_in(root, motion_scene, out)
    assert "1 job(s)" in said and "0 already" in said
    first = read_results(out / "results.jsonl")[0]
    _edit(root / "recon" / "trainer.py", "\nclass Trainer", "\n# a comment\nclass Trainer")
    _edit(root / "eventio" / "event_file.py", '"""The typed boundary', '"""Edited. The typed boundary')
    said = _bench_in(root, motion_scene, out)
    assert "1 already" in said and read_results(out / "results.jsonl") == [first]

    reader = root / "eventio" / "event_file.py"
    reader.write_text(reader.read_text() + "\n_FLIP = True\n")
    said = _bench_in(root, motion_scene, out)
    assert "0 already" in said and "made by another version and train again" in said
    second = read_results(out / "results.jsonl")[0]
    assert second["code_version"] != first["code_version"] and second["run_dir"] != first["run_dir"]
    assert second["identity"]["config"] == first["identity"]["config"]


def test_an_unchanged_tree_reuses_every_row_and_a_changed_default_trains_again(benched, motion_scene, tmp_path,
                                                                               monkeypatch):
    """What --reuse-older keeps: a row of the same resolved config made by another code version. The
    code version is changed by editing the identity of the rows on disk (the edited-source path is the
    subprocess test above); a recon/config.py default is part of the resolved config, so editing one
    is never reused (the next test)."""
    from benchmark import job_run
    from benchmark.rows import write_results

    out = tmp_path / "runs"
    shutil.copytree(benched, out)
    cfg = _cfg(motion_scene)
    trained = []
    real = job_run.run_job
    monkeypatch.setattr(job_run, "run_job", lambda job, *a, **k: trained.append(job.key) or real(job, *a, **k))
    run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=lambda s: None)
    assert trained == []                                          # unchanged: every row reused

    rows = read_results(out / "results.jsonl")
    for r in rows:                                                # as if made by an older checkout
        r["identity"] = {**r["identity"], "code": "0123456789abcdef"}
        r["config_hash"], r["code_version"] = "feedfacefeedface", "0123456789abcdef"
    write_results(out / "results.jsonl", rows)
    before = {r["key"]: r for r in rows}
    logs = []
    run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=logs.append, reuse_older=True)
    assert trained == [] and any("--reuse-older keeps 2 row(s)" in line for line in logs)
    kept, stale = current_rows(cfg, list(before.values()), motion_scene.parent, reuse_older=True)
    assert not stale and all(r["older"].startswith("code 01234567") for r in kept)
    write_report(kept, tmp_path / "tables", "", cfg)
    board = (tmp_path / "tables" / "leaderboard.md").read_text()
    assert board.count("†") >= 6 and "Kept from another version with `--reuse-older`" in board
    assert current_rows(cfg, list(before.values()), motion_scene.parent)[0] == []      # without: not in the tables

    run_bench(cfg, "tiny", motion_scene.parent, out, studies=("main",), progress=False, log=logs.append)
    assert sorted(trained) == sorted(before)                      # by default: every affected job trains again


def test_a_default_edited_in_the_sources_is_another_recipe_never_reused(motion_scene, tmp_path):
    """recon/config.py's default is a field of the resolved config: an edit of it (in a copy the bench
    runs from) trains again even with --reuse-older."""
    root = _source_copy(tmp_path)
    out = tmp_path / "runs"
    _bench_in(root, motion_scene, out)
    first = read_results(out / "results.jsonl")[0]
    _edit(root / "recon" / "config.py", "    percent_dense: float = 0.01", "    percent_dense: float = 0.02")
    said = _bench_in(root, motion_scene, out, "--reuse-older")
    assert "0 already" in said and "--reuse-older keeps" not in said
    second = read_results(out / "results.jsonl")[0]
    assert second["identity"]["config"] != first["identity"]["config"] and second["run_dir"] != first["run_dir"]


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
    assert set(e4["identity"]) == {"config", "inputs", "dataset", "code", "placement"}
    assert e4["code_version"] == e4["identity"]["code"]
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
    seed1 = seeded[f"main/{motion_scene.name}/e4dgs/seed1"].method_config.train
    assert seed1.seed == 1 and seed1.init.seed == 1                  # training and initial points both vary
    rows = run_bench(cfg, "tiny", motion_scene.parent, tmp_path, studies=("main",), progress=False, log=lambda s: None)
    assert len({r["run_dir"] for r in rows}) == 4 and {r["recipe"]["seed"] for r in rows} == {0, 1}
    write_report(rows, tmp_path, "", cfg)
    board = (tmp_path / "leaderboard.md").read_text()
    e4 = [r for r in rows if r["cell"] == "e4dgs"]
    sd = float(np.std([r["psnr"] for r in e4], ddof=1))
    assert f"{np.mean([r['psnr'] for r in e4]):.2f} ± {sd:.2f}" in board and "Seeds per cell: 2 (a seed varies training's random draws and the initial points" in board
    # a later run of the preset at one seed keeps the seed-1 rows in its tables
    kept, stale = current_rows(_cfg(motion_scene), rows, motion_scene.parent)
    assert len(kept) == 4 and not stale


def _scene_copy(motion_scene: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(motion_scene, tmp_path / "data" / motion_scene.name))


def _job(cfg: BenchConfig, scene: Path, cell: str = "e4dgs"):
    return next(j for j in jobs(cfg, scene.parent) if j.cell == cell)


def test_event_files_copied_over_without_touching_the_manifest_make_another_dataset(motion_scene, tmp_path):
    scene = _scene_copy(motion_scene, tmp_path)
    cfg = _cfg(scene)
    before = _job(cfg, scene).identity_parts["dataset"]
    manifest = (scene / "manifest.json").read_bytes()
    shutil.copy(scene / "events" / "cam1.h5", scene / "events" / "cam0.h5")     # other events, same manifest
    assert (scene / "manifest.json").read_bytes() == manifest
    assert _job(cfg, scene).identity_parts["dataset"] != before
    shutil.copy(motion_scene / "events" / "cam0.h5", scene / "events" / "cam0.h5")
    assert _job(cfg, scene).identity_parts["dataset"] == before                 # the same bytes again
    (scene / "events" / "cam0.h5").unlink()
    assert _job(cfg, scene).identity_parts["dataset"] != before


def test_rows_scored_with_other_masks_or_another_lpips_network_are_scored_again_not_shown(benched, motion_scene,
                                                                                          tmp_path):
    from benchmark.job_run import complete_row

    scene = _scene_copy(motion_scene, tmp_path)
    cfg = _cfg(scene)
    rows = read_results(benched / "results.jsonl")
    assert all(r["masks"] and r["lpips_net"] == "alex" for r in rows)
    kept, stale = current_rows(cfg, rows, scene.parent)
    assert len(kept) == 2 and not stale
    vgg = build_config(BenchConfig, {**{k: getattr(cfg, k) for k in ("dataset", "scenes", "cells")}, "lpips_net": "vgg"})
    kept, stale = current_rows(vgg, rows, scene.parent, reuse_older=True)
    assert kept == [] and len(stale) == 2                         # never an AlexNet value beside a VGG one
    assert not any(complete_row(r, _job(vgg, scene, r["cell"]), vgg, scene.parent) for r in rows)
    # the masks made again with another threshold: the dynamic-region scores are stale
    masks = scene / "dynamic" / "masks.json"
    masks.parent.mkdir(exist_ok=True)
    masks.write_text(json.dumps({"threshold_px": 0.123}) if not masks.exists()
                     else masks.read_text().replace("}", ', "edited": 1}', 1))
    kept, stale = current_rows(cfg, rows, scene.parent, reuse_older=True)
    assert kept == [] and len(stale) == 2
    assert not any(complete_row(r, _job(cfg, scene, r["cell"]), cfg, scene.parent) for r in rows)


def test_the_resolved_placement_is_part_of_the_identity(motion_scene):
    from benchmark.grid import resolved_placement

    cfg = _cfg(motion_scene)
    job = _job(cfg, motion_scene)
    auto = resolved_placement(job.method_config)
    assert auto["device"] == "cpu" and auto["backend"] == "cpu" and auto["precision"] in ("float32", "bfloat16")
    parts = {}
    for precision in ("float32", "bfloat16", "auto"):
        c = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name], "lpips_net": "alex",
                                       "cells": {"e4dgs": CellSpec("e4dgs", overrides={**TINY, "train.precision": precision})}})
        parts[precision] = _job(c, motion_scene).identity_parts["placement"]
    assert parts["float32"] != parts["bfloat16"] and parts["auto"] == parts[auto["precision"]]


def test_reuse_older_never_keeps_a_row_of_another_placement_or_without_an_identity(benched, motion_scene):
    cfg = _cfg(motion_scene)
    rows = read_results(benched / "results.jsonl")
    other = [{**r, "config_hash": "0" * 16, "identity": {**r["identity"], "placement": "elsewhere"}} for r in rows]
    assert current_rows(cfg, other, motion_scene.parent, reuse_older=True)[0] == []
    bare = [{k: v for k, v in r.items() if k != "identity"} | {"config_hash": "0" * 16} for r in rows]
    assert current_rows(cfg, bare, motion_scene.parent, reuse_older=True)[0] == []


def _forge(out: Path, edit) -> None:
    """Rewrite results.jsonl with `edit(rows)` applied (rows edited in place)."""
    from benchmark.rows import write_results

    rows = read_results(out / "results.jsonl")
    edit(rows)
    write_results(out / "results.jsonl", rows)


def _resign(out: Path, row: dict, doc: dict) -> None:
    """Write a forged views.json for `row` and point every row that uses it at its new digest."""
    from recon.view_record import sha256

    text = json.dumps(doc, indent=1, sort_keys=True)
    (out / row["views_dir"] / "views.json").write_text(text)
    _forge(out, lambda rows: [r.update(views_sha256=sha256(text.encode())) for r in rows
                              if r["views_dir"] == row["views_dir"]])


@pytest.fixture()
def forged(benched, tmp_path):
    out = tmp_path / "runs"
    shutil.copytree(benched, out)
    return out


def _verify(out: Path, motion_scene: Path, capsys, *extra: str) -> tuple[int, str]:
    code = e4dgs(["verify", str(out), "--data", str(motion_scene.parent), "--no-lpips", *extra])
    return code, capsys.readouterr().out


def test_verify_refuses_a_cherry_picked_view_set(forged, motion_scene, capsys):
    from common.metrics.image import mean_scores

    row = next(r for r in read_results(forged / "results.jsonl") if r["cell"] == "e4dgs")
    doc = json.loads((forged / row["views_dir"] / "views.json").read_text())
    worst = min(doc["views"], key=lambda v: v["psnr"])
    doc["views"].remove(worst)
    (forged / row["views_dir"] / worst["render"]).unlink()
    means = mean_scores([{k: v for k, v in e.items() if k not in ("view", "render", "render_sha256")}
                         for e in doc["views"]])
    doc["means"] = means
    _resign(forged, row, doc)
    _forge(forged, lambda rows: [r.update(psnr=means["psnr"], psnr_luma=means["psnr_luma"], ssim=means["ssim"],
                                          n_test_images=means["n_images"]) for r in rows if r["key"] == row["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and f"verify {row['key']}: mismatch" in said and f"{len(doc['views'])} views, the test split" in said


def test_verify_refuses_swapped_and_borrowed_views(forged, motion_scene, capsys):
    rows = {r["cell"]: r for r in read_results(forged / "results.jsonl")}
    a, b = rows["e4dgs"], rows["d3dgs_sharp"]
    moved = ("views_dir", "views_sha256", "psnr", "psnr_luma", "ssim", "lpips", "n_test_images")

    def swap(rs):
        for r in rs:
            src = b if r["key"] == a["key"] else a if r["key"] == b["key"] else None
            if src:
                r.update({k: src.get(k) for k in moved})
    _forge(forged, swap)
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and said.count(": mismatch") == 2 and "views_dir" in said
    # borrowed with its training folder too: the identity no longer makes the folder's name
    _forge(forged, lambda rs: [r.update({k: b.get(k) for k in moved + ("run_dir",)}) for r in rs if r["key"] == a["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and f"verify {a['key']}: mismatch: run_dir" in said
    # ... and its identity: views.json says whose they are (method), and the run folder too
    _forge(forged, lambda rs: [r.update({k: b.get(k) for k in moved + ("run_dir", "identity", "config_hash")})
                               for r in rs if r["key"] == a["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and f"verify {a['key']}: mismatch" in said


def test_verify_takes_the_lpips_network_from_the_row_and_the_preset_never_from_views_json(forged, motion_scene, capsys):
    row = next(r for r in read_results(forged / "results.jsonl") if r["cell"] == "d3dgs_sharp")
    doc = json.loads((forged / row["views_dir"] / "views.json").read_text())
    doc["lpips_net"] = None
    for v in doc["views"]:
        v["lpips"] -= 0.1
    _resign(forged, row, doc)
    _forge(forged, lambda rs: [r.update(lpips=r["lpips"] - 0.1) for r in rs if r["key"] == row["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and "scored with LPIPS None, the row says 'alex'" in said
    _forge(forged, lambda rs: [r.update(lpips_net=None) for r in rs if r["key"] == row["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and "with no LPIPS network" in said
    _forge(forged, lambda rs: [r.update(lpips_net=None, lpips=None) for r in rs if r["key"] == row["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and f"verify {row['key']}: mismatch: row lpips None is not the mean" in said


@pytest.mark.parametrize("column, value", [("floor_psnr", 5.0), ("psnr_luma_dyn", 30.0), ("dyn_fraction", 0.5),
                                           ("n_test_images", 3), ("lpips", None), ("wall_s", 1.0), ("iterations", 400),
                                           ("label", "E-4DGS (best)"), ("floor_views_dir", "elsewhere/floor_views")])
def test_verify_checks_every_column_a_table_shows(forged, motion_scene, capsys, column, value):
    row = next(r for r in read_results(forged / "results.jsonl") if r["cell"] == "e4dgs")
    if column == "lpips":
        row = next(r for r in read_results(forged / "results.jsonl") if r["cell"] == "d3dgs_sharp")
    (forged / "bench.json").write_text(json.dumps({"preset": "tiny", "dataset": "tiny_motion", "lpips_net": "alex",
                                                   "cells": {"e4dgs": {"label": "E-4DGS (events)"},
                                                             "d3dgs_sharp": {"label": "D3DGS (sharp RGB)"}}}))
    assert _verify(forged, motion_scene, capsys)[0] == 0
    _forge(forged, lambda rs: [r.update({column: value}) for r in rs if r["key"] == row["key"]])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and f"verify {row['key']}: mismatch" in said and (column in said or "LPIPS" in said)


def test_a_row_that_cannot_be_verified_fails_unless_allowed_by_name(forged, motion_scene, capsys):
    rows = read_results(forged / "results.jsonl")
    a, b = rows[0]["key"], rows[1]["key"]
    _forge(forged, lambda rs: [r.pop("views_dir") for r in rs if r["key"] == a]
           + [r.update(external=True) or r.pop("views_sha256") for r in rs if r["key"] == b])
    code, said = _verify(forged, motion_scene, capsys)
    assert code == 1 and "2 cannot be verified (not allowed" in said
    assert _verify(forged, motion_scene, capsys, "--allow-unverifiable", a)[0] == 1
    assert _verify(forged, motion_scene, capsys, "--allow-unverifiable", f"{a},{b}")[0] == 0
    (forged / "results.jsonl").write_text("")
    with pytest.raises(SystemExit, match="no scored rows to verify"):       # an empty results file: not OK
        _verify(forged, motion_scene, capsys)


def test_reuse_older_keeps_a_row_from_before_placements_were_recorded_only_where_it_ran_the_same(benched,
                                                                                                  motion_scene):
    """Rows made before `placement` was an identity part are judged by the device, backend and
    precision they recorded."""
    cfg = _cfg(motion_scene)
    rows = read_results(benched / "results.jsonl")
    older = [{**r, "config_hash": "0" * 16, "identity": {k: v for k, v in r["identity"].items() if k != "placement"}
              | {"code": "0123456789abcdef"}} for r in rows]
    kept, stale = current_rows(cfg, older, motion_scene.parent, reuse_older=True)
    assert len(kept) == 2 and not stale
    other = "float32" if rows[0]["precision"] == "bfloat16" else "bfloat16"
    kept, stale = current_rows(cfg, [{**r, "precision": other} for r in older], motion_scene.parent, reuse_older=True)
    assert kept == [] and len(stale) == 2


def test_a_row_duplicated_by_joining_two_results_files_is_refused_not_counted_as_a_seed(benched, tmp_path):
    text = (benched / "results.jsonl").read_text()
    (tmp_path / "results.jsonl").write_text(text + text.splitlines(keepends=True)[0])
    with pytest.raises(ValueError, match=r"results.jsonl:3: row .* again \(first on line 1\)"):
        read_results(tmp_path / "results.jsonl")
