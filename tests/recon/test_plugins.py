"""Methods as plug-ins: the example package under examples/plugin_method, installed with pip, trains
and appears in a bench without editing the project; broken plug-ins are refused naming the entry point."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import recon.methods as registry

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "plugin_method"
TINY = {"train.iterations": 10, "train.scale_schedule": False, "train.warm_up": 200, "train.densify.enabled": False,
        "train.init.n_points_object": 200, "train.snapshots": [1.0]}


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The example plug-in pip-installed into a folder of its own (offline, no dependencies)."""
    import shutil

    target = tmp_path_factory.mktemp("site")
    source = tmp_path_factory.mktemp("src") / "plugin_method"       # a setuptools build writes into its source
    shutil.copytree(EXAMPLE, source, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                        "--no-index", "--target", str(target), str(source)], capture_output=True, text=True,
                       cwd=source.parent)
    assert r.returncode == 0, r.stderr
    assert list(target.glob("e4dgs_integrate-*.dist-info/entry_points.txt"))
    return target


def _env(site: Path) -> dict:
    return {**os.environ, "PYTHONPATH": str(site), "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", "")}


def test_installed_plugin_trains_and_appears_in_a_bench(installed, motion_scene, tmp_path):
    preset = tmp_path / "mine.yaml"
    cells = {"d3dgs_sharp": {"method": "d3dgs", "label": "D3DGS (sharp RGB)", "overrides": {**TINY, "frames": "sharp"}},
             "mine": {"method": "integrate_d3dgs", "label": "Event integration + D3DGS", "overrides": TINY}}
    preset.write_text(json.dumps({"dataset": "tiny_motion", "scenes": [motion_scene.name], "cells": cells,
                                  "lpips_net": "alex"}))            # JSON is YAML
    out = tmp_path / "runs"
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "bench", "--preset", str(preset), "--data",
                        str(motion_scene.parent), "--out", str(out), "--studies", "main", "--no-progress"],
                       capture_output=True, text=True, cwd=ROOT, env=_env(installed))
    assert r.returncode == 0, r.stderr[-2000:]
    rows = {json.loads(line)["cell"]: json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()}
    mine = rows["mine"]
    assert mine["method"] == "integrate_d3dgs" and mine["inputs"] == ["events"] and mine["channels"] == 1
    assert np.isfinite(mine["psnr"]) and np.isfinite(mine["floor_psnr"]) and mine["iterations"] == 10
    board = (out / "leaderboard.md").read_text()
    lines = [l for l in board.splitlines() if l.startswith("| D3DGS (sharp RGB) |") or l.startswith("| Event integration")]
    assert [l.split(" |")[0] for l in lines[:2]] == ["| D3DGS (sharp RGB)", "| Event integration + D3DGS"]
    # without the plug-in installed the same preset is refused, naming the cell
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "bench", "--preset", str(preset), "--data",
                        str(motion_scene.parent), "--out", str(tmp_path / "o2"), "--studies", "main"],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode != 0 and "cells.mine.method: unknown method 'integrate_d3dgs'" in r.stderr


def test_integration_solved_by_hand():
    sys.path.insert(0, str(EXAMPLE))
    try:
        from e4dgs_integrate import integrate
    finally:
        sys.path.remove(str(EXAMPLE))
    x, y = np.array([1, 1, 1, 0]), np.array([0, 0, 0, 1])
    p, t = np.array([1.0, 1.0, -1.0, -1.0]), np.array([10, 20, 30, 40])
    out = integrate(x, y, p, t, np.array([0, 25, 50]), 2, 2, 0.5, 0.0)
    assert out[:, 0, 1].tolist() == [0.0, 1.0, 0.5] and out[:, 1, 0].tolist() == [0.0, 0.0, -0.5]
    leak = integrate(x, y, p, t, np.array([0, 25, 1025]), 2, 2, 0.5, 100.0)
    assert leak[2, 0, 1] == pytest.approx(1.0 * np.exp(-2 * np.pi * 100.0 * 1e-3) - 0.5)


class _EP:
    def __init__(self, name, obj, value="pkg.mod:Obj"):
        self.name, self.value, self._obj = name, value, obj

    def load(self):
        if isinstance(self._obj, Exception):
            raise self._obj
        return self._obj


@pytest.mark.parametrize("obj,words", [
    (ImportError("No module named 'pkg'"), "cannot be imported: ImportError: No module named 'pkg'"),
    (dict, "expected a subclass of recon.method.Method"),
])
def test_a_broken_plugin_is_refused_naming_its_entry_point_and_breaks_no_other_method(monkeypatch, obj, words):
    monkeypatch.setattr(registry, "entry_points", lambda group: [_EP("broken", obj)])
    monkeypatch.setattr(registry, "METHODS", {})
    with pytest.raises(registry.PluginError, match="method plug-in 'broken'") as exc:
        registry.get_method("broken")
    assert words in str(exc.value)
    assert set(registry.BUNDLED) <= set(registry.method_names()) and "broken" in registry.method_names()
    for name in registry.BUNDLED:                # the five bundled methods load without the plug-in
        assert registry.get_method(name).name == name


