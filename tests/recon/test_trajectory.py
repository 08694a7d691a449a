"""Per-Gaussian trajectories (train.deform_field.kind: trajectory): the fast product against the
readable reference (forward and backward), analytic values, identity at zero, densification carrying
the coefficients, and training / saving / resuming a model with them."""
import json
import math

import numpy as np
import pytest
import torch

import recon
from common.config import ConfigError
from recon.deform import DeformationField, make_field
from recon.gaussians import GaussianModel
from recon.render import deformed
from recon.trajectory import (TrajectoryField, acceleration_energy, acceleration_energy_ref, acceleration_gram,
                              n_basis, trajectory_basis, trajectory_offsets, trajectory_offsets_ref)


class Killed(Exception):
    pass


@pytest.mark.parametrize("degree, fourier", [(3, 2), (1, 0), (0, 3), (5, 4)])
@pytest.mark.parametrize("dtype, tol", [(torch.float32, 1e-5), (torch.float64, 1e-12)])
def test_fast_equals_reference_forward_and_backward(degree, fourier, dtype, tol):
    g = torch.Generator().manual_seed(degree * 10 + fourier)
    motion = torch.randn(257, n_basis(degree, fourier), 10, generator=g, dtype=dtype, requires_grad=True)
    w = torch.randn(257, 10, generator=g, dtype=dtype)
    for t in (0.0, 0.137, 0.5, 1.0):
        ref = torch.cat(trajectory_offsets_ref(motion, t, degree, fourier), 1)
        fast = torch.cat(trajectory_offsets(motion, t, degree, fourier), 1)
        torch.testing.assert_close(fast, ref, rtol=tol, atol=tol)
        (gr,) = torch.autograd.grad((ref * w).sum(), motion)
        (gf,) = torch.autograd.grad((fast * w).sum(), motion)
        torch.testing.assert_close(gf, gr, rtol=tol, atol=tol)


def test_analytic_values():
    # degree 2, one Fourier pair: basis(t) = [t, t^2, sin(2 pi t), 1 - cos(2 pi t)]
    np.testing.assert_allclose(trajectory_basis(torch.tensor(0.25, dtype=torch.float64), 2, 1).numpy(),
                               [0.25, 0.0625, 1.0, 1.0], atol=1e-12)
    assert torch.all(trajectory_basis(torch.tensor(0.0), 3, 2) == 0)            # zero at the clip's start
    motion = torch.zeros(2, 4, 10, dtype=torch.float64)
    motion[0, 0, 0] = 2.0          # dx = 2 t
    motion[1, 1, 9] = -1.0         # dlog_s[2] = -t^2
    motion[1, 2, 3] = 0.5          # dq[0] = 0.5 sin(2 pi t)
    dx, dq, ds = trajectory_offsets(motion, 0.25, 2, 1)
    assert dx[0, 0].item() == pytest.approx(0.5) and ds[1, 2].item() == pytest.approx(-0.0625)
    assert dq[1, 0].item() == pytest.approx(0.5 * math.sin(math.pi / 2))
    assert dx.shape == (2, 3) and dq.shape == (2, 4) and ds.shape == (2, 3)


@pytest.mark.parametrize("degree, fourier", [(3, 2), (1, 0), (0, 3), (5, 4)])
def test_acceleration_energy_fast_equals_reference_forward_and_backward(degree, fourier):
    g = torch.Generator().manual_seed(7 + degree)
    motion = torch.randn(64, n_basis(degree, fourier), 10, generator=g, dtype=torch.float64, requires_grad=True)
    ref, fast = acceleration_energy_ref(motion, degree, fourier), acceleration_energy(motion, degree, fourier)
    torch.testing.assert_close(fast, ref, rtol=1e-10, atol=1e-10)
    (gr,) = torch.autograd.grad(ref, motion)
    (gf,) = torch.autograd.grad(fast, motion)
    torch.testing.assert_close(gf, gr, rtol=1e-10, atol=1e-10)
    assert torch.all(gf[:, :, 3:] == 0)                          # rotation and scale offsets are not penalised


