"""The gsplat backend checked in every CI run: gsplat 1.5.3's real Python API with its compiled kernels
replaced by torch (tests/recon/gsplat_on_cpu.py) renders what the cpu backend renders, images and
gradients, on centred and off-centre cameras; trains as the cpu backend trains; is handed float32
only; and a gsplat whose kernels do not run is not picked."""
import pytest
import torch

import gsplat  # noqa: E402  (a test dependency, pyproject [test]: a broken install fails, not skips)

from recon.raster import Camera, render                         # noqa: E402
from recon.raster.gsplat_backend import render_gsplat         # noqa: E402
from tests.recon import gsplat_on_cpu                           # noqa: E402
from tests.recon.test_raster import camera, scene               # noqa: E402


@pytest.fixture
def on_cpu(monkeypatch):
    gsplat_on_cpu.install(monkeypatch)
    return gsplat_on_cpu.calls


def _inputs(n=60, seed=0, max_opacity=0.3, cx_offset=0.0):
    (means, quats, scales, opac, colors), bg = scene(n, 3, seed=seed, dtype=torch.float32)
    opac = opac * (max_opacity / 0.97)                   # alpha at the 3-sigma edge below 1/255 (see below)
    cam = camera(dtype=torch.float32, seed=seed)
    K = cam.K.clone()
    K[0, 2] += cx_offset
    return [means, quats, scales, opac, colors], bg, Camera(K, cam.world_to_cam, cam.width, cam.height)


def _both(args, bg, cam):
    leaves = [a.clone().requires_grad_(True) for a in args]
    outs = {}
    for name, fn in (("gsplat", lambda *a: render_gsplat(*a, cam, bg)), ("cpu", lambda *a: render(*a, cam, bg, "cpu"))):
        xs = [x.detach().clone().requires_grad_(True) for x in leaves]
        out = fn(*xs)
        out.means2d.retain_grad()                          # what densification reads
        g = torch.Generator().manual_seed(5)
        w_img, w_depth = torch.rand(out.image.shape, generator=g), torch.rand(out.depth.shape, generator=g)
        ((out.image * w_img).sum() + (out.depth * w_depth).sum() + out.alpha.sum()).backward()
        outs[name] = (out, [x.grad for x in xs])
    return outs


@pytest.mark.parametrize("cx_offset", [0.0, 8.0])
def test_gsplat_renders_and_differentiates_as_the_cpu_backend(on_cpu, cx_offset):
    """Opacities <= 0.3: beyond the cpu backend's 3-sigma footprint a Gaussian's alpha is below gsplat's
    1/255 threshold, so gsplat's per-tile membership adds nothing. A principal point off centre (here
    8 px of 40; real calibrations have one) differed by 1e-2 while the two clamped the Jacobian differently."""
    args, bg, cam = _inputs(cx_offset=cx_offset)
    outs = _both(args, bg, cam)
    (g, g_grads), (c, c_grads) = outs["gsplat"], outs["cpu"]
    assert float(c.alpha.max()) > 0.3                                   # the scene covers the image
    for key in ("image", "alpha", "depth"):
        torch.testing.assert_close(getattr(g, key), getattr(c, key), atol=2e-6, rtol=1e-6)   # depth ~3: float32
    for name, a, b in zip(("means", "quats", "scales", "opacities", "colors"), g_grads, c_grads):
        assert torch.linalg.vector_norm(a - b) <= 4e-6 * torch.linalg.vector_norm(b) + 1e-9, name
    both = (g.radii > 0) & (c.radii > 0)
    assert g.means2d.grad is not None and g.means2d.grad[both].abs().sum() > 0       # a node of the graph
    torch.testing.assert_close(g.means2d.grad[both], c.means2d.grad[both], atol=1e-6, rtol=1e-4)
    assert callable(g.max_weight_or_fn)                                              # computed when read
    torch.testing.assert_close(g.max_weight, c.max_weight, atol=1e-6, rtol=1e-5)
    assert {k for k, _ in on_cpu} == {"projection", "intersect_tile", "raster"}     # gsplat's path ran


