import numpy as np
import pytest
import torch

from recon.losses import l1, photometric_loss, ssim


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
