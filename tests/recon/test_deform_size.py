"""The deformation MLP's size (train.deform_field.depth / width): the paper's 8 x 256 by default and
recorded as before ({"kind": "mlp"}), another size built, recorded, saved, loaded and timed as itself."""
import pytest
import torch

import recon
from common.config import ConfigError
from recon import precision as prec
from recon.deform import PAPER_SIZE, DeformationField, make_field, mlp_spec


def n_params(depth: int, width: int, x_freqs: int = 10, t_freqs: int = 6) -> int:
    """The field's parameter count, from its layout: layer 0 takes the encoding, layer depth // 2 + 1
    the encoding and the hidden state, the others the hidden state; three heads of 3, 4, 3."""
    enc = 3 * (1 + 2 * x_freqs) + (1 + 2 * t_freqs)
    n = enc * width + width
    for i in range(depth - 1):
        fan_in = width + enc if i == depth // 2 else width
        n += fan_in * width + width
    return n + (width + 1) * 10


@pytest.mark.parametrize("depth, width", [(8, 256), (4, 128), (3, 8), (6, 64)])
def test_a_field_of_any_size_has_its_layout_and_starts_as_the_identity(depth, width):
    f = make_field(mlp_spec(depth, width))
    assert isinstance(f, DeformationField) and (f.depth, f.width) == (depth, width)
    assert sum(p.numel() for p in f.parameters()) == n_params(depth, width)
    assert f.spec() == mlp_spec(depth, width) and make_field(f.spec()).spec() == f.spec()
    dx, dq, ds = f(torch.rand(5, 3), 0.4)
    assert dx.abs().max() == 0 and dq.abs().max() == 0 and ds.abs().max() == 0


def test_the_papers_size_is_recorded_as_before():
    assert mlp_spec(*PAPER_SIZE) == {"kind": "mlp"} == DeformationField().spec()
    assert recon.resolve_config("e4dgs").train.deform_field.spec() == {"kind": "mlp"}
    cfg = recon.resolve_config("e4dgs", overrides={"train.deform_field.depth": 4, "train.deform_field.width": 128})
    assert cfg.train.deform_field.spec() == {"kind": "mlp", "depth": 4, "width": 128}
    assert cfg.train.deform_field.spec() == mlp_spec(4, 128)        # the config writes what the field writes


@pytest.mark.parametrize("key, value", [("depth", 2), ("depth", 17), ("depth", 4.5), ("width", 4), ("width", 2048),
                                        ("position_freqs", -1), ("position_freqs", 17), ("position_freqs", 8.5)])
def test_sizes_out_of_range_are_refused_by_name(key, value):
    with pytest.raises(ConfigError, match=key):
        recon.resolve_config("e4dgs", overrides={f"train.deform_field.{key}": value})


def test_precision_is_measured_for_the_size_it_runs(tmp_path):
    sizes = []

    def timer(device, size=PAPER_SIZE):
        sizes.append(size)
        return {"float32": 1.0, "bfloat16": 2.0} if size == PAPER_SIZE else {"float32": 2.0, "bfloat16": 1.0}
    cache = tmp_path / "p.json"
    assert prec.resolve_precision("auto", "cpu", cache=cache, timer=timer).dtype == "float32"
    small = prec.resolve_precision("auto", "cpu", cache=cache, timer=timer, size=(4, 128))
    assert small.dtype == "bfloat16" and small.machine.endswith("| mlp 4x128")
    assert sizes == [PAPER_SIZE, (4, 128)]
    assert prec.resolve_precision("auto", "cpu", cache=cache, timer=timer, size=(4, 128)).source == "cached"
    ms = prec.time_deformation(torch.device("cpu"), n_points=64, repeats=1, size=(3, 16))
    assert set(ms) == {"float32", "bfloat16"} and all(v > 0 for v in ms.values())


@pytest.mark.parametrize("freqs", [0, 6, 8, 10])
def test_the_position_encodings_frequencies_set_the_first_layers_and_are_recorded(freqs):
    cfg = recon.resolve_config("e4dgs", overrides={"train.deform_field.depth": 4, "train.deform_field.width": 16,
                                                   "train.deform_field.position_freqs": freqs})
    spec = cfg.train.deform_field.spec()
    assert spec == ({"kind": "mlp", "depth": 4, "width": 16} if freqs == 10
                    else {"kind": "mlp", "depth": 4, "width": 16, "position_freqs": freqs})   # 10 recorded as before
    f = make_field(spec)
    assert f.x_freqs == freqs and f.spec() == spec
    assert sum(p.numel() for p in f.parameters()) == n_params(4, 16, x_freqs=freqs)
    enc = 3 * (1 + 2 * freqs) + 13
    assert f.layers[0].in_features == enc and f.layers[3].in_features == 16 + enc    # the skip reads it again
    x = torch.rand(9, 3) * 2 - 1
    for head in (f.warp, f.rotation, f.scaling):
        torch.nn.init.normal_(head.weight, std=0.1)
    fast, ref = f.forward_times(x, [0.2, 0.9]), [f.forward_ref(x, t) for t in (0.2, 0.9)]
    for ra, rb in zip(fast, ref):
        for u, v in zip(ra, rb):
            torch.testing.assert_close(u, v, rtol=1e-5, atol=1e-6)


