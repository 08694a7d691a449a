"""The Gaussian rasterizer: backends against a dense brute force, gradients, hard cases."""
import math

import numpy as np

import pytest
import torch

from recon.raster import Camera, render
from recon.raster.types import ALPHA_MAX, T_MIN

BACKENDS = ["torch", "cpu"]


def rotation(seed):
    g = torch.Generator().manual_seed(seed)
    q, _ = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))
    return q * torch.sign(torch.det(q))


def camera(width=40, height=30, f=45.0, seed=0, dist=3.0, dtype=torch.float64, rotate=True):
    K = torch.tensor([[f, 0, width / 2 + 0.3], [0, f * 1.05, height / 2 - 0.2], [0, 0, 1]], dtype=dtype)
    w2c = torch.eye(4, dtype=dtype)
    if rotate:
        w2c[:3, :3] = rotation(seed).to(dtype)
    w2c[2, 3] = dist
    return Camera(K, w2c, width, height)


def scene(n, channels=3, seed=0, dtype=torch.float64, spread=0.6, scale=(0.02, 0.15)):
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=dtype) * spread
    quats = torch.randn(n, 4, generator=g, dtype=dtype)
    scales = torch.empty(n, 3, dtype=dtype).uniform_(*scale, generator=g)
    opac = torch.rand(n, generator=g, dtype=dtype) * 0.95 + 0.02
    colors = torch.rand(n, channels, generator=g, dtype=dtype)
    bg = torch.rand(channels, generator=g, dtype=dtype)
    return [means, quats, scales, opac, colors], bg


def assert_outputs_close(a, b, atol, atol_means2d=None):
    """Outputs equal within atol; means2d compared where visible (culled ones are undefined)."""
    assert torch.equal(a.radii.long(), b.radii.long())
    visible = a.radii > 0
    for name in ("image", "alpha", "depth", "max_weight", "means2d"):
        x, y = getattr(a, name).detach().double(), getattr(b, name).detach().double()
        assert x.shape == y.shape, name
        tol, rtol = atol, 0.0
        if name == "means2d":  # far off-screen centres are large numbers: relative tolerance too
            x, y, tol, rtol = x[visible], y[visible], atol_means2d or atol, (atol_means2d or 0.0) * 0.1
        assert torch.allclose(x, y, atol=tol, rtol=rtol), f"{name}: max diff {(x - y).abs().max().item():.3g}"


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed, channels", [(0, 3), (1, 1), (2, 3), (3, 2)])
def test_forward_matches_dense_brute_force(backend, seed, channels):
    params, bg = scene(120, channels, seed)
    cam = camera(seed=seed)
    dense = render(*params, cam, bg, backend="dense")
    out = render(*params, cam, bg, backend=backend)
    assert (dense.radii > 0).sum() > 50 and dense.alpha.max() > 0.9
    assert_outputs_close(out, dense, atol=1e-12)


def test_backends_match_each_other_on_a_larger_float32_scene():
    params, bg = scene(3000, 3, seed=7, dtype=torch.float32, spread=0.8, scale=(0.005, 0.06))
    cam = camera(128, 96, f=120.0, seed=7, dtype=torch.float32)
    a = render(*params, cam, bg, backend="torch")
    b = render(*params, cam, bg, backend="cpu")
    assert_outputs_close(a, b, atol=2e-5, atol_means2d=1e-4)


def test_image_composition_of_one_gaussian_is_analytic():
    # a single isotropic Gaussian at the principal point: alpha(d) = o exp(-|d|^2 / (2 sigma^2))
    K = torch.tensor([[50.0, 0, 10.5], [0, 50.0, 10.5], [0, 0, 1]], dtype=torch.float64)
    w2c = torch.eye(4, dtype=torch.float64)
    w2c[2, 3] = 2.0
    cam = Camera(K, w2c, 21, 21)
    sigma_world = 0.08
    params = [torch.tensor([[0.0, 0.0, 0.0]], dtype=torch.float64), torch.tensor([[1.0, 0, 0, 0]], dtype=torch.float64),
              torch.full((1, 3), sigma_world, dtype=torch.float64), torch.tensor([0.8], dtype=torch.float64),
              torch.tensor([[1.0]], dtype=torch.float64)]
    out = render(*params, cam, torch.zeros(1, dtype=torch.float64), backend="cpu")
    var = (50.0 * sigma_world / 2.0) ** 2 + 0.3          # projected variance + low-pass dilation
    v, u = torch.meshgrid(torch.arange(21.0, dtype=torch.float64), torch.arange(21.0, dtype=torch.float64), indexing="ij")
    d2 = (u + 0.5 - 10.5) ** 2 + (v + 0.5 - 10.5) ** 2
    alpha = 0.8 * torch.exp(-0.5 * d2 / var)
    alpha = torch.where(alpha >= 1 / 255, alpha, torch.zeros_like(alpha)).double()
    inside = (u + 0.5 - 10.5).abs().le(out.radii[0]) & (v + 0.5 - 10.5).abs().le(out.radii[0])
    alpha = torch.where(inside, alpha, torch.zeros_like(alpha))
    torch.testing.assert_close(out.alpha, alpha, atol=1e-12, rtol=0)
    torch.testing.assert_close(out.image[..., 0], alpha, atol=1e-12, rtol=0)
    torch.testing.assert_close(out.depth, 2.0 * alpha, atol=1e-12, rtol=0)
    assert out.max_weight[0].item() == pytest.approx(alpha.max().item())
    assert out.radii[0].item() == math.ceil(3 * math.sqrt(var))


