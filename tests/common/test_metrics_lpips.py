"""Offline LPIPS against the official `lpips` network, run on a minimal torchvision stand-in."""
import sys
import types

import pytest
import torch

from common.metrics.lpips import (LPIPS, backbone_state_from_jax, build_features, default_backbone_path,
                                     lpips_distance)


def _pair(seed=0, shape=(1, 3, 64, 96)):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(shape, generator=g)
    # smooth structure plus noise: a pair LPIPS scores well away from 0
    y = (0.7 * x + 0.3 * torch.roll(x, shifts=(3, 5), dims=(2, 3)) + 0.05 * torch.randn(shape, generator=g)).clamp(0, 1)
    return x, y


@pytest.fixture
def official_lpips(monkeypatch):
    """`lpips.LPIPS` with `torchvision.models.alexnet/vgg16` replaced by stand-ins carrying the same weights."""
    class _Net(torch.nn.Module):
        def __init__(self, net):
            super().__init__()
            self.features = build_features(net)
            # torchvision's features run one layer past LPIPS's last tap; pad so the official slicing fits
            n = len(self.features)
            self.features.add_module(str(n), torch.nn.MaxPool2d(2 if net == "vgg" else 3, 2))
            self.features.load_state_dict(backbone_state_from_jax(default_backbone_path(net), net), strict=False)

    models = types.SimpleNamespace(alexnet=lambda pretrained=True, **kw: _Net("alex"),
                                   vgg16=lambda pretrained=True, **kw: _Net("vgg"),
                                   squeezenet1_1=lambda **kw: None)
    tv = types.ModuleType("torchvision")
    tv.models = models
    monkeypatch.setitem(sys.modules, "torchvision", tv)
    monkeypatch.setitem(sys.modules, "torchvision.models", models)
    for name in [m for m in sys.modules if m == "lpips" or m.startswith("lpips.")]:
        monkeypatch.delitem(sys.modules, name)
    import lpips
    return lpips


@pytest.mark.parametrize("net", ["alex", "vgg"])
def test_lpips_equals_official(official_lpips, net):
    ref = official_lpips.LPIPS(net=net, verbose=False).eval()
    ours = LPIPS(net)
    for seed in range(3):
        x, y = _pair(seed)
        with torch.no_grad():
            want = ref(x, y, normalize=True).flatten()
            got = ours(x, y)
        assert want.item() > 0.01
        assert got.item() == pytest.approx(want.item(), rel=1e-5, abs=1e-7)


def test_lpips_identical_zero_and_symmetric():
    m = LPIPS("alex")
    x, y = _pair(4)
    assert m(x, x).item() == 0.0
    assert m(x, y).item() == pytest.approx(m(y, x).item(), rel=1e-6)


def test_lpips_gray_is_three_equal_channels():
    m = LPIPS("alex")
    x, y = _pair(5, (1, 1, 48, 64))
    assert m(x, y).item() == pytest.approx(m(x.expand(-1, 3, -1, -1), y.expand(-1, 3, -1, -1)).item(), rel=1e-6)
    a, b = x[0, 0].numpy(), y[0, 0].numpy()
    assert lpips_distance(a, b, "alex") == pytest.approx(m(x, y).item(), rel=1e-5)


def test_torchvision_weights_file_gives_the_same_number(tmp_path):
    """A torchvision-layout state dict (features.N.*) loads into the same network."""
    state = {f"features.{k}": v for k, v in backbone_state_from_jax(default_backbone_path("alex"), "alex").items()}
    state["classifier.1.weight"] = torch.zeros(4, 4)     # torchvision files carry a classifier too
    path = tmp_path / "alexnet-owt.pth"
    torch.save(state, path)
    x, y = _pair(6)
    assert LPIPS("alex", backbone=path)(x, y).item() == pytest.approx(LPIPS("alex")(x, y).item(), rel=1e-6)


def test_lpips_grows_with_distortion():
    m = LPIPS("alex")
    x, _ = _pair(7)
    g = torch.Generator().manual_seed(1)
    n = torch.randn(x.shape, generator=g)
    d = [m(x, (x + s * n).clamp(0, 1)).item() for s in (0.02, 0.1, 0.3)]
    assert d[0] < d[1] < d[2]
