"""recon.deform_kernels: the deformation MLP at several times with its backward written out, against
the layers autograd differentiates (DeformationField.forward_times_autograd), forward and backward."""
import pytest
import torch

from recon import deform_kernels
from recon.deform import DeformationField


def field_with_heads(depth, width, seed=0, dtype=torch.float64):
    torch.manual_seed(seed)
    f = DeformationField(depth, width).to(dtype)
    for head in (f.warp, f.rotation, f.scaling):       # zero heads would hide every gradient below them
        torch.nn.init.normal_(head.weight, std=0.3)
        torch.nn.init.normal_(head.bias, std=0.1)
    for layer in f.layers:                              # some biases negative: ReLUs cut in every layer
        torch.nn.init.normal_(layer.bias, std=0.3)
    return f


def outputs_and_grads(f, fn, x, times, weights):
    f.zero_grad()
    res = fn(x, times)
    loss = sum(weights[k, j] * (o * torch.cos(o)).sum() for k, r in enumerate(res) for j, o in enumerate(r))
    loss.backward()
    return res, {name: p.grad.clone() for name, p in f.named_parameters()}


@pytest.mark.parametrize("depth, width, times", [(1, 8, [0.4]), (2, 8, [0.1, 0.9]), (3, 16, [0.7]),
                                                 (4, 24, [0.2, 0.25]), (4, 96, [0.0, 1.0, 0.5]),
                                                 (8, 32, [0.3, 0.3]), (5, 12, [0.6, 0.2])])
def test_the_kernel_equals_the_autograd_layers_forward_and_backward(depth, width, times):
    f = field_with_heads(depth, width, seed=depth * width)
    x = torch.rand(57, 3, dtype=torch.float64) * 2 - 1
    weights = torch.rand(len(times), 3, dtype=torch.float64)           # a loss that tells outputs apart
    a, ga = outputs_and_grads(f, f.forward_times, x, times, weights)
    b, gb = outputs_and_grads(f, f.forward_times_autograd, x, times, weights)
    assert len(a) == len(times)
    for ra, rb in zip(a, b):
        assert [o.shape for o in ra] == [(57, 3), (57, 4), (57, 3)]
        for u, v in zip(ra, rb):
            torch.testing.assert_close(u, v, rtol=1e-12, atol=1e-13)
    assert ga.keys() == gb.keys()
    for name in ga:
        torch.testing.assert_close(ga[name], gb[name], rtol=1e-10, atol=1e-12, msg=name)
        assert torch.isfinite(ga[name]).all()
    assert all(ga[name].abs().max() > 0 for name in ga), "every parameter gets a gradient here"


def test_outputs_that_the_loss_does_not_read_give_the_same_gradients():
    f = field_with_heads(4, 16)
    x = torch.rand(30, 3, dtype=torch.float64)
    grads = []
    for fn in (f.forward_times, f.forward_times_autograd):
        f.zero_grad()
        (dx0, _, _), (_, dq1, _) = fn(x, [0.2, 0.8])       # the scales and half of the rest unused
        (dx0.sum() + (dq1 ** 2).sum()).backward()
        grads.append([torch.zeros_like(p) if p.grad is None else p.grad.clone() for p in f.parameters()])
    for u, v in zip(*grads):       # autograd leaves an unread head's gradient None, the kernel zero
        torch.testing.assert_close(u, v, rtol=1e-10, atol=1e-12)
    assert grads[0][-1].abs().max() == 0      # the log-scale head's bias: nothing reads it


def test_the_training_path_is_the_kernel_and_autocast_keeps_the_layers(monkeypatch):
    f = field_with_heads(4, 16, dtype=torch.float32)
    calls = []
    real = deform_kernels._MLPTimes.apply
    monkeypatch.setattr(deform_kernels._MLPTimes, "apply", lambda *a: calls.append(1) or real(*a))
    x = torch.rand(20, 3)
    f.forward_times(x, [0.1, 0.2])
    assert calls == [1]
    with torch.autocast("cpu", dtype=torch.bfloat16):
        f.forward_times(x, [0.1, 0.2])
    assert calls == [1]


def test_positions_get_no_gradient_and_float32_matches_float64():
    f = field_with_heads(4, 32)
    x = (torch.rand(100, 3, dtype=torch.float64) * 2 - 1).requires_grad_(True)
    out64 = f.forward_times(x, [0.3, 0.35])
    sum(o.sum() for r in out64 for o in r).backward()
    assert x.grad is None
    out32 = f.float().forward_times(x.detach().float(), [0.3, 0.35])
    for r64, r32 in zip(out64, out32):
        for u, v in zip(r64, r32):
            assert v.dtype == torch.float32
            torch.testing.assert_close(v.double(), u.detach(), rtol=1e-4, atol=1e-5)