def test_gradcheck_of_the_reference():
    params, bg = scene(4, 2, seed=3, scale=(0.1, 0.25), spread=0.3)
    cam = camera(9, 7, f=10.0, seed=3)
    inputs = [p.detach().clone().requires_grad_(True) for p in params] + [bg.clone().requires_grad_(True)]

    def fn(means, quats, scales, opac, colors, background):
        out = render(means, quats, scales, opac, colors, cam, background, backend="torch")
        return out.image, out.alpha, out.depth

    assert torch.autograd.gradcheck(fn, inputs, eps=1e-6, atol=1e-6)


@pytest.mark.parametrize("seed, channels", [(0, 3), (5, 1), (7, 2)])
def test_cpu_gradients_match_reference_autograd(seed, channels):
    params, bg = scene(300, channels, seed)
    cam = camera(48, 36, f=50.0, seed=seed)
    g = torch.Generator().manual_seed(seed)
    w_img = torch.randn(36, 48, channels, generator=g, dtype=torch.float64)
    w_alpha = torch.randn(36, 48, generator=g, dtype=torch.float64)
    w_depth = torch.randn(36, 48, generator=g, dtype=torch.float64)
    grads = {}
    for backend in ("torch", "cpu"):
        inputs = [p.detach().clone().requires_grad_(True) for p in params] + [bg.clone().requires_grad_(True)]
        out = render(*inputs[:5], cam, inputs[5], backend=backend)
        out.means2d.retain_grad()
        loss = (out.image * w_img).sum() + (out.alpha * w_alpha).sum() + 0.1 * (out.depth * w_depth).sum()
        loss.backward()
        grads[backend] = [x.grad for x in inputs] + [out.means2d.grad]
    names = ["means", "quats", "scales", "opacities", "colors", "background", "means2d"]
    for name, a, b in zip(names, grads["torch"], grads["cpu"]):
        scale = a.abs().max().item()
        assert scale > 0, name
        assert torch.allclose(a, b, atol=1e-10 * max(scale, 1.0), rtol=1e-9), f"{name}: {(a - b).abs().max().item():.3g}"


def long_thin_scene(n, dtype=torch.float64, seed=11):
    """Large, elongated, tilted Gaussians: row spans that shift by many columns from row to row (the
    cpu backend's row cursor then restarts) and rows tens of pixels long (its recurrences run long)."""
    params, bg = scene(n, 1, seed, dtype=dtype, spread=0.5)
    g = torch.Generator().manual_seed(seed)
    params[2] = torch.stack([torch.empty(n, dtype=dtype).uniform_(0.2, 0.7, generator=g),
                             torch.empty(n, dtype=dtype).uniform_(0.004, 0.03, generator=g),
                             torch.empty(n, dtype=dtype).uniform_(0.004, 0.03, generator=g)], 1)
    params[3] = torch.empty(n, dtype=dtype).uniform_(0.05, 0.3, generator=g)   # a haze: long compositing
    return params, bg


def loss_gradients(params, bg, cam, backend, seed=0):
    g = torch.Generator().manual_seed(seed)
    inputs = [p.detach().clone().requires_grad_(True) for p in params] + [bg.clone().requires_grad_(True)]
    out = render(*inputs[:5], cam, inputs[5], backend=backend)
    h, w = out.alpha.shape
    loss = ((out.image * torch.randn(h, w, out.image.shape[-1], generator=g, dtype=torch.float64).to(out.image.dtype)).sum()
            + (out.alpha * torch.randn(h, w, generator=g, dtype=torch.float64).to(out.alpha.dtype)).sum()
            + 0.1 * out.depth.sum())
    loss.backward()
    return out, [x.grad.double() for x in inputs]


