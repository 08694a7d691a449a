"""Building blocks of the deformable Gaussians: deformation field, spherical harmonics, initial points."""
import numpy as np
import pytest
import torch

from recon.deform import DeformationField, positional_encoding
from recon.point_clouds import dense_to_sparse_sphere, from_point_cloud, random_cube
from recon.sh import C0, eval_sh, n_coeffs, rgb_to_dc, sh_to_color


def test_positional_encoding_layout():
    x = torch.tensor([[0.5, -1.0]])
    e = positional_encoding(x, 3)
    assert e.shape == (1, 2 * 7)
    torch.testing.assert_close(e[0, :2], x[0])
    torch.testing.assert_close(e[0, 2:4], torch.sin(x[0]))
    torch.testing.assert_close(e[0, 4:6], torch.cos(x[0]))
    torch.testing.assert_close(e[0, 10:12], torch.sin(4 * x[0]))


def test_zero_initialised_field_is_the_identity_and_learns():
    field = DeformationField()
    x = torch.randn(50, 3, requires_grad=True)
    for t in (0.0, 0.37, 1.0, torch.rand(50)):
        dx, dq, ds = field(x, t)
        assert torch.all(dx == 0) and torch.all(dq == 0) and torch.all(ds == 0)
    # the layer layout of the public code: 8 x 256, inputs concatenated again after layer 4
    assert len(field.layers) == 8 and field.layers[5].in_features == 256 + 63 + 13
    # gradients reach the heads (so the field can learn) but never the canonical positions
    dx, dq, ds = field(x, 0.5)
    (dx.sum() + dq.sum() + ds.sum()).backward()
    assert field.warp.weight.grad.abs().sum() > 0 and x.grad is None


def test_field_rejects_times_outside_the_clip():
    field = DeformationField(depth=2, width=8)
    with pytest.raises(ValueError, match=r"time must lie in \[0, 1\]"):
        field(torch.zeros(3, 3), 1.2)
    with pytest.raises(ValueError):
        field(torch.zeros(3, 3), torch.tensor([0.1, -0.1, 0.5]))


def test_spherical_harmonics():
    dirs = torch.nn.functional.normalize(torch.randn(20, 3), dim=-1)
    rgb = torch.rand(20, 3)
    sh = torch.zeros(20, n_coeffs(3), 3)
    sh[:, 0] = rgb_to_dc(rgb)
    for deg in range(4):  # only the DC term set: every degree gives the colour, view-independent
        torch.testing.assert_close(sh_to_color(deg, sh, dirs), rgb)
    sh[:, 3, 0] = 1.0     # the x-linear band: value -C1 * x
    torch.testing.assert_close(eval_sh(1, sh, dirs)[:, 0], C0 * sh[:, 0, 0] - 0.4886025119029199 * dirs[:, 0])
    with pytest.raises(ValueError, match="degree must be 0..3"):
        n_coeffs(4)


def test_initial_point_clouds():
    cube = random_cube(10000, 1.5, center=(0, 0, 0.5), seed=1)
    assert cube.shape == (10000, 3) and np.all(np.abs(cube - [0, 0, 0.5]) <= 1.5)
    ball = dense_to_sparse_sphere(200000, radius=10.0, seed=2)
    r = np.linalg.norm(ball, axis=1)
    assert r.max() <= 10.0
    # density (points per volume) falls off with radius: inner shells are far denser
    edges = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
    counts = np.histogram(r, edges)[0]
    density = counts / (4 / 3 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3))
    assert np.all(np.diff(density) < 0) and density[0] > 20 * density[-1]
    assert np.array_equal(random_cube(5, 1.0, seed=3), random_cube(5, 1.0, seed=3))
    pts = from_point_cloud(np.random.rand(100, 3), n_max=10)
    assert pts.shape == (10, 3)
    with pytest.raises(ValueError, match=r"\[N, 3\]"):
        from_point_cloud(np.zeros((4, 2)))


def _model_and_adam(n=6):
    from recon.gaussians import GaussianModel

    g = torch.Generator().manual_seed(0)
    pts = torch.rand(n, 3, generator=g).numpy()
    model = GaussianModel.from_points(pts, colors=torch.rand(n, 3, generator=g), sh_degree=1)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    loss = sum(p.square().sum() for p in model.parameters()) + model.means.sum()
    loss.backward()
    opt.step()
    return model, opt


def test_from_points_activations_and_colours():
    from recon.gaussians import GaussianModel, nearest_neighbour_scale

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [5, 5, 5]], np.float32)
    scale = nearest_neighbour_scale(pts, k=1)
    np.testing.assert_allclose(scale, [1.0, 1.0, 2.0, np.linalg.norm([5, 3, 5])], rtol=1e-6)
    model = GaussianModel.from_points(pts, colors=torch.tensor([[0.2, 0.4, 0.6]] * 4), sh_degree=2)
    assert len(model) == 4 and model.sh_rest.shape == (4, 8, 3)
    torch.testing.assert_close(model.opacities, torch.full((4,), 0.1))
    torch.testing.assert_close(model.colors(torch.tensor([3.0, 3.0, 3.0])), torch.tensor([[0.2, 0.4, 0.6]] * 4))


