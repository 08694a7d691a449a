"""Per-pixel ground truth (depth, normals, ids, flow) against answers not computed by the code under
test: a board at a known depth sliding at a known speed, the same board moved by a shape key, a camera
sweeping past a static scene (flow from depth and pose alone), DSEC's own PNG convention."""
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from datagen import ground_truth as G
from datagen.blur_geometry import PartMotion

ROOT = Path(__file__).resolve().parents[2]
ALL = ["depth", "flow", "normals", "ids"]


def generate(out: Path, scene: str, scene_yaml: Path, preset: Path) -> Path:
    r = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", scene, "--scene-config", str(scene_yaml),
                        "--preset", str(preset), "--out", str(out), "--no-progress"],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    return out / scene


def board(tmp_path_factory, name: str) -> Path:
    """blur_plane (or its shape-key twin) with every kind of ground truth."""
    out = tmp_path_factory.mktemp(name)
    cfg = yaml.safe_load((ROOT / "blender_scenes" / f"{name}.yaml").read_text())
    cfg["ground_truth"] = ALL
    (out / "scene.yaml").write_text(yaml.safe_dump(cfg))
    (out / "preset.yaml").write_text(f"scenes: [{name}]\n")
    return generate(out / "data", name, out / "scene.yaml", out / "preset.yaml")


@pytest.fixture(scope="module")
def plane(tmp_path_factory):
    return board(tmp_path_factory, "blur_plane")


def _fx(scene: Path) -> float:
    return json.loads((scene / "cameras.json").read_text())["intrinsics"]["fx"]


def test_a_board_at_a_known_depth_gives_that_depth_its_normal_and_its_id_at_every_pixel(plane):
    from blender_scenes import blur_plane as B
    from scene_format.reader import SceneDataset

    d = SceneDataset(plane)
    assert d.ground_truth_kinds == tuple(ALL) and list(d.objects().values()) == ["face"]
    worst = 0.0
    for j in range(len(d.frames("train")) + len(d.frames("test"))):
        g = d.ground_truth(0, j)
        worst = max(worst, float(np.abs(g.depth_m - B.FRONT_DEPTH_M).max()))
        assert np.all(g.ids == 1)
        assert np.abs(g.normals - np.array([0, 0, -1], np.float32)).max() < 1e-6    # facing the camera
    assert worst < 2e-6, worst        # the ray cast runs in single precision: 3.99 m to a few ulp
    print(f"board: max |depth - {B.FRONT_DEPTH_M}| = {worst:.2e} m")


def test_a_sliding_board_has_the_analytic_flow_and_image_velocity(plane):
    """The board slides TRAVEL_M along +y (image +x for this camera) over the clip at depth Z: between
    kept frames keep_every rendered frames apart it moves fx * dy / Z px; its image velocity is
    fx * v / Z px per second of real time."""
    from blender_scenes import blur_plane as B
    from scene_format.reader import SceneDataset

    d = SceneDataset(plane)
    cfg = d.config
    t_end_s = (cfg.n_timestamps - 1) / cfg.real_fps
    dy = B.TRAVEL_M * cfg.frames.keep_every / (cfg.n_timestamps - 1)
    fx = _fx(plane)
    expect_px = fx * dy / B.FRONT_DEPTH_M
    expect_px_per_ms = fx * (B.TRAVEL_M / t_end_s) / B.FRONT_DEPTH_M / 1000.0
    n = len(json.loads((plane / "manifest.json").read_text())["files"])
    assert n > 0
    kept = cfg.n_timestamps // cfg.frames.keep_every + 1
    epe = []
    for j in range(kept):
        g = d.ground_truth(0, j)
        assert np.abs(g.velocity_px_per_ms[..., 0] - expect_px_per_ms).max() < 2e-3 * expect_px_per_ms
        assert np.abs(g.velocity_px_per_ms[..., 1]).max() < 1e-3
        if j == kept - 1:
            assert g.flow_px is None                     # no later kept frame
            continue
        x = np.arange(g.flow_px.shape[1]) + 0.5
        inside = np.broadcast_to(x + expect_px < g.flow_px.shape[1], g.flow_valid.shape)
        assert np.array_equal(g.flow_valid, inside) and not g.flow_occluded.any()   # leaving the image: invalid
        err = np.hypot(g.flow_px[..., 0] - expect_px, g.flow_px[..., 1])[inside]
        epe.append(float(err.max()))
    assert max(epe) < 0.01, epe
    print(f"board: flow {expect_px:.4f} px between kept frames, max end-point error {max(epe):.2e} px")


