"""train.precision: `auto` picks the dtype measured faster (never the slower one), caches the answer per
machine, records it in run.json / log / model, and a checkpoint resumes under whatever precision the
machine it resumes on picks."""
import json
import math
import warnings

import pytest
import torch

import recon
from common.config import ConfigError
from recon import precision as prec
from recon.deform import DeformationField
from recon.model import upgrade_meta
from recon.render import deformed

CPU = torch.device("cpu")


class Killed(Exception):
    pass


def fake_timer(timings):
    calls = []

    def timer(device, size=(8, 256)):
        calls.append(device)
        return dict(timings)
    timer.calls = calls
    return timer


@pytest.mark.parametrize("f32, bf16", [(85.0, 3898.0), (300.0, 103.0), (1.0, 1.0), (2.0, 1.999), (1e-3, 1e6)])
def test_auto_never_picks_the_dtype_measured_slower(f32, bf16, tmp_path):
    timer = fake_timer({"float32": f32, "bfloat16": bf16})
    choice = prec.resolve_precision("auto", CPU, cache=tmp_path / "p.json", timer=timer)
    expected = "bfloat16" if bf16 < f32 else "float32"          # a tie keeps the exact dtype
    assert choice.dtype == expected and choice.source == "measured" and len(timer.calls) == 1
    assert choice.timings_ms[choice.dtype] == min(f32, bf16)
    # a second start on the same machine reads the cache: same answer, nothing measured
    again = prec.resolve_precision("auto", CPU, cache=tmp_path / "p.json", timer=timer)
    assert again.dtype == expected and again.source == "cached" and len(timer.calls) == 1


def test_forced_precision_is_taken_as_it_is_and_measures_nothing(tmp_path):
    timer = fake_timer({"float32": 1.0, "bfloat16": 2.0})
    for dtype in ("float32", "bfloat16"):
        choice = prec.resolve_precision(dtype, CPU, cache=tmp_path / "p.json", timer=timer)
        assert (choice.dtype, choice.source) == (dtype, "config")
    assert timer.calls == [] and not (tmp_path / "p.json").exists()
    with pytest.raises(ValueError, match="train.precision: expected one of auto, float32, bfloat16, got 'fp16'"):
        prec.resolve_precision("fp16", CPU)


def test_the_cache_is_per_machine_key_and_survives_bad_files(tmp_path, monkeypatch):
    cache = tmp_path / "p.json"
    slow_bf16 = fake_timer({"float32": 10.0, "bfloat16": 400.0})
    assert prec.resolve_precision("auto", CPU, cache=cache, timer=slow_bf16).dtype == "float32"
    # another thread count is another key: measured again, both kept
    old = torch.get_num_threads()
    fast_bf16 = fake_timer({"float32": 10.0, "bfloat16": 4.0})
    try:
        torch.set_num_threads(old + 1)
        assert prec.resolve_precision("auto", CPU, cache=cache, timer=fast_bf16).dtype == "bfloat16"
    finally:
        torch.set_num_threads(old)
    machines = json.loads(cache.read_text())["machines"]
    assert len(machines) == 2 and all(f"| {n} threads" in "".join(machines) for n in (old, old + 1))
    assert prec.resolve_precision("auto", CPU, cache=cache, timer=fast_bf16).source == "cached"
    # a broken or foreign cache file is measured over, not a crash
    for text in ("{not json", json.dumps({"format": "other"}), json.dumps({"format": prec.CACHE_FORMAT, "machines": {
            prec.machine_key(CPU): {"timings_ms": {"float32": -1, "bfloat16": "x"}}}})):
        cache.write_text(text)
        timer = fake_timer({"float32": 10.0, "bfloat16": 400.0})
        assert prec.resolve_precision("auto", CPU, cache=cache, timer=timer).source == "measured" and timer.calls
    # a cache that cannot be written: a warning naming the file and the variable, and the choice still made
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.warns(UserWarning, match=r"could not cache .*E4DGS_CACHE_DIR"):
        choice = prec.resolve_precision("auto", CPU, cache=blocker / "p.json", timer=fake_timer({"float32": 1, "bfloat16": 2}))
    assert choice.dtype == "float32" and not (blocker / "p.json").exists()


def test_the_default_cache_lives_in_E4DGS_CACHE_DIR(tmp_path, monkeypatch):
    monkeypatch.setenv("E4DGS_CACHE_DIR", str(tmp_path / "cache"))
    prec.resolve_precision("auto", CPU, timer=fake_timer({"float32": 1.0, "bfloat16": 2.0}))
    data = json.loads((tmp_path / "cache" / prec.CACHE_FILE).read_text())
    assert list(data["machines"]) == [prec.machine_key(CPU)]
    assert data["machines"][prec.machine_key(CPU)]["timings_ms"] == {"float32": 1.0, "bfloat16": 2.0}


def test_auto_on_cuda_is_float32_without_measuring(monkeypatch):
    monkeypatch.setattr(torch.cuda, "get_device_name", lambda device=None: "NVIDIA H100")
    timer = fake_timer({"float32": 9.0, "bfloat16": 1.0})
    choice = prec.resolve_precision("auto", torch.device("cuda"), timer=timer)
    assert (choice.dtype, choice.source) == ("float32", "cuda") and timer.calls == []
    assert choice.machine.startswith("NVIDIA H100 | torch ")


