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


def _ssim_against_scikit_image(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(our `ssim` of two images [H, W, C], what scikit-image's structural_similarity (Gaussian window,
    sigma 1.5, population covariance, data range 1) implies for it). The images agree in their outer
    10 px, so our zero-padded border windows see equal images (SSIM 1 there) and every pixel inside
    the 5 px band is one whose window scikit-image also averages: ours = (1 - f) + f x skimage's,
    f the share of the inner pixels."""
    from skimage.metrics import structural_similarity

    ours = ssim(torch.from_numpy(a), torch.from_numpy(b)).item()
    sk = structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0,
                               channel_axis=-1)
    h, w = a.shape[:2]
    f = (h - 10) * (w - 10) / (h * w)
    return ours, (1 - f) + f * sk


def _real_pair(motion_scene, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """Two real frames of the tiny scene (one camera, a quarter of the clip apart), equal in a 10 px band."""
    from scene_format.reader import SceneDataset

    ds = SceneDataset(motion_scene)
    recs = [r for r in ds.frames("train") if r.camera == 0]
    a, b = (ds.load_image(r.path).astype(np.float64) for r in (recs[0], recs[len(recs) // 4]))
    if channels == 1:
        a, b = a.mean(-1, keepdims=True), b.mean(-1, keepdims=True)
    b[:10], b[-10:], b[:, :10], b[:, -10:] = a[:10], a[-10:], a[:, :10], a[:, -10:]
    return a, b


@pytest.mark.parametrize("channels", [3, 1])
def test_ssim_equals_scikit_images_structural_similarity_on_real_frames(motion_scene, channels):
    a, b = _real_pair(motion_scene, channels)
    ours, theirs = _ssim_against_scikit_image(a, b)
    assert 0.3 < theirs < 0.999                   # the frames differ: the comparison means something
    assert ours == pytest.approx(theirs, abs=1e-9)


def test_the_scikit_image_check_fails_on_a_mutated_ssim_map(motion_scene, monkeypatch):
    """The check above catches a wrong SSIM map (the constant C2 taken as 0.03 instead of 0.03 ** 2),
    though `ssim` and `ssim_ref` then still agree with each other."""
    import recon.losses as losses

    a, b = _real_pair(motion_scene, 3)
    real = losses._ssim_map

    def mutated(mu_x, mu_y, exx, eyy, exy):
        sxx, syy, sxy = exx - mu_x ** 2, eyy - mu_y ** 2, exy - mu_x * mu_y
        return ((2 * mu_x * mu_y + losses.C1) * (2 * sxy + 0.03)) / ((mu_x ** 2 + mu_y ** 2 + losses.C1) * (sxx + syy + 0.03))

    monkeypatch.setattr(losses, "_ssim_map", mutated)
    ours, theirs = _ssim_against_scikit_image(a, b)
    assert abs(ours - theirs) > 1e-3
    ta, tb = torch.from_numpy(a), torch.from_numpy(b)
    assert ssim(ta, tb).item() == pytest.approx(ssim_ref(ta, tb).item(), abs=1e-12)     # the shared map hides it
    monkeypatch.setattr(losses, "_ssim_map", real)


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