def test_the_flow_png_reads_back_through_dsecs_loader_convention(plane):
    """DSEC's loader: cv2 (BGR) flipped to RGB, x = (R - 2**15) / 128, y = (G - 2**15) / 128, valid = B."""
    from scene_format.reader import SceneDataset

    g = SceneDataset(plane).ground_truth(0, 0)
    png = cv2.imread(str(plane / "ground_truth" / "flow" / "cam0" / "00000.png"), cv2.IMREAD_UNCHANGED)
    assert png.dtype == np.uint16 and png.shape == g.flow_px.shape[:2] + (3,)
    rgb = png[..., ::-1].astype(np.float32)
    flow = np.stack([(rgb[..., 0] - 2 ** 15) / 128.0, (rgb[..., 1] - 2 ** 15) / 128.0], -1)
    assert np.array_equal(rgb[..., 2] == 1, g.flow_valid)
    assert np.abs(flow - g.flow_px)[g.flow_valid].max() <= 0.5 / 128 + 1e-6


def test_the_same_board_moved_by_a_shape_key_has_the_same_ground_truth(plane, tmp_path_factory):
    """blur_plane_deform moves the board's vertices by a shape key (the object never moves): its
    points are tracked by triangle and barycentric coordinates, and every map equals the rigid board's."""
    from scene_format.reader import SceneDataset

    rigid, deform = SceneDataset(plane), SceneDataset(board(tmp_path_factory, "blur_plane_deform"))
    for j in (0, 2):
        a, b = rigid.ground_truth(0, j), deform.ground_truth(0, j)
        assert np.abs(a.depth_m - b.depth_m).max() < 1e-5
        assert np.abs(a.flow_px - b.flow_px).max() < 1e-3
        assert np.abs(a.velocity_px_per_ms - b.velocity_px_per_ms).max() < 1e-3


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """The tiny preset's cubes held still (motion_strength 0) while the two cameras sweep past them."""
    out = tmp_path_factory.mktemp("sweep")
    preset = yaml.safe_load((ROOT / "configs" / "datasets" / "tiny.yaml").read_text())
    preset["overrides"].update(motion_strength=0.0, ground_truth=["depth", "flow", "ids"])
    preset["overrides"]["blur"]["fit"] = True          # the camera sweep alone blurs less than the targets
    (out / "preset.yaml").write_text(yaml.safe_dump(preset))
    return generate(out / "data", "cubes", ROOT / "blender_scenes" / "cubes.yaml", out / "preset.yaml")


