"""datagen.geometry_cache: what a start measured from the scene geometry comes back exactly, or not at all."""
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from datagen import geometry_cache
from datagen.blur_geometry import BlurReport, LevelChoice


def _job(root: Path, name: str, blur: BlurReport | None = None, dynamic=None):
    return SimpleNamespace(dir=root / name, blur=blur, windows=blur.windows if blur else {}, dynamic=dynamic or {},
                           rendered=np.array([0, 2, 4, 5]), render_plan={"adaptive_px": 2.0, "rendered_frames": 4})


def _report(seed: int) -> BlurReport:
    rng = np.random.default_rng(seed)
    return BlurReport(
        choices=[LevelChoice("mild", 5.0, 21, 1.0), LevelChoice("shutter", None, 7, 0.8)],
        windows={"mild": {0: (0, 20), 3: (10, 30)}, "shutter": {0: (0, 6)}},
        manifest={"levels": {"mild": {"n_frames": 21, "median_px": np.float32(5.25)}}, "px_per_frame": {"p90": 0.7}},
        view_median_px={"mild": rng.random((2, 4)), "shutter": rng.random((2, 4))})


def _fresh(root: Path, name: str):
    return SimpleNamespace(dir=root / name, blur="unset", windows="unset", dynamic="unset", rendered=None, render_plan=None)


def test_the_measurements_come_back_exactly(tmp_path):
    masks = {(0, 0): np.eye(3, dtype=bool), (1, 2): np.ones((3, 3), bool)}
    jobs = [_job(tmp_path, "lego", _report(0), masks), _job(tmp_path, "lego_x3", _report(1), masks),
            _job(tmp_path, "lego_x9", None, masks)]
    geometry_cache.save(tmp_path / "lego", "abc", jobs)
    back = [_fresh(tmp_path, j.dir.name) for j in jobs]
    assert geometry_cache.load(tmp_path / "lego", "abc", back)
    for a, b in zip(jobs, back):
        assert b.windows == a.windows and b.render_plan == a.render_plan
        assert np.array_equal(b.rendered, a.rendered) and b.dynamic.keys() == a.dynamic.keys()
        assert all(np.array_equal(b.dynamic[v], a.dynamic[v]) and b.dynamic[v].dtype == bool for v in a.dynamic)
        if a.blur is None:
            assert b.blur is None
            continue
        assert b.blur.choices == a.blur.choices                      # None target (exposure-declared) kept as None
        assert b.blur.windows == a.blur.windows and list(b.blur.windows) == list(a.blur.windows)
        assert b.blur.manifest == {"levels": {"mild": {"n_frames": 21, "median_px": 5.25}}, "px_per_frame": {"p90": 0.7}}
        for level in a.blur.view_median_px:
            assert np.array_equal(b.blur.view_median_px[level], a.blur.view_median_px[level])


def test_another_config_or_a_damaged_file_is_measured_again(tmp_path):
    jobs = [_job(tmp_path, "lego", _report(0), {(0, 0): np.eye(2, dtype=bool)})]
    geometry_cache.save(tmp_path / "lego", "abc", jobs)
    assert not geometry_cache.load(tmp_path / "lego", "other", [_fresh(tmp_path, "lego")])
    assert not (tmp_path / "lego" / geometry_cache.FILE_NAME).exists()        # a stale cache is dropped
    geometry_cache.save(tmp_path / "lego", "abc", jobs)
    (tmp_path / "lego" / geometry_cache.FILE_NAME).write_bytes(b"not an npz")
    fresh = _fresh(tmp_path, "lego")
    assert not geometry_cache.load(tmp_path / "lego", "abc", [fresh]) and fresh.blur == "unset"
    assert not geometry_cache.load(tmp_path / "missing", "abc", [fresh])
    # a cache made for the scene alone does not serve a run with a speed variant it never measured
    geometry_cache.save(tmp_path / "lego", "abc", jobs)
    assert not geometry_cache.load(tmp_path / "lego", "abc", [_fresh(tmp_path, "lego"), _fresh(tmp_path, "lego_x3")])