def test_cpu_long_thin_gaussians_match_brute_force_and_autograd():
    params, bg = long_thin_scene(80)
    cam = camera(64, 48, f=60.0, seed=4)
    dense = render(*params, cam, bg, backend="dense")
    out, grads = loss_gradients(params, bg, cam, "cpu")
    assert (dense.radii > 20).sum() > 20          # long rows
    assert_outputs_close(out, dense, atol=1e-12)
    _, ref = loss_gradients(params, bg, cam, "torch")
    for name, a, b in zip(["means", "quats", "scales", "opacities", "colors", "background"], ref, grads):
        scale = a.abs().max().item()
        assert torch.allclose(a, b, atol=1e-10 * max(scale, 1.0), rtol=1e-9), f"{name}: {(a - b).abs().max().item():.3g}"


def test_cpu_float32_inputs_are_composited_in_float64():
    """float32 inputs give the float64 result of the same values, rounded: the row recurrences'
    factors are computed in float64 (with float32 factors a 40-pixel row drifts by ~1e-5)."""
    params32, bg32 = long_thin_scene(80, dtype=torch.float32)
    cam32 = camera(64, 48, f=60.0, seed=4, dtype=torch.float32)
    # the projection is float32 here; render its float32 screen-space values in both dtypes
    from recon.raster import cpu as cpu_backend
    means2d, conics, depths, radii = cpu_backend.project_cpu(*params32[:3], cam32)
    screen32 = [means2d, conics, depths, params32[3], params32[4], bg32]
    grads = {}
    for dtype in (torch.float32, torch.float64):
        inputs = [x.detach().to(dtype).requires_grad_(True) for x in screen32]
        img, alpha, depth, _ = cpu_backend.rasterize_cpu(inputs[0], inputs[1], inputs[2], radii, inputs[3],
                                                         inputs[4], inputs[5], 64, 48)
        g = torch.Generator().manual_seed(1)
        ((img.double() * torch.randn(img.shape, generator=g, dtype=torch.float64)).sum()
         + (alpha.double() * torch.randn(alpha.shape, generator=g, dtype=torch.float64)).sum()
         + 0.1 * depth.double().sum()).backward()
        grads[dtype] = (img.detach().double(), [x.grad.double() for x in inputs])
    (img32, gr32), (img64, gr64) = grads[torch.float32], grads[torch.float64]
    assert (img32 - img64).abs().max() < 1e-6
    for name, a, b in zip(["means2d", "conics", "depths", "opacities", "colors", "background"], gr32, gr64):
        scale = b.abs().max().item()
        assert scale > 0, name
        assert (a - b).abs().max() <= 2e-6 * scale, f"{name}: {(a - b).abs().max().item() / scale:.2g} relative"


def finite_forward_backward(params, cam, bg, backend):
    inputs = [p.detach().clone().requires_grad_(True) for p in params]
    out = render(*inputs, cam, bg, backend=backend)
    (out.image.sum() + out.alpha.sum() + out.depth.sum()).backward()
    for t in (out.image, out.alpha, out.depth, out.max_weight, *[x.grad for x in inputs]):
        assert torch.all(torch.isfinite(t))
    return out, inputs


