"""tools.curves_alternated: runs take turns of equal training seconds, a run sliced into turns trains
exactly the model an uninterrupted run trains, and the time to a goal is read off the curve."""
import argparse

import pytest
import torch

import recon
from tools.curves_alternated import alternate, crossing_s, run_spec
from tools.field_curves import run_overrides

SETS = {"train.iterations": 400, "train.init.n_points_object": 300, "train.precision": "float32",
        "train.checkpoint_every": 1000, "train.warm_up": 2}


def test_run_spec():
    assert run_spec("a=configs/x.yaml:mlp") == {"name": "a", "config": "configs/x.yaml", "field": "mlp", "scale": 1.0}
    assert run_spec("t=c.yaml:trajectory:12")["scale"] == 12.0
    for bad in ["c.yaml:mlp", "a=c.yaml", "a=c.yaml:hash", "a=c.yaml:mlp:0", "a=c.yaml:mlp:nan", "=c.yaml:mlp",
                "a=c.yaml:mlp:2:3"]:
        with pytest.raises(argparse.ArgumentTypeError):
            run_spec(bad)


def test_crossing_is_linear_between_the_points_around_it():
    curve = [{"wall_s": 0.0, "psnr": 30.0, "psnr_dyn": None}, {"wall_s": 100.0, "psnr": 34.0, "psnr_dyn": 20.0},
             {"wall_s": 200.0, "psnr": 38.0, "psnr_dyn": 26.0}, {"wall_s": 300.0, "psnr": 35.0, "psnr_dyn": 27.0}]
    assert crossing_s(curve, "psnr", 36.0) == pytest.approx(150.0)
    assert crossing_s(curve, "psnr", 38.0) == pytest.approx(200.0)
    assert crossing_s(curve, "psnr", 29.0) == 0.0                       # the start already meets it
    assert crossing_s(curve, "psnr", 38.5) is None
    assert crossing_s(curve, "psnr_dyn", 25.0) == pytest.approx(100.0 + 100.0 * 5.0 / 6.0)
    assert crossing_s(curve, "psnr_dyn", 19.0) == 100.0                 # the first point that has the value


def test_turns_alternate_and_slicing_changes_nothing(motion_scene, tmp_path):
    runs = [{"name": "a", "config": None, "field": "mlp", "scale": 1.0},
            {"name": "b", "config": None, "field": "trajectory", "scale": 1.0}]
    done = alternate(str(motion_scene), "d3dgs", runs, tmp_path / "alt", max_train_s=0.9, slice_s=0.3,
                     snapshots=[0.5, 1.0], sets=SETS, log=lambda *_: None)
    slices = done["slices"]
    assert [s["run"] for s in slices] == ["a", "b"] * 3 and [s["round"] for s in slices] == [1, 1, 2, 2, 3, 3]
    for s in slices:                          # each turn ends at its pass's budget, one step past at most
        assert s["train_s"] >= s["until_s"] and not s["finished"]
    for name in "ab":
        mine = [s for s in slices if s["run"] == name]
        assert [s["until_s"] for s in mine] == pytest.approx([0.3, 0.6, 0.9])
        assert mine[0]["iteration"] < mine[1]["iteration"] < mine[2]["iteration"] < 400
        assert mine[0]["iteration"] > 2, "the deformation trains in the first turn"
        assert done["initial"][name] is not None and done["trained"][name]["stop"]["iteration"] == mine[-1]["iteration"]

    # run a trained in one go to the iteration where its third turn stopped: the same model
    stop_at = done["trained"]["a"]["stop"]["iteration"]

    class Enough(Exception):
        pass

    def halt(trainer, it):
        if it == stop_at:
            trainer.model.save(tmp_path / "whole.pt")
            raise Enough

    with pytest.raises(Enough):
        recon.fit(motion_scene, "d3dgs", None, tmp_path / "whole",
                  overrides=run_overrides("d3dgs", None, "mlp", 1.0, SETS, [0.5, 1.0]), progress=False,
                  on_iteration=halt)
    whole, sliced = recon.load(tmp_path / "whole.pt"), recon.load(tmp_path / "alt" / "a" / "stopped.pt")
    assert len(whole) == len(sliced)
    for name, p in whole.gaussians.named_parameters():
        torch.testing.assert_close(getattr(sliced.gaussians, name), p, rtol=1e-5, atol=1e-6, msg=name)
    for (name, p), q in zip(whole.deform.named_parameters(), sliced.deform.parameters()):
        torch.testing.assert_close(q, p, rtol=1e-5, atol=1e-6, msg=name)


def test_a_finished_run_sits_out_later_passes(motion_scene, tmp_path):
    runs = [{"name": "short", "config": None, "field": "trajectory", "scale": 1.0}]
    short = {**SETS, "train.iterations": 3}
    done = alternate(str(motion_scene), "d3dgs", runs, tmp_path / "alt", max_train_s=30.0, slice_s=10.0,
                     snapshots=[1.0], sets=short, log=lambda *_: None)
    assert [s["run"] for s in done["slices"]] == ["short"] and done["slices"][0]["finished"]
    assert done["slices"][0]["iteration"] == 3 and done["trained"]["short"]["stop"] is None


def test_the_table_marks_the_stop_and_a_missing_moving_score():
    from tools.field_curves import curves_table

    text = curves_table({"a": [{"iteration": 0, "wall_s": 0.0, "psnr": 30.0, "psnr_dyn": None, "n_gaussians": 5},
                               {"iteration": 9, "wall_s": 9.4, "psnr": 31.234, "psnr_dyn": 20.0, "n_gaussians": 6,
                                "stopped": True}]}, "run").splitlines()
    assert text[0].startswith("| run |") and text[2] == "| a | 0 | 0 | 30.00 | – | 5 |"
    assert text[3] == "| a | 9 (stopped) | 9 | 31.23 | 20.00 | 6 |"