def test_acceleration_energy_analytic_values():
    # degree 3, two Fourier pairs: basis [t, t^2, t^3, sin 2pi t, 1 - cos 2pi t, sin 4pi t, 1 - cos 4pi t]
    def energy(coeffs):          # coeffs: {basis index: (dx, dy, dz)} of one Gaussian
        motion = torch.zeros(1, 7, 10, dtype=torch.float64)
        for b, v in coeffs.items():
            motion[0, b, 0:3] = torch.tensor(v, dtype=torch.float64)
            motion[0, b, 3:] = 5.0                                   # rotation / scale: not counted
        return acceleration_energy(motion, 3, 2).item()
    assert energy({0: (3.0, -1.0, 2.0)}) == pytest.approx(0.0, abs=1e-12)    # constant velocity: no acceleration
    assert energy({1: (1.5, 0.0, 0.0)}) == pytest.approx(4 * 1.5 ** 2)        # x'' = 2 a
    assert energy({2: (0.0, 2.0, 0.0)}) == pytest.approx(12 * 2.0 ** 2)       # x'' = 6 b t: 36 b^2 / 3
    a, b = 0.7, -0.4                                                       # x'' = 2 a + 6 b t
    assert energy({1: (a, 0, 0), 2: (b, 0, 0)}) == pytest.approx(4 * a * a + 12 * a * b + 12 * b * b)
    w1, w2 = 2 * math.pi, 4 * math.pi
    assert energy({3: (0, 0, 0.1)}) == pytest.approx(w1 ** 4 * 0.01 / 2)     # sin: integral of sin^2 is 1/2
    assert energy({6: (0.1, 0, 0)}) == pytest.approx(w2 ** 4 * 0.01 / 2)
    assert energy({3: (0.1, 0, 0), 4: (0.1, 0, 0)}) == pytest.approx(w1 ** 4 * 0.01, rel=1e-10)  # sin, cos orthogonal
    assert energy({3: (0.1, 0, 0), 5: (0.1, 0, 0)}) == pytest.approx((w1 ** 4 + w2 ** 4) * 0.01 / 2, rel=1e-10)
    gram = acceleration_gram(3, 2)
    assert gram.shape == (7, 7) and torch.allclose(gram, gram.T)
    assert torch.linalg.eigvalsh(gram[1:, 1:]).min() > 0                  # positive definite beyond the linear term


def gaussians_with_motion(n=50, seed=0):
    g = GaussianModel.from_points(np.random.default_rng(seed).uniform(-0.5, 0.5, (n, 3)), channels=1)
    g.enable_motion(n_basis(3, 2))
    with torch.no_grad():
        g.motion.normal_(0, 0.1, generator=torch.Generator().manual_seed(seed))
    return g


def test_field_deforms_and_zero_coefficients_are_the_identity():
    field = make_field({"kind": "trajectory", "degree": 3, "fourier": 2})
    assert isinstance(field, TrajectoryField) and list(field.parameters()) == []
    g = GaussianModel.from_points(np.random.default_rng(0).uniform(-0.5, 0.5, (40, 3)), channels=1)
    g.enable_motion(field.n_basis)
    means, quats, log_scales = deformed(g, field, 0.7)
    assert torch.equal(means, g.means) and torch.equal(quats, g.quats) and torch.equal(log_scales, g.log_scales)
    g = gaussians_with_motion()
    means, _, _ = deformed(g, field, 0.7)
    dx, _, _ = trajectory_offsets_ref(g.motion, 0.7, 3, 2)
    torch.testing.assert_close(means, g.means + dx)
    with pytest.raises(ValueError, match="time must lie in"):
        field.deform(g, 1.5)
    with pytest.raises(ValueError, match="no motion coefficients of shape"):
        field.deform(GaussianModel(3, channels=1), 0.5)
    assert isinstance(make_field(None), DeformationField) and isinstance(make_field({"kind": "mlp"}), DeformationField)
    with pytest.raises(ValueError, match="expected kind mlp or trajectory"):
        make_field({"kind": "hexplane"})


def test_densification_carries_the_coefficients_and_their_adam_state():
    g = gaussians_with_motion(10)
    opt = torch.optim.Adam([{"params": [g.means]}, {"params": [g.motion]}], lr=0.1)
    g.motion.grad = torch.ones_like(g.motion)
    g.means.grad = torch.ones_like(g.means)
    opt.step()
    before = g.motion.detach().clone()
    g.clone_selected(torch.arange(10) < 3, opt)
    assert len(g) == 13 and torch.equal(g.motion[10:], before[:3]) and g.motion in opt.state
    assert torch.all(opt.state[g.motion]["exp_avg"][10:] == 0) and torch.all(opt.state[g.motion]["exp_avg"][:10] != 0)
    split = torch.zeros(13, dtype=torch.bool)
    split[[1, 4]] = True
    g.split_selected(split, 2, opt, torch.Generator().manual_seed(0))
    assert len(g) == 15                               # 13 - 2 parents + 4 children
    children = g.motion[-4:]
    for k, parent in enumerate([1, 4, 1, 4]):        # children inherit their parent's trajectory
        assert torch.equal(children[k], before[parent])
    keep = torch.ones(15, dtype=torch.bool)
    keep[0] = False
    g.prune(keep, opt)
    assert g.motion.shape == (14, n_basis(3, 2), 10) and opt.state[g.motion]["exp_avg"].shape == g.motion.shape