def test_a_camera_moving_past_a_static_scene_has_the_ego_motion_flow_of_depth_and_pose(sweep):
    """Back-project each pixel with its depth through the camera's pose at kept frame j, project it
    with the pose at j + 1: the stored flow equals that to 0.01 px away from object edges."""
    from scene_format.reader import SceneDataset

    d = SceneDataset(sweep)
    cfg = d.config
    K = d.intrinsics.K
    h, w = cfg.render.height, cfg.render.width
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    rays = np.stack([x, y, np.ones_like(x)], -1) @ np.linalg.inv(K).T
    worst, checked = 0.0, 0
    for k in range(d.n_cameras):
        times = d.cameras[k].times_us
        for j in range(len(times[::cfg.frames.keep_every]) - 1):
            g = d.ground_truth(k, j)
            i0, i1 = j * cfg.frames.keep_every, (j + 1) * cfg.frames.keep_every
            c0, c1 = d.pose(k, times[i0]), d.pose(k, times[i1])
            world = (rays * g.depth_m[..., None]) @ c0[:3, :3].T + c0[:3, 3]
            cam1 = (world - c1[:3, 3]) @ c1[:3, :3]
            uv1 = cam1[..., :2] / cam1[..., 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
            expect = uv1 - np.stack([x, y], -1)
            ids = g.ids.astype(np.int64)
            inner = np.ones_like(g.flow_valid)
            for dy_ in (-1, 0, 1):
                for dx_ in (-1, 0, 1):
                    inner &= np.roll(np.roll(ids, dy_, 0), dx_, 1) == ids
            sel = g.flow_valid & inner & (ids > 0)
            sel[[0, -1], :] = sel[:, [0, -1]] = False
            if sel.any():
                worst = max(worst, float(np.abs(g.flow_px - expect)[sel].max()))
                checked += int(sel.sum())
    assert checked > 500 and worst < 0.01, (checked, worst)
    print(f"ego-motion: {checked} pixels, max |flow - analytic| {worst:.2e} px")


def test_the_warped_frame_matches_the_next_and_the_manifest_lists_every_file(sweep):
    m = json.loads((sweep / "manifest.json").read_text())
    check = m["ground_truth"]["warp_check"]
    assert check["psnr_db_warped"] > check["psnr_db_unwarped"] + 3, check
    gt_files = [f for f in m["files"] if f.startswith("ground_truth/")]
    on_disk = sorted(str(p.relative_to(sweep)) for p in (sweep / "ground_truth").rglob("*") if p.is_file())
    assert sorted(gt_files) == on_disk and len(on_disk) > 20
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "check", str(sweep)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    victim = sweep / "ground_truth" / "depth" / "cam0" / "00001.exr"
    saved = victim.read_bytes()
    try:
        victim.write_bytes(saved[:-1] + bytes([saved[-1] ^ 1]))
        r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "check", str(sweep)], capture_output=True, text=True, cwd=ROOT)
        assert r.returncode == 1 and "ground_truth/depth/cam0/00001.exr" in r.stdout + r.stderr
    finally:
        victim.write_bytes(saved)


# ---- pure functions ------------------------------------------------------------------------------

def test_backward_warp_of_a_shifted_image_is_the_image():
    rng = np.random.default_rng(1)
    img = rng.random((10, 12))
    shifted = np.roll(img, 2, axis=1)                  # frame 1: everything 2 px to the right
    warped = G.warp_backward(shifted, np.broadcast_to([2.0, 0.0], (10, 12, 2)))
    assert np.allclose(warped[:, :10], img[:, :10])


def test_a_point_hidden_at_the_later_time_is_occluded_and_one_leaving_the_image_is_invalid():
    hit = np.array([True, True, True, True, False])      # a 5 x 1 view; the last pixel sees nothing
    s = G.ViewSurface(hit, np.zeros((4, 3)), np.zeros(4, np.int64), np.zeros((4, 3)), np.zeros((4, 3)))
    uv1 = np.array([[1.5, 0.5], [0.5, 0.5], [9.0, 0.5], [4.5, 0.5]])     # pixel 1, pixel 0, outside, pixel 4
    z1 = np.array([2.0, 2.0, 2.0, 2.0])
    visible1 = np.array([True, False, True, True])       # the ray cast: the second point is hidden
    flow, valid, occluded = G.forward_flow(s, uv1, z1, visible1, 5, 1)
    # the fourth point lands on pixel 4, where the later frame sees background: nothing hides it
    assert valid.tolist() == [[True, False, False, True, False]]
    assert occluded.tolist() == [[False, True, False, False, False]]
    assert flow[0, 0].tolist() == [1.0, 0.0] and flow[0, 3].tolist() == [1.0, 0.0]


