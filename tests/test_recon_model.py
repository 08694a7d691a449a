"""Building blocks of the deformable Gaussians: deformation field, spherical harmonics, initial points."""
import numpy as np
import pytest
import torch

from recon.deform import DeformationField, positional_encoding
from recon.init import dense_to_sparse_sphere, from_point_cloud, random_cube
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