def test_a_plugin_whose_name_differs_from_its_entry_point_or_lacks_inputs_is_refused(monkeypatch):
    from recon.methods.d3dgs import D3DGS

    class NoInputs(D3DGS):
        name = "no_inputs"
        inputs = ()

    class Renamed(D3DGS):
        name = "other"

    for cls, ep_name, words in ((NoInputs, "no_inputs", "inputs must name what the method sees"),
                                (Renamed, "mine", "the entry point's name must be the method's name 'other'")):
        monkeypatch.setattr(registry, "entry_points", lambda group, c=cls, n=ep_name: [_EP(n, c)])
        with pytest.raises(registry.PluginError, match=words):
            registry.get_method(ep_name)
    assert "no_inputs" not in registry.METHODS and "other" not in registry.METHODS


def test_the_bundled_methods_are_entry_points_of_the_package():
    """pyproject.toml declares the bundled methods in the group, as BUNDLED says; the installed
    metadata lists them (a checkout not installed falls back on BUNDLED)."""
    import re
    from importlib.metadata import entry_points

    text = (ROOT / "pyproject.toml").read_text()
    block = text.split('[project.entry-points."e4dgs.methods"]', 1)[1].split("\n[", 1)[0]
    declared = dict(re.findall(r'^(\w+) = "([\w.:]+)"', block, re.M))
    assert declared == registry.BUNDLED
    installed = {ep.name: ep.value for ep in entry_points(group=registry.ENTRY_POINT_GROUP)}
    assert {k: v for k, v in installed.items() if k in declared} == declared


def test_a_plugin_whose_step_raises_is_named(motion_scene, tmp_path, monkeypatch):
    """A plug-in's failure is one TrainingError naming the method and its class, not an 'internal
    error'; the cause stays chained for --debug."""
    import recon
    from recon.methods.d3dgs import D3DGS
    from recon.trainer import TrainingError

    class Broken(D3DGS):
        name = "broken_d3dgs"

        def step(self, trainer, it):
            return 1 / 0

    monkeypatch.setitem(registry.METHODS, "broken_d3dgs", Broken)
    with pytest.raises(TrainingError, match=r"method 'broken_d3dgs' \(plug-in class .*Broken\): its step raised "
                                            r"ZeroDivisionError: division by zero at iteration 1") as exc:
        recon.fit(motion_scene, "broken_d3dgs", overrides=TINY, out_dir=tmp_path / "run", progress=False)
    assert isinstance(exc.value.__cause__, ZeroDivisionError)
    assert not (tmp_path / "run").exists()          # nothing to resume: nothing left behind


def test_training_that_ends_with_non_finite_parameters_saves_no_model(motion_scene, tmp_path, monkeypatch):
    import torch

    import recon
    from recon.trainer import Trainer, TrainingError

    original = Trainer._optimise

    def poisoned(self, it):
        out = original(self, it)
        if it == self.tcfg.iterations:
            with torch.no_grad():
                self.model.gaussians.sh_dc[0, 0, 0] = float("inf")
        return out
    monkeypatch.setattr(Trainer, "_optimise", poisoned)
    with pytest.raises(TrainingError, match=r"non-finite values in gaussians\.sh_dc; no model is saved"):
        recon.fit(motion_scene, "d3dgs", overrides={**TINY, "train.checkpoint_every": 5}, out_dir=tmp_path / "run",
                  progress=False)
    assert not (tmp_path / "run" / "model.pt").exists() and (tmp_path / "run" / "checkpoint.pt").exists()