def test_a_visibility_ray_stops_just_short_of_its_point():
    dirs, dist = G.ray_stops(np.zeros(3), np.array([[0.0, 0.0, 4.0], [3.0, 4.0, 0.0]]))
    np.testing.assert_allclose(dirs, [[0, 0, 1], [0.6, 0.8, 0]])
    np.testing.assert_allclose(dist, [4 * (1 - G.VISIBLE_REL) - G.VISIBLE_ABS_M, 5 * (1 - G.VISIBLE_REL) - G.VISIBLE_ABS_M])
    assert np.all(4 - dist[:1] < 1e-3)             # far below any gap between two surfaces


def test_instant_flow_is_the_central_difference_in_px_per_ms():
    uv0, uv1 = np.array([[1.0, 1.0]]), np.array([[3.0, 0.0]])
    v = G.instant_flow(uv0, uv1, 0.5, np.array([True, False]), 2, 1)
    assert v[0, 0].tolist() == [4.0, -2.0] and v[0, 1].tolist() == [0.0, 0.0]


def test_tracking_a_rigid_part_follows_its_matrix():
    """track_uv carries a surface point with its part's matrix: a part translated by 1 m along x in
    front of a camera at the origin looking along +z moves fx / z px."""
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    mats = np.repeat(np.eye(4)[None, None], 2, 0)
    mats[1, 0, 0, 3] = 1.0
    s = G.ViewSurface(np.array([True]), np.array([[0.0, 0.0, 4.0]]), np.array([0]), np.array([[0.0, 0.0, 4.0]]),
                      np.array([[0.0, 0.0, -1.0]]))
    uv, z = G.track_uv(s, PartMotion(mats, {}), np.repeat(np.eye(4)[None], 2, 0), K, np.array([0, 1]))
    assert uv[1, 0, 0] - uv[0, 0, 0] == pytest.approx(25.0) and z[1, 0] == pytest.approx(4.0)


def test_an_event_takes_the_id_of_its_pixel_in_the_nearest_kept_frame():
    ids = np.zeros((3, 1, 2), np.uint16)
    ids[0, 0, 0], ids[1, 0, 0], ids[2, 0, 1] = 1, 2, 3            # frames at 0, 100, 200 us
    t = np.array([0, 49, 50, 51, 170, 250, -5])
    x = np.array([0, 0, 0, 0, 1, 1, 0])
    labels = G.event_labels(t, x, np.zeros(7, np.int64), np.array([0, 100, 200]), ids)
    assert labels.tolist() == [1, 1, 1, 2, 3, 3, 1]               # a tie goes to the earlier frame


def test_every_event_is_labelled_and_the_counts_add_up(gt_scene):
    from eventio.event_file import EventFile
    from scene_format.reader import SceneDataset

    m = json.loads((gt_scene / "manifest.json").read_text())
    by_object = m["ground_truth"]["events_by_object"]
    for k, counts in enumerate(by_object):
        labels = np.load(gt_scene / "ground_truth" / "event_ids" / f"cam{k}.npy")
        with EventFile(gt_scene / "events" / f"cam{k}.h5") as ev:
            assert len(labels) == ev.n == sum(counts.values()) == m["counts"]["events_per_camera"][k]
        assert set(counts) == {"none", *m["ground_truth"]["objects"].values()}
        assert counts["none"] < 0.5 * len(labels)                  # most events come from the moving cubes
    assert SceneDataset(gt_scene).joined_parts() == {}                       # five animated cubes, none joined
    assert json.loads((gt_scene / "ground_truth" / "objects.json").read_text())["joined"] == {}