def test_config_is_checked():
    cfg = recon.resolve_config("d3dgs", overrides={"train.deform_field.kind": "trajectory"})
    assert cfg.train.deform_field.spec() == {"kind": "trajectory", "degree": 3, "fourier": 2}
    assert recon.resolve_config("d3dgs").train.deform_field.spec() == {"kind": "mlp"}
    with pytest.raises(ConfigError, match="not both 0"):
        recon.resolve_config("d3dgs", overrides={"train.deform_field.degree": 0, "train.deform_field.fourier": 0})
    with pytest.raises(ConfigError, match="kind"):
        recon.resolve_config("d3dgs", overrides={"train.deform_field.kind": "grid"})
    with pytest.raises(ConfigError, match="smoothness.*kind: trajectory"):
        recon.resolve_config("d3dgs", overrides={"train.deform_field.smoothness": 1.0})
    with pytest.raises(ConfigError, match="smoothness"):
        recon.resolve_config("d3dgs", overrides={"train.deform_field.kind": "trajectory",
                                                 "train.deform_field.smoothness": -1.0})


TRAJ = {"train.deform_field.kind": "trajectory", "train.init.n_points_object": 400, "train.snapshots": [1.0],
        "train.warm_up": 5, "train.scale_schedule": False, "train.densify.start": 4, "train.densify.interval": 4,
        "train.densify.stop": 20, "train.densify.grad_threshold": 1e-5, "train.lr.feature": 0.01,
        "train.checkpoint_every": 8}


@pytest.mark.parametrize("method", ["d3dgs", "e4dgs"])
def test_a_trajectory_model_trains_moves_saves_and_resumes(method, motion_scene, tmp_path):
    cfg = {**TRAJ, "train.iterations": 24, **({"train.init.kind": "cube"} if method == "e4dgs" else {})}
    whole = recon.fit(motion_scene, method, overrides=cfg, out_dir=tmp_path / "whole", progress=False).model
    g = whole.gaussians
    assert whole.meta.deform_field == {"kind": "trajectory", "degree": 3, "fourier": 2}
    assert whole.meta.deform_enabled and g.motion is not None and g.motion.shape == (len(g), 7, 10)
    assert g.motion.abs().max() > 0                                   # it learned a motion
    log = [json.loads(line) for line in (tmp_path / "whole" / "log.jsonl").read_text().splitlines()]
    assert any("densify" in r for r in log) and log[0]["precision"] == "float32"
    run = json.loads((tmp_path / "whole" / "run.json").read_text())
    assert run["precision"][0]["source"] == "trajectory"
    # saved and loaded: the same renders
    loaded = recon.load(tmp_path / "whole")
    assert torch.equal(loaded.gaussians.motion, g.motion)
    for cam, t in [(0, 0.0), (1, 0.6)]:
        assert torch.equal(loaded.render(cam, t), whole.render(cam, t))

    def kill_at_10(trainer, it):
        if it == 10:
            raise Killed
    with pytest.raises(Killed):
        recon.fit(motion_scene, method, overrides=cfg, out_dir=tmp_path / "resumed", progress=False, on_iteration=kill_at_10)
    resumed = recon.fit(motion_scene, method, overrides=cfg, out_dir=tmp_path / "resumed", progress=False).model
    torch.testing.assert_close(resumed.gaussians.motion, g.motion, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(resumed.gaussians.means, g.means, rtol=1e-5, atol=1e-6)


def test_the_smoothness_term_lowers_the_trajectories_acceleration(motion_scene, tmp_path):
    cfg = {**TRAJ, "train.iterations": 24}
    energies = {}
    for weight in (0.0, 100.0):
        model = recon.fit(motion_scene, "d3dgs", overrides={**cfg, "train.deform_field.lr_scale": 5,
                                                             "train.deform_field.smoothness": weight},
                          out_dir=tmp_path / f"w{weight}", progress=False).model
        energies[weight] = acceleration_energy(model.gaussians.motion.double(), 3, 2).item()
    assert energies[0.0] > 0
    assert energies[100.0] < 0.5 * energies[0.0]