def test_a_failing_plugin_costs_only_its_own_cells_in_a_bench(motion_scene, tmp_path, monkeypatch, capsys):
    """Serial bench with a plug-in whose step raises beside a working cell: the working cell is scored,
    the plug-in's cell is a 'failed' row naming the plug-in, and the tables say so."""
    from benchmark.config import BenchConfig, CellSpec
    from benchmark.report import write_report
    from benchmark.runner import run_bench
    from common.config import build_config
    from recon.methods.d3dgs import D3DGS

    class Broken(D3DGS):
        name = "broken_d3dgs"

        def step(self, trainer, it):
            return 1 / 0

    monkeypatch.setitem(registry.METHODS, "broken_d3dgs", Broken)
    over = {**TINY, "frames": "sharp"}
    cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name],
                                     "cells": {"broken": CellSpec("broken_d3dgs", overrides=over),
                                               "good": CellSpec("d3dgs", overrides=over)}})
    lines = []
    rows = run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "runs", studies=("main",), progress=False,
                     log=lines.append)
    by_cell = {r["cell"]: r for r in rows}
    assert by_cell["good"].get("status") != "failed" and np.isfinite(by_cell["good"]["psnr"])
    assert by_cell["broken"]["status"] == "failed"
    assert "method 'broken_d3dgs' (plug-in class" in by_cell["broken"]["error"] and "ZeroDivisionError" in by_cell["broken"]["error"]
    assert any("broken: FAILED" in ln for ln in lines)
    write_report(rows, tmp_path / "runs", "", cfg)
    assert "failed" in (tmp_path / "runs" / "leaderboard.md").read_text()
    # `e4dgs bench` exits 1 naming the failed job, after writing the tables (here from the rows above)

    from benchmark.cli import run_bench_cli

    import yaml

    from benchmark.config import dump

    preset = tmp_path / "mine.yaml"          # the preset the rows were made with (the tables keep only its rows)
    preset.write_text(yaml.safe_dump(dump(cfg)))
    from e4dgs.cli import build_parser

    args = build_parser().parse_args(["bench", "--preset", str(preset), "--out", str(tmp_path / "runs"), "--data",
                                      str(motion_scene.parent), "--report", "--studies", "main", "--no-progress"])
    assert run_bench_cli(args) == 1
    assert f"main/{motion_scene.name}/broken" in capsys.readouterr().err


@pytest.mark.parametrize("kind,words", [
    ("constructor", r"its constructor raised RuntimeError: no weights"),
    ("junk", r"its step returned a str at iteration 1; expected \(loss, renders\)"),
    ("vector", r"its step returned \(Tensor of shape \(3,\), list\) at iteration 1"),
])
def test_a_plugin_that_fails_to_build_or_returns_junk_is_named(kind, words, motion_scene, tmp_path, monkeypatch):
    import torch

    import recon
    from recon.methods.d3dgs import D3DGS
    from recon.trainer import TrainingError

    class Odd(D3DGS):
        name = "odd_d3dgs"

        def __init__(self, dataset, cfg):
            if kind == "constructor":
                raise RuntimeError("no weights")
            super().__init__(dataset, cfg)

        def step(self, trainer, it):
            return "a loss" if kind == "junk" else (torch.ones(3, requires_grad=True), [])

    monkeypatch.setitem(registry.METHODS, "odd_d3dgs", Odd)
    with pytest.raises(TrainingError, match=r"method 'odd_d3dgs' \(plug-in class .*Odd\): " + words):
        recon.fit(motion_scene, "odd_d3dgs", overrides=TINY, out_dir=tmp_path / "run", progress=False)
    assert not (tmp_path / "run" / "model.pt").exists()


def test_training_frames_of_the_wrong_size_are_refused_naming_the_view(motion_scene, monkeypatch):
    """Gray frames of another size than the camera's (a plug-in's, or an E2VID network's) were taken."""
    import torch

    from recon.methods.d3dgs import D3DGS, TrainView
    from scene_format.reader import DatasetError, SceneDataset

    class SmallFrames(D3DGS):
        name = "small_frames"

        def training_views(self):
            views = super().training_views()
            return views[:1] + [TrainView(v.camera, v.time, torch.zeros(8, 8, v.image.shape[2])) for v in views[1:2]]

    ds = SceneDataset(motion_scene)
    cfg = registry.get_method("d3dgs").config_cls()
    with pytest.raises(DatasetError, match=r"training view 1 \(t = .*\) is \(8, 8, 3\) \(height, width, channels\); "
                                           r"its camera sees \(\d+, \d+, 3\)"):
        SmallFrames(ds, cfg)


def test_a_plugin_that_renders_no_views_is_named_in_a_bench(motion_scene, tmp_path, monkeypatch):
    """A plug-in whose scorer yields no (prediction, ground truth) pairs failed inside score_pairs
    ('no image pairs'), naming nothing; in a bench its cell is now a failed row naming the plug-in."""
    from benchmark.config import BenchConfig, CellSpec
    from benchmark.runner import run_bench
    from common.config import build_config
    from recon.methods.d3dgs import D3DGS

    class NoViews(D3DGS):
        name = "no_views"

        @classmethod
        def scorer(cls, dataset, cfg):
            class Empty:
                def eval_pairs(self, model, records, backend="auto"):
                    return []
            return Empty()

    monkeypatch.setitem(registry.METHODS, "no_views", NoViews)
    over = {**TINY, "frames": "sharp"}
    cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [motion_scene.name],
                                     "cells": {"none": CellSpec("no_views", overrides=over)}})
    rows = run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "runs", studies=("main",), progress=False,
                     log=lambda s: None)
    assert rows[0]["status"] == "failed"
    assert "method 'no_views' (" in rows[0]["error"] and "its scorer gave 0 (prediction, ground truth) pairs" in rows[0]["error"]
