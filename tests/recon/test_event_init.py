"""Event-based initialisation: the activity mask and the space carving give the analytic answers,
and `init.kind: events` puts the initial points where the tiny scene's events are."""
import numpy as np
import pytest

from recon import event_supervision as ev
from recon import point_clouds as initial


def test_activity_mask_ignores_isolated_events_and_grows_by_the_dilation():
    counts = np.zeros((20, 30))
    counts[2, 2] = 1                      # an isolated noise event
    counts[10, 15] = 1                    # two neighbouring events of opposite sign
    counts[10, 16] = -1
    active = ev.activity_mask(counts, min_events=2, dilate_px=0)
    assert not active[2, 2]
    # only pixels whose 3x3 box holds both events: rows 9-11, columns 15-16
    rows, cols = np.nonzero(active)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (9, 11, 15, 16) and active.sum() == 6
    grown = ev.activity_mask(counts, min_events=2, dilate_px=2)
    rows, cols = np.nonzero(grown)
    assert (rows.min(), rows.max(), cols.min(), cols.max()) == (7, 13, 13, 18)
    assert grown.sum() == 7 * 6


def _look_at(eye):
    """OpenCV world-to-camera [4, 4] of a camera at eye looking at the origin (up +z or +y)."""
    eye = np.asarray(eye, float)
    f = -eye / np.linalg.norm(eye)
    up = np.array([0, 0, 1.0]) if abs(f[2]) < 0.9 else np.array([0, 1.0, 0])
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    d = np.cross(f, r)                      # y down
    R = np.stack([r, d, f])                 # rows: camera axes in world
    w2c = np.eye(4)
    w2c[:3, :3], w2c[:3, 3] = R, -R @ eye
    return w2c


def _ball_silhouette(K, w2c, radius, w, h):
    """Pixels whose ray passes within `radius` of the origin."""
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    rays = rays @ w2c[:3, :3]              # to world (R^T applied as row vectors)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    c = -w2c[:3, :3].T @ w2c[:3, 3]
    closest = c - (rays @ c)[..., None] * rays
    return np.linalg.norm(closest, axis=-1) <= radius


def test_carving_keeps_the_ball_and_removes_what_a_view_sees_as_empty():
    w, h, radius = 120, 100, 0.5
    K = np.array([[100.0, 0, w / 2], [0, 100.0, h / 2], [0, 0, 1]])
    views = []
    for eye in ([4, 0, 0], [0, 4, 0], [0, 0, 4]):
        w2c = _look_at(eye)
        views.append((K, w2c, _ball_silhouette(K, w2c, radius, w, h)))
    pts = np.random.default_rng(0).uniform(-1.5, 1.5, size=(50_000, 3))
    keep = initial.carve(pts, views)
    r = np.linalg.norm(pts, axis=1)
    # the ball is never carved (a pixel is active by its centre ray, so allow a pixel's width, 0.04)
    assert keep[r <= radius - 0.05].all()
    # a point whose projection is farther than the silhouette's reach along an axis is outside the hull
    assert not keep[np.abs(pts).max(1) > radius * 4 / (4 - 1.5) + 1e-3].any()
    assert keep.mean() < 0.1
    # a point only one view sees is dropped with min_views = 2, and kept with min_views = 1
    one = [views[2]]
    ball_pts = pts[r <= radius - 0.05]
    assert not initial.carve(ball_pts, one, min_views=2).any()
    assert initial.carve(ball_pts, one, min_views=1).all()


def test_sample_kept_draws_only_near_kept_candidates_and_refuses_none():
    cand = np.array([[0.0, 0, 0], [10.0, 0, 0], [0, 10.0, 0]])
    pts = initial.sample_kept(cand, np.array([True, False, False]), 50, jitter=0.1, seed=1)
    assert pts.shape == (50, 3) and np.abs(pts).max() <= 0.1 + 1e-6
    with pytest.raises(ValueError, match="no candidate"):
        initial.sample_kept(cand, np.zeros(3, bool), 5, jitter=0.1)


def test_events_init_puts_points_where_the_scene_is(motion_scene):
    from dataclasses import replace

    from scene_format.reader import SceneDataset
    from recon.config import InitConfig, TrainConfig
    from recon.initial_points import initial_points

    ds = SceneDataset(motion_scene)
    cube = initial_points(ds, replace(TrainConfig(), init=InitConfig(kind="cube", n_points_object=4000)))
    carved = initial_points(ds, replace(TrainConfig(), init=InitConfig(kind="events", n_points_object=4000,
                                                                       carve_candidates=40_000)))
    assert carved.shape == (4000, 3) and np.isfinite(carved).all()
    # the carved points are a strictly smaller volume inside the cube (the scene occupies part of it)
    assert np.ptp(carved, axis=0).prod() < 0.9 * np.ptp(cube, axis=0).prod()


def test_a_carving_that_keeps_nothing_falls_back_to_the_auto_volume_and_says_so(motion_scene, tmp_path):
    import json
    import warnings
    from dataclasses import replace

    import recon
    from scene_format.reader import SceneDataset
    from recon.config import InitConfig, TrainConfig
    from recon.event_init import NoCarvedPointsError
    from recon.initial_points import InitFallbackWarning, initial_points

    ds = SceneDataset(motion_scene)
    nothing = dict(kind="events", n_points_object=500, carve_candidates=5000, carve_min_events=1000)  # no pixel active (the range's top)
    cube = initial_points(ds, replace(TrainConfig(), init=InitConfig(kind="auto", n_points_object=500)))
    with pytest.warns(InitFallbackWarning, match=r"init.kind events -> cube: .*kept no initial point .*\) \(init.carve_fallback: auto\)$"):
        got = initial_points(ds, replace(TrainConfig(), init=InitConfig(**nothing)))
    np.testing.assert_array_equal(got, cube)                  # the paper's volume, as kind: auto would draw it
    with pytest.raises(NoCarvedPointsError, match="kept no initial point.*use init.kind: auto, or init.carve_fallback: auto"):
        initial_points(ds, replace(TrainConfig(), init=InitConfig(**nothing, carve_fallback="error")))
    # a run records it in run.json and trains on
    overrides = {"train.iterations": 3, "train.scale_schedule": False, "train.warm_up": 100,
                 **{f"train.init.{k}": v for k, v in nothing.items()}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # the short schedule's own ConfigWarnings
        recon.fit(motion_scene, "e4dgs", overrides=overrides, out_dir=tmp_path / "run", progress=False)
    run = json.loads((tmp_path / "run" / "run.json").read_text())
    assert run["init_fallback"].startswith("init.kind events -> cube")
    assert (tmp_path / "run" / "model.pt").exists()