def test_time_deformation_times_both_dtypes_and_stops_timing_a_hopeless_one():
    real = prec.time_deformation(CPU, n_points=64, repeats=1)
    assert set(real) == {"float32", "bfloat16"} and all(math.isfinite(v) and v > 0 for v in real.values())
    # a fake clock: each pass takes what the list says (warm-ups float32 then bfloat16, then the repeats)
    durations = iter([0.010, 0.100] + [0.010, 0.012, 0.008] + [0.0] * 10)
    now = [0.0]
    reads = []

    def clock():
        reads.append(now[0])
        if len(reads) % 2 == 0:          # the end of a pass: advance by its duration
            now[0] += next(durations)
            return now[0]
        return now[0]
    # bfloat16's warm-up is 10x float32's (> STOP_RATIO): only float32 is timed again
    got = prec.time_deformation(CPU, n_points=16, repeats=3, clock=clock)
    assert len(reads) == 2 * (2 + 3) and got == {"float32": pytest.approx(10.0), "bfloat16": pytest.approx(100.0)}


def test_bfloat16_autocast_stays_close_to_float32_and_returns_float32():
    torch.manual_seed(0)
    field = DeformationField()
    with torch.no_grad():
        for head in (field.warp, field.rotation, field.scaling):
            head.weight.normal_(0, 0.05)

    class G:   # the three tensors `deformed` reads
        means = torch.rand(300, 3)
        quats = torch.nn.functional.normalize(torch.randn(300, 4), dim=-1)
        log_scales = torch.full((300, 3), -3.0)

        def __len__(self):
            return 300

        def deformation_inputs(self):
            return self.means
    f32 = deformed(G(), field, 0.4, "float32")
    bf16 = deformed(G(), field, 0.4, "bfloat16")
    for a, b in zip(f32, bf16):
        assert b.dtype == torch.float32 and not torch.equal(a, b)        # it really ran in bf16
        torch.testing.assert_close(b, a, rtol=0, atol=0.02)


def test_config_checks_precision_and_names_the_old_key():
    assert recon.resolve_config("d3dgs").train.precision == "auto"
    with pytest.raises(ConfigError, match="precision: expected auto, float32 or bfloat16"):
        recon.resolve_config("d3dgs", overrides={"train.precision": "half"})
    with pytest.raises(ConfigError, match="deform_bf16: unknown key"):
        recon.resolve_config("d3dgs", overrides={"train.deform_bf16": True})


def test_models_saved_with_deform_bf16_load_with_its_precision():
    meta = upgrade_meta({"deform_bf16": True, "config": {"train": {"deform_bf16": False, "iterations": 5}}})
    assert meta == {"precision": "bfloat16", "config": {"train": {"precision": "float32", "iterations": 5}}}
    assert upgrade_meta({"precision": "float32", "config": {}}) == {"precision": "float32", "config": {}}


def test_a_run_records_its_choice_and_a_resume_takes_the_machine_s(motion_scene, tmp_path, monkeypatch):
    """auto measured bf16 faster at the start; the run is killed, and where it resumes float32 is
    faster: the checkpoint resumes there in float32, and run.json, the log and the model say so."""
    import recon.trainer as trainer_mod

    timings = {"float32": 50.0, "bfloat16": 20.0}
    measured = []

    def resolve(requested, device, **kwargs):
        measured.append(requested)
        return prec.resolve_precision(requested, device, cache=tmp_path / f"cache{len(measured)}.json",
                                      timer=fake_timer(timings))
    monkeypatch.setattr(trainer_mod, "resolve_precision", resolve)
    cfg = {"train.iterations": 8, "train.checkpoint_every": 4, "train.init.n_points_object": 200, "train.densify.enabled": False,
           "train.snapshots": [1.0], "train.warm_up": 1, "train.scale_schedule": False}

    def kill_at_5(trainer, it):
        if it == 5:
            raise Killed
    with pytest.raises(Killed):
        recon.fit(motion_scene, "d3dgs", overrides=cfg, out_dir=tmp_path / "run", progress=False, on_iteration=kill_at_5)
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert [(p["from_iteration"], p["dtype"], p["source"]) for p in run["precision"]] == [(0, "bfloat16", "measured")]
    assert run["precision"][0]["timings_ms"] == timings and run["config"]["train"]["precision"] == "auto"
    timings.update(bfloat16=900.0)                         # another machine: bf16 is slow there
    result = recon.fit(motion_scene, "d3dgs", overrides=cfg, out_dir=tmp_path / "run", progress=False)
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert [(p["from_iteration"], p["dtype"]) for p in run["precision"]] == [(0, "bfloat16"), (4, "float32")]
    log = [json.loads(line) for line in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    assert [(r["iteration"], r["precision"]) for r in log if "precision" in r] == [(1, "bfloat16"), (5, "float32")]
    assert result.model.meta.precision == "float32" == recon.load(tmp_path / "run").meta.precision
    assert result.model.meta.iteration == 8


def test_forced_bfloat16_trains_and_renders_in_bfloat16(motion_scene, tmp_path):
    cfg = {"train.iterations": 3, "train.init.n_points_object": 200, "train.snapshots": [1.0], "train.warm_up": 1,
           "train.scale_schedule": False, "train.precision": "bfloat16"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = recon.fit(motion_scene, "d3dgs", overrides=cfg, out_dir=tmp_path / "run", progress=False)
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert [(p["dtype"], p["source"]) for p in run["precision"]] == [("bfloat16", "config")]
    assert result.model.meta.precision == "bfloat16"
    img = result.model.render(0, 0.5)
    assert torch.isfinite(img).all()
