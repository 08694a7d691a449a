"""3DGS densification, opacity reset and the schedule scaled to a budget."""
import math

import pytest
import torch

from common.config import ConfigError
from recon.config import (MIN_OPACITY_RESET_INTERVAL, MIN_WARM_UP, DensifyConfig, TrainConfig)
from recon.densify import DensifyStats, densify_and_prune, reset_opacity
from recon.gaussians import GaussianModel
from recon.raster import RenderOutput


def _model(log_scales, opacities):
    n = len(opacities)
    m = GaussianModel(n, sh_degree=0)
    with torch.no_grad():
        m.means.copy_(torch.arange(3 * n, dtype=torch.float32).view(n, 3))
        m.log_scales.copy_(torch.tensor(log_scales, dtype=torch.float32)[:, None].expand(n, 3))
        m.opacity_logits.copy_(torch.logit(torch.tensor(opacities, dtype=torch.float32)))
        m.sh_dc.copy_(torch.arange(n, dtype=torch.float32)[:, None, None].expand(n, 1, 3))
    opt = torch.optim.Adam([{"params": [p], "name": name} for name, p in m.named_parameters()], lr=0.01, eps=1e-15)
    sum(p.sum() for p in m.parameters()).backward()
    opt.step()
    return m, opt


def test_stats_use_the_ndc_gradient_of_visible_gaussians():
    stats = DensifyStats(3)
    means2d = torch.zeros(3, 2, requires_grad=True)
    (means2d * torch.tensor([[1e-4, 0.0], [0.0, 2e-4], [5.0, 5.0]])).sum().backward()
    out = RenderOutput(None, None, None, torch.tensor([3, 7, 0]), means2d, None)
    stats.add(out, width=200, height=100)
    # pixel gradient x (W/2, H/2); the third Gaussian is not visible (radius 0) and counts nothing
    torch.testing.assert_close(stats.grad_accum, torch.tensor([1e-4 * 100, 2e-4 * 50, 0.0]))
    assert stats.count.tolist() == [1, 1, 0] and stats.max_radii.tolist() == [3, 7, 0]


def test_clone_small_split_large_prune_transparent():
    extent = 10.0
    cfg = DensifyConfig(grad_threshold=1.0, percent_dense=0.01, min_opacity=0.05)
    # 0: big grad, small -> cloned; 1: big grad, large -> split in two; 2: small grad -> kept;
    # 3: transparent -> pruned
    m, opt = _model([math.log(0.05), math.log(0.5), math.log(0.05), math.log(0.05)], [0.5, 0.6, 0.5, 0.01])
    stats = DensifyStats(4)
    stats.grad_accum = torch.tensor([4.0, 6.0, 0.5, 0.0])
    stats.count = torch.tensor([2.0, 2.0, 1.0, 3.0])
    parent1 = {"scale": m.scales[1].detach().clone(), "opacity": m.opacities[1].item(), "dc": m.sh_dc[1].clone()}
    info = densify_and_prune(m, stats, cfg, extent, opt, prune_large=False, generator=torch.Generator().manual_seed(0))
    assert info == {"cloned": 1, "split": 1, "pruned": 1}
    # survivors: 0, 2, the clone of 0, then the two children of 1 (3 was pruned)
    assert len(m) == 5 and len(stats) == 5
    assert [round(v) for v in m.sh_dc[:, 0, 0].tolist()] == [0, 2, 0, 1, 1]
    torch.testing.assert_close(m.means[2], m.means[0])
    torch.testing.assert_close(m.scales[3:], (parent1["scale"] / 1.6).expand(2, 3))
    assert m.opacities[3:].tolist() == pytest.approx([parent1["opacity"]] * 2)
    for p in m.parameters():
        assert opt.state[p]["exp_avg"].shape == p.shape


def test_prune_large_and_extra_mask_and_cap():
    cfg = DensifyConfig(grad_threshold=1.0, max_world_size=0.1, max_screen_size=20, max_gaussians=3)
    m, opt = _model([math.log(0.05), math.log(2.0), math.log(0.05), math.log(0.05)], [0.5] * 4)
    stats = DensifyStats(4)
    stats.max_radii = torch.tensor([5.0, 5.0, 50.0, 5.0])
    extra = torch.tensor([False, False, False, True])
    info = densify_and_prune(m, stats, cfg, 10.0, opt, prune_large=True, extra_prune=extra)
    assert info["pruned"] == 3 and len(m) == 1          # too big in the world, on screen, and by the extra mask
    # the cap: at most max_gaussians - N new ones, largest gradients first
    m, opt = _model([math.log(0.05)] * 3, [0.5] * 3)
    stats = DensifyStats(3)
    stats.grad_accum, stats.count = torch.tensor([5.0, 9.0, 7.0]), torch.ones(3)
    cfg = DensifyConfig(grad_threshold=1.0, min_opacity=0.0, max_gaussians=4)
    assert densify_and_prune(m, stats, cfg, 10.0, opt, prune_large=False)["cloned"] == 1
    assert round(m.sh_dc[-1, 0, 0].item()) == 1             # the clone of the largest gradient


def test_opacity_reset_clamps_and_clears_adam_state():
    m, opt = _model([0.0, 0.0], [0.9, 0.005])
    low = m.opacities[1].item()
    reset_opacity(m, opt, 0.01)
    assert m.opacities.tolist() == pytest.approx([0.01, low], rel=1e-5)
    assert torch.all(opt.state[m.opacity_logits]["exp_avg"] == 0)


def test_schedule_scales_with_the_budget_and_keeps_floors():
    ref = TrainConfig(iterations=40_000).schedule()
    assert (ref.warm_up, ref.densify_start, ref.densify_stop, ref.densify_interval) == (3000, 500, 15000, 100)
    assert ref.opacity_reset_interval == 3000 and ref.position_lr_steps == 30000
    s = TrainConfig(iterations=8000).schedule()
    assert (s.warm_up, s.densify_start, s.densify_stop, s.densify_interval) == (600, 100, 3000, 20)
    assert s.opacity_reset_interval == MIN_OPACITY_RESET_INTERVAL and s.position_lr_steps == 6000
    tiny = TrainConfig(iterations=400).schedule()
    assert tiny.warm_up == MIN_WARM_UP and tiny.densify_interval == 10
    fixed = TrainConfig(iterations=400, scale_schedule=False).schedule()
    assert fixed.warm_up == 3000 and fixed.densify_interval == 100


def test_schedule_written_for_another_budget_scales_from_it():
    recipe = dict(warm_up=300, position_lr_steps=750, deform_lr_steps=750, sh_interval=100,
                  densify=DensifyConfig(start=50, stop=350, interval=25))
    same = TrainConfig(iterations=750, schedule_reference=750, **recipe).schedule()
    unscaled = TrainConfig(iterations=750, scale_schedule=False, **recipe).schedule()
    assert same == unscaled                              # at its own budget the recipe is unchanged
    cut = TrainConfig(iterations=420, schedule_reference=750, **recipe).schedule()
    assert (cut.densify_start, cut.densify_stop, cut.densify_interval) == (28, 196, 14)   # x 0.56
    assert (cut.position_lr_steps, cut.sh_interval) == (420, 56) and cut.warm_up == MIN_WARM_UP   # 168 < floor
    assert TrainConfig(iterations=1500, schedule_reference=750, **recipe).schedule().warm_up == 600
    with pytest.raises(ConfigError, match="schedule_reference"):
        TrainConfig(schedule_reference=0)