def test_prune_clone_split_keep_parameters_and_adam_state_aligned():
    model, opt = _model_and_adam(6)
    before = {n: getattr(model, n).detach().clone() for n in ("means", "log_scales", "quats", "opacity_logits")}
    exp_avg = opt.state[model.means]["exp_avg"].clone()
    keep = torch.tensor([True, False, True, True, False, True])
    model.prune(keep, opt)
    assert len(model) == 4 and torch.equal(model.means, before["means"][keep])
    assert torch.equal(opt.state[model.means]["exp_avg"], exp_avg[keep])
    model.clone_selected(torch.tensor([True, False, False, True]), opt)
    assert len(model) == 6 and torch.equal(model.means[4:], model.means[[0, 3]])
    assert torch.all(opt.state[model.means]["exp_avg"][4:] == 0)
    parent_scale = model.scales[1].detach().clone()
    parent_opacity = model.opacity_logits[1].item()
    model.split_selected(torch.tensor([False, True, False, False, False, False]), n=2, optimizer=opt,
                         generator=torch.Generator().manual_seed(1))
    assert len(model) == 7  # one parent replaced by two children
    torch.testing.assert_close(model.scales[-2:], (parent_scale / 1.6).expand(2, 3))
    assert model.opacity_logits[-2:].tolist() == [parent_opacity] * 2
    for p in model.parameters():  # every parameter is known to Adam with matching state shapes
        assert opt.state[p]["exp_avg"].shape == p.shape
    loss = sum(p.square().sum() for p in model.parameters())
    loss.backward()
    opt.step()  # no shape mismatch after the edits


def test_position_learning_rate_schedule():
    from recon.gaussians import position_lr

    assert position_lr(0, 1.6e-4, 1.6e-6, 30000) == pytest.approx(1.6e-4)
    assert position_lr(30000, 1.6e-4, 1.6e-6, 30000) == pytest.approx(1.6e-6)
    assert position_lr(15000, 1.6e-4, 1.6e-6, 30000) == pytest.approx(1.6e-5)   # log-linear midpoint
    assert position_lr(0, 1.6e-4, 1.6e-6, 30000, delay_steps=100, delay_mult=0.01) == pytest.approx(1.6e-6)


def test_render_at_with_an_untrained_field_equals_the_static_model():
    from scene_format.cameras import look_at_opencv
    from recon.gaussians import GaussianModel
    from recon.raster import render
    from recon.render import camera_center, camera_from_pose, render_at

    g = torch.Generator().manual_seed(3)
    model = GaussianModel.from_points((torch.rand(200, 3, generator=g) - 0.5).numpy(), sh_degree=1,
                                      colors=torch.rand(200, 3, generator=g))
    c2w = look_at_opencv((2.0, -2.5, 1.0), (0.0, 0.0, 0.0))
    K = np.array([[40.0, 0, 24], [0, 40.0, 18], [0, 0, 1]])
    cam = camera_from_pose(K, c2w, 48, 36)
    torch.testing.assert_close(camera_center(cam), torch.tensor([2.0, -2.5, 1.0]), atol=1e-5, rtol=0)
    bg = torch.zeros(3)
    field = DeformationField(depth=4, width=32)
    with torch.no_grad():
        static = render(model.means, model.quats, model.scales, model.opacities,
                        model.colors(camera_center(cam)), cam, bg)
        for t in (0.0, 0.6, 1.0):
            out = render_at(model, field, cam, t, bg)
            torch.testing.assert_close(out.image, static.image)
        assert static.alpha.max() > 0.5
        with pytest.raises(ValueError, match=r"time must lie in \[0, 1\]"):
            render_at(model, field, cam, 1.5, bg)


@pytest.mark.parametrize("kind", ["mlp", "trajectory", "none"])
def test_renders_at_several_times_in_one_call_equal_one_call_per_time(kind):
    from scene_format.cameras import look_at_opencv
    from recon.deform import make_field
    from recon.gaussians import GaussianModel
    from recon.render import camera_from_pose, render_views, render_views_times

    g = torch.Generator().manual_seed(5)
    model = GaussianModel.from_points((torch.rand(150, 3, generator=g) - 0.5).numpy(), sh_degree=1,
                                      colors=torch.rand(150, 3, generator=g))
    field = None
    if kind == "mlp":
        field = DeformationField(depth=4, width=32)
        for head in (field.warp, field.rotation, field.scaling):
            torch.nn.init.normal_(head.weight, std=0.05)
    elif kind == "trajectory":
        field = make_field({"kind": "trajectory", "degree": 2, "fourier": 1})
        model.enable_motion(field.n_basis)
        with torch.no_grad():
            model.motion.normal_(0.0, 0.05, generator=g)
    K = np.array([[40.0, 0, 24], [0, 40.0, 18], [0, 0, 1]])
    cams = [camera_from_pose(K, look_at_opencv(p, (0.0, 0.0, 0.0)), 48, 36) for p in [(2.0, -2.5, 1.0), (-2.0, 2.0, 1.5)]]
    bg = torch.zeros(3)
    times = [0.1, 0.9]
    both = render_views_times(model, field, [cams, cams[:1]], times, bg)
    assert [len(r) for r in both] == [2, 1]
    for outs, t in zip(both, times):
        for out, ref in zip(outs, render_views(model, field, cams, t, bg)):
            torch.testing.assert_close(out.image, ref.image, rtol=1e-5, atol=1e-6)
    if field is not None:          # the two times differ, so the shared call did not reuse one time's state
        assert (both[0][0].image - both[1][0].image).abs().max() > 1e-4
    with pytest.raises(ValueError, match="one camera list per time"):
        render_views_times(model, field, [cams], times, bg)