@pytest.mark.parametrize("backend", BACKENDS)
def test_gaussians_behind_the_camera_or_on_the_near_plane_are_culled(backend):
    params, bg = scene(3, 3, seed=1, spread=0.0)
    cam = camera(rotate=False)
    params[0] = torch.tensor([[0.0, 0.0, -3.5], [0.0, 0.0, -3.0 + 0.005], [0.0, 0.0, 0.0]], dtype=torch.float64)
    out, inputs = finite_forward_backward(params, cam, bg, backend)
    assert out.radii.tolist()[:2] == [0, 0] and out.radii[2] > 0
    assert torch.all(inputs[0].grad[:2] == 0) and torch.all(out.max_weight[:2] == 0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_extreme_scales_opacity_one_and_zero_quaternion(backend):
    params, bg = scene(4, 3, seed=2, spread=0.2)
    params[2] = torch.tensor([[1e-8] * 3, [1e3] * 3, [0.1, 1e-8, 0.1], [0.05] * 3], dtype=torch.float64)
    params[3] = torch.tensor([1.0, 0.5, 1.0, 1.0], dtype=torch.float64)
    params[1][3] = 0.0  # zero quaternion -> identity rotation
    out, inputs = finite_forward_backward(params, camera(), bg, backend)
    assert out.alpha.max() <= ALPHA_MAX + 1e-12 or out.alpha.max() <= 1.0  # capped per Gaussian
    dense = render(*params, camera(), bg, backend="dense")
    assert_outputs_close(out, dense, atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_hundreds_stacked_on_one_pixel_stop_at_the_transmittance_floor(backend):
    n = 400
    params, bg = scene(n, 3, seed=4, spread=0.0, scale=(0.05, 0.05))
    params[0] = torch.zeros(n, 3, dtype=torch.float64)
    params[0][:, 2] = torch.linspace(-0.5, 0.5, n, dtype=torch.float64)
    params[3] = torch.full((n,), 0.9, dtype=torch.float64)
    cam = camera(rotate=False)
    out, _ = finite_forward_backward(params, cam, bg, backend)
    assert 1.0 - out.alpha.max().item() >= T_MIN * (1 - 1e-9)   # never below the floor
    assert out.alpha.max().item() > 1.0 - 10 * T_MIN            # but the centre is opaque
    dense = render(*params, cam, bg, backend="dense")
    assert_outputs_close(out, dense, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS + ["dense"])
def test_empty_scene_and_one_pixel_image(backend):
    params, bg = scene(0, 3)
    out = render(*params, camera(), bg, backend=backend)
    assert torch.allclose(out.image, bg.expand(30, 40, 3)) and torch.all(out.alpha == 0)
    params, bg = scene(50, 3, seed=6)
    cam = camera(1, 1, f=2.0)
    out, _ = finite_forward_backward(params, cam, bg, backend)
    assert out.image.shape == (1, 1, 3)
    assert_outputs_close(out, render(*params, cam, bg, backend="dense"), atol=1e-12)


def test_bad_shapes_are_clear_errors():
    params, bg = scene(5, 3)
    with pytest.raises(ValueError, match="quats must have shape"):
        render(params[0], params[1][:, :3], *params[2:], camera(), bg)
    with pytest.raises(ValueError, match="background must have shape"):
        render(*params, camera(), bg[:2])
    with pytest.raises(ValueError, match="backend must be one of"):
        render(*params, camera(), bg, backend="opengl")


def test_footprint_boxes_hold_every_pixel_alpha_reaches_and_are_tight():
    """The cpu backend's per-Gaussian pixel boxes: every pixel whose alpha >= 1/255 (inside the
    footprint square) lies in its Gaussian's box; and the box is tight: unless cut by the image or
    the square, its edge columns / rows meet the ellipse d^T Q d <= k = 2 log(o / (1/255)) (whose
    smallest value over a column at offset dx is dx^2 det(Q) / Q_yy) and the next ones out do not."""
    from recon.raster.cpu_raster import footprints
    from recon.raster.project_ref import project_ref
    from recon.raster.rasterize_ref import gaussian_alphas
    from recon.raster.types import ALPHA_MIN

    n, w, h = 150, 64, 48
    params, _ = scene(n, 1, seed=11, scale=(0.02, 0.12))
    params[3] = torch.rand(n, generator=torch.Generator().manual_seed(3), dtype=torch.float64) ** 3 * 0.99
    cam = camera(w, h, f=60.0, seed=11)
    means2d, conics, _, radii = project_ref(*params[:3], cam)
    boxes, _ = footprints(means2d.numpy(), conics.numpy(), radii.numpy().astype(np.int32), params[3].numpy(), w, h)
    vv, uu = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    px = torch.stack([uu.reshape(-1) + 0.5, vv.reshape(-1) + 0.5], -1)
    alphas = gaussian_alphas(px, means2d, conics, params[3], radii).T.reshape(n, h, w)
    n_checked = n_smaller = 0
    for g in range(n):
        u0, u1, v0, v1 = boxes[g]
        hit = alphas[g] >= ALPHA_MIN
        if hit.any():
            rows, cols = torch.nonzero(hit, as_tuple=True)
            assert u0 <= cols.min() and cols.max() <= u1 and v0 <= rows.min() and rows.max() <= v1, g
        if u0 > u1 or params[3][g] < ALPHA_MIN:
            continue
        (a, b, c), (mx, my), r = conics[g].tolist(), means2d[g].tolist(), int(radii[g])
        k, det = 2 * math.log(params[3][g].item() / ALPHA_MIN), a * c - b * b
        reach_x = lambda u: (u + 0.5 - mx) ** 2 * det / c      # noqa: E731
        reach_y = lambda v: (v + 0.5 - my) ** 2 * det / a      # noqa: E731
        for edge, out, lim, reach, centre in ((u0, u0 - 1, 0, reach_x, mx), (u1, u1 + 1, w - 1, reach_x, mx),
                                              (v0, v0 - 1, 0, reach_y, my), (v1, v1 + 1, h - 1, reach_y, my)):
            if edge == lim or abs(out + 0.5 - centre) > r:      # cut by the image or the square
                continue
            assert reach(edge) <= k + 1e-2 and reach(out) > k - 1e-2, (g, edge)
            n_checked += 1
        n_smaller += (u1 - u0 + 1) * (v1 - v0 + 1) < 0.7 * (2 * r + 1) ** 2
    assert n_checked > 100 and n_smaller > 20      # faint Gaussians: much less than the square