def test_a_small_field_trains_saves_and_loads_as_itself(motion_scene, tmp_path):
    over = {"train.iterations": 12, "train.warm_up": 4, "train.scale_schedule": False, "train.init.n_points_object": 300,
            "train.snapshots": [1.0], "train.densify.enabled": False, "train.precision": "float32", "train.device": "cpu",
            "train.deform_field.depth": 4, "train.deform_field.width": 32, "train.deform_field.position_freqs": 7}
    model = recon.fit(motion_scene, "d3dgs", overrides=over, out_dir=tmp_path / "run", progress=False).model
    assert model.meta.deform_field == {"kind": "mlp", "depth": 4, "width": 32, "position_freqs": 7}
    assert model.deform.warp.weight.abs().max() > 0                    # the heads learned
    loaded = recon.load(tmp_path / "run")
    assert (loaded.deform.depth, loaded.deform.width, loaded.deform.x_freqs) == (4, 32, 7)
    assert torch.equal(loaded.render(0, 0.7), model.render(0, 0.7))


@pytest.mark.parametrize("depth, width", [(8, 256), (4, 128), (3, 8)])
def test_the_split_skip_product_equals_the_concatenated_reference_forward_and_backward(depth, width):
    torch.manual_seed(depth)
    f = DeformationField(depth, width)
    for head in (f.warp, f.rotation, f.scaling):
        torch.nn.init.normal_(head.weight, std=0.1)
    x, t = torch.rand(50, 3, dtype=torch.float64), torch.rand(50, dtype=torch.float64)
    f = f.double()
    grads = []
    for fn in (f.forward, f.forward_ref):
        f.zero_grad()
        outs = fn(x, t)
        sum((o * (k + 1)).sum() for k, o in enumerate(outs)).backward()
        grads.append((outs, [p.grad.clone() for p in f.parameters()]))
    (a, ga), (b, gb) = grads
    for u, v in zip(a, b):
        torch.testing.assert_close(u, v, rtol=1e-12, atol=1e-12)
    for u, v in zip(ga, gb):
        torch.testing.assert_close(u, v, rtol=1e-10, atol=1e-12)
    with torch.autocast("cpu", dtype=torch.bfloat16):     # bf16: the same up to bf16 rounding
        fast, ref = f.float()(x.float(), 0.5), f.forward_ref(x.float(), 0.5)
    for u, v in zip(fast, ref):
        torch.testing.assert_close(u.float(), v.float(), rtol=0.05, atol=0.02)


@pytest.mark.parametrize("depth, width, times", [(8, 256, [0.2, 0.25]), (4, 64, [0.0, 1.0, 0.5]), (3, 16, [0.7]),
                                                 (3, 8, [0.3, 0.3])])
def test_several_times_in_one_call_equal_the_reference_at_each_time_forward_and_backward(depth, width, times):
    torch.manual_seed(width)
    f = DeformationField(depth, width).double()
    for head in (f.warp, f.rotation, f.scaling):
        torch.nn.init.normal_(head.weight, std=0.1)
    x = torch.rand(40, 3, dtype=torch.float64)
    weights = torch.rand(len(times), 3, dtype=torch.float64)          # a loss that tells the times apart
    grads = []
    for outs in (lambda: f.forward_times(x, times), lambda: [f.forward_ref(x, t) for t in times]):
        f.zero_grad()
        res = outs()
        sum(weights[k, j] * (o ** 2).sum() for k, r in enumerate(res) for j, o in enumerate(r)).backward()
        grads.append((res, [p.grad.clone() for p in f.parameters()]))
    (a, ga), (b, gb) = grads
    assert len(a) == len(times)
    for ra, rb in zip(a, b):
        for u, v in zip(ra, rb):
            assert u.shape == v.shape
            torch.testing.assert_close(u, v, rtol=1e-12, atol=1e-12)
    for u, v in zip(ga, gb):
        torch.testing.assert_close(u, v, rtol=1e-10, atol=1e-12)
    assert any(g.abs().max() > 0 for g in ga)
    f = f.float()
    with torch.autocast("cpu", dtype=torch.bfloat16):     # bf16: the same up to bf16 rounding
        fast, ref = f.forward_times(x.float(), times), [f(x.float(), t) for t in times]
    for ra, rb in zip(fast, ref):
        for u, v in zip(ra, rb):
            torch.testing.assert_close(u.float(), v.float(), rtol=0.05, atol=0.02)


@pytest.mark.parametrize("times", [[], [0.2, 1.5], [-0.1]])
def test_times_out_of_range_are_refused(times):
    with pytest.raises(ValueError, match="times in \\[0, 1\\]"):
        DeformationField(2, 8).forward_times(torch.rand(3, 3), times)
