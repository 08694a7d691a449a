import numpy as np
import pytest
import torch

from recon.losses import l1, photometric_loss, ssim, ssim_ref


def test_ssim_identity_and_bounds():
    g = torch.Generator().manual_seed(0)
    a = torch.rand(32, 40, 3, generator=g, dtype=torch.float64)
    assert ssim(a, a).item() == pytest.approx(1.0)
    b = torch.rand(32, 40, 3, generator=g, dtype=torch.float64)
    assert -1.0 <= ssim(a, b).item() < 0.2
    assert photometric_loss(a, a).item() == pytest.approx(0.0, abs=1e-12)


def test_ssim_matches_scikit_image_away_from_the_borders():
    from skimage.metrics import structural_similarity

    g = torch.Generator().manual_seed(1)
    a = torch.rand(48, 48, 1, generator=g, dtype=torch.float64)
    b = (a + 0.1 * torch.randn(48, 48, 1, generator=g, dtype=torch.float64)).clamp(0, 1)
    _, full = structural_similarity(a[..., 0].numpy(), b[..., 0].numpy(), gaussian_weights=True, sigma=1.5,
                                    use_sample_covariance=False, data_range=1.0, full=True)
    from recon.losses import C1, C2, _window
    import torch.nn.functional as F
    # ours, per pixel, on the interior where zero padding plays no part
    x, y = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]
    w = _window(11, 1.5, 1, torch.float64, "cpu")
    mu_x, mu_y = F.conv2d(x, w), F.conv2d(y, w)
    sxx, syy = F.conv2d(x * x, w) - mu_x ** 2, F.conv2d(y * y, w) - mu_y ** 2
    sxy = F.conv2d(x * y, w) - mu_x * mu_y
    ours = ((2 * mu_x * mu_y + C1) * (2 * sxy + C2)) / ((mu_x ** 2 + mu_y ** 2 + C1) * (sxx + syy + C2))
    np.testing.assert_allclose(ours[0, 0].numpy(), full[5:-5, 5:-5], atol=1e-6)


def test_losses_are_differentiable_and_known():
    a = torch.zeros(8, 8, 3, requires_grad=True)
    ref = torch.full((8, 8, 3), 0.25)
    assert l1(a, ref).item() == pytest.approx(0.25)
    photometric_loss(a, ref).backward()
    assert torch.all(torch.isfinite(a.grad)) and a.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="shapes differ"):
        ssim(a, ref[:4])


@pytest.mark.parametrize("shape", [(32, 40, 3), (26, 35, 1), (9, 7, 2), (4, 5, 3)])
def test_separable_ssim_matches_the_2d_window_forward_and_backward(shape):
    """The fast SSIM (two 1-D passes) against the reference (the 11x11 window), in float64 to rounding
    and in float32 to its precision; images smaller than the window (coarse stages) included, where
    the zero padding covers most of the window."""
    g = torch.Generator().manual_seed(sum(shape))
    a = torch.rand(*shape, generator=g, dtype=torch.float64)
    b = (a + 0.2 * torch.randn(*shape, generator=g, dtype=torch.float64)).clamp(0, 1)
    for dtype, tol in ((torch.float64, 1e-12), (torch.float32, 2e-5)):
        outs = []
        for fn in (ssim, ssim_ref):
            x = a.to(dtype).clone().requires_grad_(True)
            v = fn(x, b.to(dtype))
            v.backward()
            outs.append((v.detach(), x.grad))
        (v1, g1), (v0, g0) = outs
        assert abs(v1.item() - v0.item()) <= tol
        assert torch.all(torch.isfinite(g1))
        assert (g1 - g0).abs().max().item() <= tol * g0.abs().max().item()
        assert g0.abs().max().item() > 0


def test_ssim_of_a_shifted_image_drops_as_the_window_sees_it():
    """A one-pixel shift of a smooth pattern keeps SSIM high; of white noise it destroys it."""
    yy, xx = torch.meshgrid(torch.arange(40.0), torch.arange(48.0), indexing="ij")
    smooth = (0.5 + 0.4 * torch.sin(xx / 6) * torch.cos(yy / 7))[..., None].double()
    noise = torch.rand(40, 48, 1, generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    assert ssim(smooth[:, 1:], smooth[:, :-1]).item() > 0.95
    assert ssim(noise[:, 1:], noise[:, :-1]).item() < 0.1