def test_the_old_symmetric_clamp_is_what_an_off_centre_camera_catches(on_cpu, monkeypatch):
    """The parity above holds off centre because both backends clamp about the principal point: put
    the cpu backend's old rule back (symmetric about the image centre) and the images differ."""
    import importlib

    ref = importlib.import_module("recon.raster.project_ref")      # the package re-exports a function of that name
    args, bg, cam = _inputs(cx_offset=8.0, max_opacity=0.9)
    monkeypatch.setattr(ref, "jacobian_limits", lambda fx, fy, cx, cy, w, h: (
        1.3 * 0.5 * w / fx, 1.3 * 0.5 * w / fx, 1.3 * 0.5 * h / fy, 1.3 * 0.5 * h / fy))
    with torch.no_grad():
        g = render_gsplat(*args, cam, bg)
        c = render(*args, cam, bg, "torch")
    assert float((g.image - c.image).abs().max()) > 1e-3


def test_float64_inputs_reach_gsplat_as_float32_and_come_back_in_float64(on_cpu):
    args, bg, cam = _inputs()
    with torch.no_grad():
        f32 = render_gsplat(*args, cam, bg)
        f64 = render_gsplat(*[a.double() for a in args], cam.to(torch.float64), bg.double())
    assert {dtype for _, dtype in on_cpu} == {torch.float32}
    assert f64.image.dtype == torch.float64 and torch.equal(f64.image.float(), f32.image)


def test_training_with_gsplat_reproduces_the_cpu_backends_run(on_cpu, motion_scene, tmp_path, monkeypatch):
    """60 D3DGS iterations with backend gsplat (kernels on the CPU) against backend cpu, densifying every
    10 steps: Gaussian counts within 2 % (densification reads the gradient of gsplat's means2d, averaged
    over the views where a Gaussian is visible, and gsplat's culling bounds each axis by 3.33 sigma,
    ours the major axis by 3 sigma: borderline Gaussians differ) and the same test PSNR."""
    import recon.device
    import recon.raster
    from recon.api import fit

    real = recon.raster.resolve_backend
    monkeypatch.setattr(recon.raster, "resolve_backend", lambda b, d: "gsplat" if b == "gsplat" else real(b, d))
    monkeypatch.setattr(recon.device, "resolve_backend", lambda b, d: "gsplat" if b == "gsplat" else real(b, d))
    over = {"frames": "sharp", "train.iterations": 60, "train.scale_schedule": False, "train.warm_up": 200,
            "train.init.n_points_object": 400, "train.densify.start": 10, "train.densify.stop": 50,
            "train.densify.interval": 10, "train.densify.grad_threshold": 1e-4, "train.device": "cpu",
            "train.precision": "float32", "train.eval_max_views": 4}
    runs = {b: fit(motion_scene, "d3dgs", out_dir=tmp_path / b, overrides={**over, "train.backend": b}, progress=False)
            for b in ("cpu", "gsplat")}
    assert runs["gsplat"].backend == "gsplat" and ("raster", torch.float32) in on_cpu
    n_g, n_c = len(runs["gsplat"].model), len(runs["cpu"].model)
    assert n_c > 2000 and abs(n_g - n_c) <= 0.02 * n_c           # densified alike (measured: 2570 vs 2542)
    assert runs["gsplat"].last_test_psnr[0] == pytest.approx(runs["cpu"].last_test_psnr[0], abs=0.02)   # 23.016 vs 23.013


def test_a_gsplat_whose_kernels_do_not_run_is_not_picked(monkeypatch, capsys):
    """gsplat imports without its kernels (they compile on first use); where they cannot run, `auto`
    must not pick it and die at the first step: one line says why, and the run stays on the torch
    reference (CUDA faked here: the test render on the absent device fails as a failed build would)."""
    import recon.device
    import recon.raster

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    recon.raster.gsplat_available.cache_clear()
    try:
        assert recon.raster.gsplat_available() is False
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "gsplat 1.5.3 is installed but its CUDA kernels do not run here" in err
        assert recon.raster.resolve_backend("auto", "cuda") == "torch"
    finally:
        recon.raster.gsplat_available.cache_clear()