def test_events_are_labelled_in_bounded_chunks_with_the_labels_of_one_pass(gt_scene, tmp_path, monkeypatch):
    """A paper scene's camera has tens of millions of events: labelling reads them a chunk at a time
    (memory bounded by the chunk, not the clip), and the labels are those of one pass over them all."""
    from datagen import ground_truth_files as F
    from eventio.event_file import EventFile
    from scene_format.reader import SceneDataset

    scene = SceneDataset(gt_scene)
    ids = np.stack([scene.ground_truth(0, j).ids for j in range(len(scene.kept_times_us))])
    objects = scene.manifest["ground_truth"]["objects"]
    with EventFile(gt_scene / "events" / "cam0.h5") as ev:
        n = ev.n
        whole = G.event_labels(ev.times(0, n), *ev.rows(0, n)[:2], scene.kept_times_us, ids)
    reads = []
    rows = EventFile.rows
    monkeypatch.setattr(EventFile, "rows", lambda self, i0, i1: reads.append(i1 - i0) or rows(self, i0, i1))
    monkeypatch.setattr(F, "LABEL_CHUNK", 1000)
    counts = F.label_events(gt_scene, tmp_path, 0, scene.kept_times_us, ids, objects)
    assert max(reads) <= 1000 and sum(reads) == n and len(reads) > 1
    assert np.array_equal(np.load(tmp_path / "event_ids" / "cam0.npy"), whole)
    assert counts == scene.manifest["ground_truth"]["events_by_object"][0]


def test_a_speed_variant_shares_the_maps_and_its_velocity_is_the_scenes_times_its_speed(gt_scene):
    from scene_format.reader import SceneDataset

    scene, variant = SceneDataset(gt_scene), SceneDataset(gt_scene.parent / "cubes_x4")
    assert not (variant.dir / "ground_truth" / "velocity").exists()            # no copies of its own
    for j in (0, 3):
        a, b = scene.ground_truth(0, j), variant.ground_truth(0, j)
        assert a.t_us == scene.kept_times_us[j] == j * 1e6 * scene.config.frames.keep_every / scene.config.render.fps
        assert b.t_us == pytest.approx(a.t_us / 4, abs=1)         # the same frame, 4 times sooner
        for field in ("depth_m", "normals", "ids", "flow_px", "flow_valid"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), field
        assert np.allclose(b.velocity_px_per_ms, 4 * a.velocity_px_per_ms)
        assert (variant.dir / "ground_truth" / "depth" / "cam0" / f"{j:05d}.exr").stat().st_ino == \
            (scene.dir / "ground_truth" / "depth" / "cam0" / f"{j:05d}.exr").stat().st_ino   # a hard link
    m = json.loads((variant.dir / "manifest.json").read_text())
    counts = m["ground_truth"]["events_by_object"][0]               # its own events, labelled at its own times
    assert sum(counts.values()) == m["counts"]["events_per_camera"][0]
    assert m["ground_truth"]["shared_with"] == "cubes" and m["ground_truth"]["velocity_scale"] == 4


JOINED = """
import json
from pathlib import Path
import numpy as np
import bpy
from datagen import render as R
from datagen.config import resolve_scene
from datagen.render_geometry import SurfaceTracer
from scene_format.cameras import intrinsics_from_fov
cfg = resolve_scene("garage", scene_file=Path(r"{root}") / "blender_scenes" / "garage.yaml")
R.build_scene(cfg, intrinsics_from_fov(64, 48, 50.0))
tracer = SurfaceTracer(np.array([0.0, 0.001, 0.002]))
print(json.dumps({{"names": tracer.names, "joined": {{str(k): v for k, v in tracer.joined.items()}}}}))
"""


def test_an_object_the_renderer_joined_names_the_parts_it_holds(tmp_path):
    """Workbench renders faster with static parts joined (blender_scenes.common.consolidate): garage's
    floor, walls, shelves and the rest become one object named "floor". The ground truth's object
    table says what it holds, so "floor 82 % of the events" is not read as the floor alone."""
    script = tmp_path / "joined.py"
    script.write_text(JOINED.format(root=ROOT))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    names, joined = out["names"], {int(k): v for k, v in out["joined"].items()}
    assert joined, "garage has static parts joined into one object"
    for n, parts in joined.items():
        assert parts[0] == names[n] and len(parts) > 1            # named after its first part
        assert not set(parts[1:]) & set(names)                   # the others exist only inside it
    assert {"floor", "wall_n", "wall_s", "wall_e", "wall_w"} <= set(joined[names.index("floor")])


