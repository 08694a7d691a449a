"""One device per run: placement rules, every tensor a training step creates on the run's device,
and the gsplat backend's tensor plumbing (means2d gradient, max_weight) checked on the CPU through
a stand-in for gsplat built from the reference rasterizer. The CUDA-only parity tests are in
test_gsplat_cuda.py."""
import sys
import types

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


# -- the gsplat backend's plumbing, on the CPU ----------------------------------------------------

def gsplat_stand_in() -> types.ModuleType:
    """gsplat's four calls as render_gsplat uses them, computed by our projection and reference
    rasterizer (shapes as gsplat 1.5: a leading camera axis, x/y radii). The tile lists are replaced
    by what the reference needs: isect_tiles passes the radii on as 'offsets' and the detached depths
    as 'flatten_ids'."""
    from recon.raster.project_ref import project_ref
    from recon.raster.rasterize_ref import rasterize_ref

    def fully_fused_projection(means, covars, quats, scales, viewmats, Ks, width, height, eps2d, near_plane,
                               packed):
        assert covars is None and not packed and viewmats.shape == (1, 4, 4) and Ks.shape == (1, 3, 3)
        m2d, conics, depths, radii = project_ref(means, quats, scales, Camera(Ks[0], viewmats[0], width, height))
        return radii[None, :, None].expand(1, -1, 2).contiguous(), m2d[None], depths[None], conics[None], None

    def isect_tiles(means2d, radii, depths, tile_size, tiles_w, tiles_h):
        assert means2d.shape[0] == 1 and radii.shape[-1] == 2
        return None, radii[0, :, 0], depths[0].detach()

    def isect_offset_encode(isect_ids, n_images, tiles_w, tiles_h):
        return isect_ids

    def rasterize_to_pixels(means2d, conics, colors, opacities, width, height, tile_size, offsets, flatten_ids):
        bg = torch.zeros(colors.shape[-1], dtype=colors.dtype)
        image, alpha, _, _ = rasterize_ref(means2d[0], conics[0], flatten_ids, offsets, opacities[0], colors[0],
                                             bg, width, height)
        return image[None], alpha[None, ..., None]

    mod = types.ModuleType("gsplat")
    for f in (fully_fused_projection, isect_tiles, isect_offset_encode, rasterize_to_pixels):
        setattr(mod, f.__name__, f)
    return mod


def _render_and_backprop(render_fn, params, bg, cam, weights):
    leaves = [p.clone().requires_grad_(True) for p in params] + [bg.clone().requires_grad_(True)]
    out = render_fn(*leaves[:5], cam, leaves[5])
    out.means2d.retain_grad()
    w_img, w_alpha, w_depth = weights
    ((out.image * w_img).sum() + (out.alpha * w_alpha).sum() + (out.depth * w_depth).sum()).backward()
    return out, [p.grad for p in leaves]


def test_gsplat_backend_plumbing_gives_densification_its_gradient_and_max_weight(monkeypatch):
    from recon.raster.gsplat_backend import render_gsplat

    monkeypatch.setitem(sys.modules, "gsplat", gsplat_stand_in())
    params, bg = scene(150, 3, seed=5)
    cam = camera(48, 36, f=50.0, seed=5)
    g = torch.Generator().manual_seed(0)
    weights = (torch.rand(36, 48, 3, generator=g, dtype=torch.float64), torch.rand(36, 48, generator=g, dtype=torch.float64),
               torch.rand(36, 48, generator=g, dtype=torch.float64))
    ref, ref_grads = _render_and_backprop(lambda *a: render(*a, backend="cpu"), params, bg, cam, weights)
    out, grads = _render_and_backprop(render_gsplat, params, bg, cam, weights)
    assert callable(out.max_weight_or_fn)              # not computed until read
    for name in ("image", "alpha", "depth", "max_weight"):
        torch.testing.assert_close(getattr(out, name), getattr(ref, name), atol=1e-9, rtol=1e-9, msg=name)
    assert torch.equal(out.radii, ref.radii.to(torch.int32))
    visible = ref.radii > 0
    assert out.means2d.grad is not None and out.means2d.grad[visible].abs().sum() > 0
    torch.testing.assert_close(out.means2d.grad[visible], ref.means2d.grad[visible], atol=1e-9, rtol=1e-7)
    for name, a, b in zip(("means", "quats", "scales", "opacities", "colors", "background"), grads, ref_grads):
        torch.testing.assert_close(a, b, atol=1e-9, rtol=1e-7, msg=name)
