"""One device per run: placement rules, every tensor a training step creates on the run's device,
The gsplat backend on the CPU (gsplat's own API, its kernels in torch): test_gsplat_cpu.py; the
CUDA-only parity tests: test_gsplat_cuda.py."""

import pytest
import torch

import recon
import recon.device
import recon.raster
from scene_format.reader import SceneDataset
from common.config import ConfigError
from recon.device import DeviceError, run_placement, to_device
from recon.raster import Camera, render
from recon.trainer import Trainer
from tests.recon.test_raster import camera, scene

CPU = torch.device("cpu")


def _fake_machine(monkeypatch, cuda: bool, gsplat: bool):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: cuda)
    monkeypatch.setattr(recon.raster, "gsplat_available", lambda: gsplat)
    monkeypatch.setattr(recon.device, "gsplat_available", lambda: gsplat)


def test_placement_follows_the_machine_and_refuses_what_it_cannot_do(monkeypatch):
    _fake_machine(monkeypatch, cuda=False, gsplat=False)
    assert run_placement("auto", "auto") == (CPU, "cpu")
    assert run_placement("cpu", "torch") == (CPU, "torch")
    with pytest.raises(DeviceError, match="train.device: 'cuda' asked for, but torch .* sees no CUDA"):
        run_placement("cuda", "auto")
    with pytest.raises(DeviceError, match="train.backend: .*'gsplat' renders CUDA tensors"):
        run_placement("cpu", "gsplat")
    _fake_machine(monkeypatch, cuda=True, gsplat=True)
    assert run_placement("auto", "auto") == (torch.device("cuda"), "gsplat")
    assert run_placement("auto", "cpu") == (CPU, "cpu")          # the numba backend keeps a run on the CPU
    assert run_placement("cpu", "auto") == (CPU, "cpu")
    with pytest.raises(DeviceError, match="'cpu' \\(numba\\) renders CPU tensors"):
        run_placement("cuda", "cpu")
    _fake_machine(monkeypatch, cuda=True, gsplat=False)
    assert run_placement("auto", "auto") == (CPU, "cpu")          # no fast CUDA renderer: stay on the CPU
    assert run_placement("cuda", "auto") == (torch.device("cuda"), "torch")


def test_device_and_backend_are_checked_when_the_config_loads():
    with pytest.raises(ConfigError, match="device: expected auto, cpu, cuda or cuda:N, got 'gpu'"):
        recon.resolve_config("d3dgs", overrides={"train.device": "gpu"})
    with pytest.raises(ConfigError, match="backend: expected auto, cpu, gsplat, torch or dense, got 'opengl'"):
        recon.resolve_config("d3dgs", overrides={"train.backend": "opengl"})
    assert recon.resolve_config("d3dgs", overrides={"train.device": "cuda:1"}).train.device == "cuda:1"


def test_to_device_rebuilds_nested_dataclasses():
    cam = camera(dtype=torch.float32)
    moved = to_device({"views": [cam], "n": 3}, "meta")
    assert moved["n"] == 3 and moved["views"][0].K.device.type == "meta" and cam.K.device == CPU
    assert moved["views"][0].width == cam.width


SMALL = {"train.init.n_points_object": 300, "train.iterations": 40, "train.warm_up": 0,
         "train.densify.grad_threshold": 1e-12, "train.eval_every": 20, "train.eval_max_views": 2,
         "train.snapshots": [0.5, 1.0], "train.checkpoint_every": 25, "train.device": "cpu"}
EVENT = {"events.iip_interval": 20_000, "events.iip_threshold": 1e-4, "train.precision": "float32"}
CASES = [("d3dgs", {}), ("deblur_d3dgs", {"frames": "mild", "blur_samples": 3}), ("e4dgs", EVENT),
         ("e4dgs_rgb", {**EVENT, "rgb_frames": "mild", "rgb_samples": 3})]


@pytest.mark.parametrize("method, overrides", CASES, ids=[c[0] for c in CASES])
def test_training_creates_every_tensor_on_the_run_device(motion_scene, tmp_path, method, overrides):
    """After the first iteration torch's default device becomes 'meta'. A tensor that training creates
    without naming the run's device (densification masks and statistics, Adam moments of new
    Gaussians, event maps, IIP weights, backgrounds, evaluation, checkpoints) lands on 'meta' and
    fails the first operation that mixes it with the run's tensors, or its conversion to numpy."""
    cfg = recon.resolve_config(method, overrides={**SMALL, **overrides})
    seen = {}

    def on_iteration(trainer, it):
        if it == 1:
            torch.set_default_device("meta")
        seen["deform"] = seen.get("deform", False) or trainer.model.meta.deform_enabled

    trainer = Trainer(recon.get_method(method)(SceneDataset(motion_scene), cfg), tmp_path / method,
                      progress=False, on_iteration=on_iteration)
    try:
        model = trainer.run()
    finally:
        torch.set_default_device(None)
    densified = [r["densify"] for r in trainer.log if "densify" in r]
    assert any(d.get("cloned", 0) + d.get("split", 0) > 0 for d in densified), densified
    assert seen["deform"] and sum("test_psnr" in r for r in trainer.log) >= 2
    tensors = [*model.gaussians.parameters(), *model.deform.parameters()]
    assert all(t.device == CPU for t in tensors)