def test_the_ground_truth_matches_blenders_own_cycles_passes_and_ray_casts(gt_scene, tmp_path):
    """A second implementation of every map, in Blender itself (datagen.crosscheck): Cycles' Depth,
    Normal, Object Index and Vector passes at 1 sample, and each flow label against exact visibility by
    Blender's scene ray cast (the surface point carried by its object's matrix, seen from the next
    frame's camera). The depth-test rule the labels used before disagrees on edges; the stored
    labels may not (< 1 %)."""
    out = tmp_path / "crosscheck.json"
    r = subprocess.run([sys.executable, "-m", "datagen.crosscheck", str(gt_scene), "--cameras", "0,1",
                        "--json", str(out)], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    print(r.stdout)
    doc = json.loads(out.read_text())
    for p in doc["passes"]:
        assert p["pixels_seen"] > 100 and p["ids_agree_off_edges"] >= 0.999
        assert p["depth_median_m"] < 1e-4 and p["depth_p95_m"] < 1e-3          # single-precision BVH vs Cycles
        assert p["normal_median_deg"] < 0.05 and p["normal_p95_deg"] < 0.5
    for v in doc["vector"]:        # Cycles' Vector pass and the tracking over one Blender frame either side
        assert v["pixels"] > 100 and v["vector_median_px"] < 1e-4 and v["vector_p95_px"] < 0.01 * v["speed_median_px"] + 1e-4
    tot = doc["occlusion_total"]
    assert tot["checked"] > 500 and tot["labelled_occluded"] > 0
    assert tot["disagree"] <= 0.01 * tot["checked"]
    assert tot["old_disagree"] > tot["disagree"]


@pytest.mark.parametrize("kind, rel", [("ids", "ids/cam0/00001.png"), ("depth", "depth/cam0/00001.exr"),
                                       ("normals", "normals/cam1/00001.exr"), ("flow", "flow/cam0/00001.npz"),
                                       ("velocity", "velocity/cam0/00001.npz")])
def test_a_missing_ground_truth_file_is_an_error_naming_it_never_an_absent_map(gt_scene, tmp_path, kind, rel):
    import shutil

    from scene_format.reader import DatasetError, SceneDataset

    scene = Path(shutil.copytree(gt_scene, tmp_path / "cubes"))
    (scene / "ground_truth" / rel).unlink()
    camera = int(rel.split("/")[1][3:])
    with pytest.raises(DatasetError, match=f"{rel}: missing"):
        SceneDataset(scene).ground_truth(camera, 1)
    SceneDataset(scene).ground_truth(1 - camera, 1)            # the other camera's files are all there


@pytest.mark.parametrize("camera, index", [(-1, 0), (2, 0), (0, -1), (0, 10_000), (True, 0), (0, 1.0), ("0", 0)])
def test_a_camera_or_frame_that_is_not_an_index_of_the_scene_is_a_dataset_error(gt_scene, camera, index):
    from scene_format.reader import DatasetError, SceneDataset

    with pytest.raises(DatasetError, match="ground truth: (camera|kept frame) .*: expected an integer 0 to"):
        SceneDataset(gt_scene).ground_truth(camera, index)


def test_the_last_kept_frame_has_no_flow_and_every_frame_a_velocity(gt_scene):
    from scene_format.reader import SceneDataset

    d = SceneDataset(gt_scene)
    last = d.ground_truth(0, len(d.kept_times_us) - 1)
    assert last.flow_px is None and last.velocity_px_per_ms is not None
    assert d.ground_truth(0, 0).flow_px is not None


def _resign_file(scene: Path, rel: str, content: bytes) -> None:
    """Replace a listed file and re-sign the manifest over it (what a checksum alone cannot catch)."""
    from common.fileio import sha256_file

    path = scene / rel
    path.write_bytes(content)
    m = json.loads((scene / "manifest.json").read_text())
    m["files"][rel] = {"bytes": path.stat().st_size, "sha256": sha256_file(path)}
    (scene / "manifest.json").write_text(json.dumps(m, indent=1))


@pytest.mark.parametrize("case", ["labels", "flow_photo", "ids_size", "exr_as_npz"])
def test_check_reads_ground_truth_content_behind_a_resigned_manifest(gt_scene, tmp_path, case):
    """`e4dgs check` with the manifest re-signed over a wrong file: 100 labels for a camera's events, an
    8-bit photo as a flow PNG, an id map of another size, depth bytes as a flow .npz: each named."""
    import shutil

    import cv2

    from scene_format.verify import verify_scene

    scene = tmp_path / "cubes"
    shutil.copytree(gt_scene, scene)
    assert verify_scene(scene) == []
    photo = cv2.imencode(".png", np.full((48, 64, 3), 128, np.uint8))[1].tobytes()
    small = cv2.imencode(".png", np.zeros((10, 10), np.uint16))[1].tobytes()
    buf = __import__("io").BytesIO()
    np.save(buf, np.zeros(100, np.uint8))
    rel, content, expected = {
        "labels": ("ground_truth/event_ids/cam0.npy", buf.getvalue(), "100 labels for"),
        "flow_photo": ("ground_truth/flow/cam0/00001.png", photo, "not a 16-bit 3-channel PNG"),
        "ids_size": ("ground_truth/ids/cam0/00001.png", small, "10x10 pixels, the scene's cameras"),
        "exr_as_npz": ("ground_truth/flow/cam0/00001.npz", (scene / "ground_truth/depth/cam0/00001.exr").read_bytes(),
                       "not a ground-truth flow file"),
    }[case]
    _resign_file(scene, rel, content)
    problems = verify_scene(scene)
    assert len(problems) == 1 and rel in problems[0] and expected in problems[0], problems


def test_check_reads_exported_event_files_behind_a_resigned_manifest(gt_scene, tmp_path):
    import shutil

    from datagen.exports import ensure_exports
    from scene_format.verify import verify_scene

    scene = tmp_path / "cubes"
    shutil.copytree(gt_scene, scene)
    assert ensure_exports(scene, ("aedat4", "txt"), log=lambda s: None) == ["aedat4", "txt"]
    assert verify_scene(scene) == []
    _resign_file(scene, "exports/txt/cam0.txt", b"hello, these are notes\n")
    _resign_file(scene, "exports/aedat4/cam1.aedat4", (scene / "exports/txt/cam1.txt").read_bytes())
    problems = verify_scene(scene)
    assert len(problems) == 2, problems
    assert "exports/txt/cam0.txt: not an E2VID event text file" in problems[1] or \
        "exports/txt/cam0.txt: not an E2VID event text file" in problems[0]
    assert any("exports/aedat4/cam1.aedat4: " in p and "not a recognised event file" in p for p in problems), problems
    _resign_file(scene, "exports/aedat4/cam1.aedat4", (scene / "events/cam1.h5").read_bytes())
    assert any("exports/aedat4/cam1.aedat4: holds h5, not the aedat4 events" in p for p in verify_scene(scene))


def test_check_fails_on_a_stray_file_in_the_generators_folders(gt_scene, tmp_path):
    """A file the manifest does not list inside exports/ (or events/, ground_truth/, ...) fails the
    check naming it; beside the data it is a note."""
    import shutil

    scene = tmp_path / "cubes"
    shutil.copytree(gt_scene, scene)
    (scene / "exports" / "txt").mkdir(parents=True)
    (scene / "exports" / "txt" / "cam0.txt").write_text("not events\n")
    (scene / "notes.md").write_text("mine\n")
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "check", str(scene)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 1 and "exports/txt/cam0.txt" in r.stdout and "generate the scene again" in r.stdout, r.stdout
    assert "note: 1 file(s) the manifest does not list" in r.stdout and "notes.md" in r.stdout
