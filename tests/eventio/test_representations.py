"""eventio.representations: every module's `>>>` example runs, the fast forms equal their references,
and the representations keep their invariants (counts sum to the events, surfaces decay with age)."""
import doctest
import importlib
import pkgutil

import numpy as np
import pytest

import eventio.representations as reps
from eventio.representations import count_image, time_surface, time_surface_ref, voxel_grid, voxel_grid_ref

MODULES = sorted(m.name for m in pkgutil.iter_modules(reps.__path__))


@pytest.mark.parametrize("name", MODULES)
def test_every_module_has_a_passing_example(name):
    mod = importlib.import_module(f"eventio.representations.{name}")
    result = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name} has no >>> example"
    assert result.failed == 0


def random_events(rng, n=500, w=7, h=5, t_max=10_000):
    t = np.sort(rng.integers(0, t_max, n))
    return t, rng.integers(0, w, n), rng.integers(0, h, n), rng.choice([-1, 1], n)


def test_count_images_sum_to_the_events(rng):
    t, x, y, p = random_events(rng)
    signed, split = count_image(x, y, p, 7, 5), count_image(x, y, p, 7, 5, split=True)
    assert split.sum() == len(t) and signed.sum() == p.sum()
    np.testing.assert_array_equal(signed, split[0] - split[1])


def test_time_surface_equals_its_reference_and_decays_with_age(rng):
    t, x, y, p = random_events(rng)
    for t_ref, tau in [(5_000, 1_000.0), (20_000, 300.0), (-1, 50.0)]:
        np.testing.assert_allclose(time_surface(t, x, y, p, 7, 5, t_ref, tau),
                                   time_surface_ref(t, x, y, p, 7, 5, t_ref, tau), rtol=1e-12)
    order = rng.permutation(len(t))                       # events in any order: the latest one counts
    np.testing.assert_array_equal(time_surface(t[order], x[order], y[order], p[order], 7, 5, 6_000, 800.0),
                                  time_surface(t, x, y, p, 7, 5, 6_000, 800.0))
    s = time_surface(np.array([0]), np.array([0]), np.array([0]), np.array([1]), 1, 1, 2_000, 1_000.0)
    assert s[0, 0, 0] == pytest.approx(np.exp(-2.0)) and s[1, 0, 0] == 0
    with pytest.raises(ValueError, match="tau_us"):
        time_surface(t, x, y, p, 7, 5, 0, 0.0)


def test_voxel_grid_keeps_the_polarity_sum(rng):
    t, x, y, p = random_events(rng)
    g = voxel_grid(t, x, y, p, 5, 7, 5)
    np.testing.assert_allclose(g, voxel_grid_ref(t, x, y, p, 5, 7, 5), atol=1e-5)
    assert g.sum() == pytest.approx(p.sum(), abs=1e-3)


def test_reading_and_drawing_events_imports_none_of_the_simulators_modules_that_simulate():
    import subprocess
    import sys

    code = ("import sys, scene_format, recon.event_windows, viewer, eventio.representations, e2vid.voxel; "
            "bad = sorted(m for m in sys.modules if m in ('simulator.simulator', 'simulator.kernels', 'simulator.pixel', "
            "'simulator.noise', 'simulator.readout', 'simulator.event_file')); "
            "print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
