"""Faults users meet: an output that would land on an input, a full disk under every writer (a real
tmpfs where the machine lets us mount one), and refusals that come before any work."""

import cv2
import numpy as np
import pytest

from e4dgs.cli import main
from eventio import formats
from eventio.events import EventStream, make_events
from eventio.h5io import write_events
from tests.conftest import mount_tmpfs, unmount


def stream(n: int, start_us: int = 0, seed: int = 0) -> EventStream:
    rng = np.random.default_rng(seed)
    t = start_us + np.sort(rng.integers(0, 1_000_000, n))
    return EventStream(make_events(t, rng.integers(0, 346, n), rng.integers(0, 260, n), rng.choice([-1, 1], n)), 346, 260)


def run(argv, capsys) -> tuple[int, str]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:
        rc = 1 if exc.code not in (0, None) else 0
        if isinstance(exc.code, str):
            print(exc.code, file=__import__("sys").stderr)
    err = capsys.readouterr().err
    return rc, err


@pytest.fixture
def frames(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for k in range(4):
        cv2.imwrite(str(folder / f"{k:03d}.png"), rng.integers(0, 255, (26, 34, 3), dtype=np.uint8))
    return folder


def test_simulate_never_writes_a_sibling_output_over_its_timestamps(frames, tmp_path, capsys):
    ts = tmp_path / "ts.txt"
    ts.write_text("0\n1000\n2000\n3000\n")
    rc, err = run(["simulate", frames, "--timestamps", ts, "--out", tmp_path / "ts.h5", "--format", "txt"], capsys)
    assert rc == 1 and "--format txt (written beside --out)" in err and "is also --timestamps" in err
    assert ts.read_text() == "0\n1000\n2000\n3000\n" and not (tmp_path / "ts.h5").exists()


@pytest.mark.parametrize("argv", [
    lambda d: ["import", d / "rec.h5", "--out", d / "rec.h5"],
    lambda d: ["export", d / "rec.h5", "--format", "h5", "--out", d / "rec.h5"],
    lambda d: ["draw-events", d / "rec.h5", "--out", d / "rec.h5"],
    lambda d: ["simulate", d / "frames", "--fps", "1000", "--out", d / "cfg.h5", "--format", "txt",
               "--config", d / "cfg.txt"],
    lambda d: ["e2vid", d / "rec.h5", "--out", d / "rec.h5"],
], ids=["import", "export", "view", "simulate-config", "e2vid"])
def test_an_output_on_an_input_is_refused_before_any_work(argv, frames, tmp_path, capsys):
    write_events(tmp_path / "rec.h5", stream(100))
    (tmp_path / "cfg.txt").write_text("contrast_threshold: 0.2\n")
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    rc, err = run(argv(tmp_path), capsys)
    assert rc == 1 and ("an input" in err or "input folder" in err or "is the" in err), err
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_simulate_refuses_an_existing_ros2_bag_before_writing_anything(frames, tmp_path, capsys):
    (tmp_path / "ev_rosbag2").mkdir()
    rc, err = run(["simulate", frames, "--fps", "1000", "--out", tmp_path / "ev.h5", "--format", "rosbag2"],
                  capsys)
    assert rc == 1 and "ev_rosbag2 exists" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ev_rosbag2", "frames"]


@pytest.fixture
def small_disk(tmp_path):
    """A 1 MiB tmpfs (root can mount one; elsewhere the tests skip)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if not mount_tmpfs(disk, "size=1m"):
        pytest.skip("cannot mount a tmpfs here")
    yield disk
    unmount(disk)


@pytest.mark.parametrize("fmt", formats.FORMATS)
def test_a_full_disk_under_every_export_names_the_file_and_leaves_nothing(fmt, small_disk, tmp_path, capsys):
    src = write_events(tmp_path / "big.h5", stream(300_000, start_us=1_700_000_000_000_000))
    out = small_disk / f"x{formats.SUFFIX[fmt]}"
    rc, err = run(["export", src, "--format", fmt, "--out", out], capsys)
    assert rc == 1 and f"{out}: No space left on device" in err, err
    assert len(err.strip().splitlines()) == 1, err
    assert list(small_disk.iterdir()) == []


def test_a_full_disk_under_import_simulate_and_view(frames, small_disk, tmp_path, capsys):
    src = write_events(tmp_path / "big.h5", stream(300_000))
    rc, err = run(["import", src, "--out", small_disk / "y.h5"], capsys)
    assert rc == 1 and f"{small_disk / 'y.h5'}: No space left on device" in err
    rc, err = run(["draw-events", src, "--out", small_disk / "v.mp4", "--window", "2ms", "--scale", "4"], capsys)
    assert rc == 1 and f"{small_disk / 'v.mp4'}: No space left on device" in err, err
    assert list(small_disk.iterdir()) == []
    big = tmp_path / "bigframes"
    big.mkdir()
    rng = np.random.default_rng(1)
    for k in range(30):
        cv2.imwrite(str(big / f"{k:03d}.png"), rng.integers(0, 255, (260, 346, 3), dtype=np.uint8))
    rc, err = run(["simulate", big, "--fps", "1000", "--out", small_disk / "s.h5"], capsys)
    assert rc == 1 and "No space left on device" in err and str(small_disk) in err, err


def test_a_premultiplied_rgba_exr_is_refused_like_an_rgba_png(tmp_path):
    """score used to drop alpha from EXR renders and score premultiplied colours (15.79 dB for renders
    worth 25.10); an opaque alpha is still fine."""
    import OpenEXR

    from benchmark.score import RenderError, read_render

    rgb = np.full((6, 8, 3), 0.5, np.float32)
    for alpha, ok in ((np.ones((6, 8), np.float32), True), (np.linspace(0, 1, 48, dtype=np.float32).reshape(6, 8), False)):
        chans = {c: np.ascontiguousarray(rgb[..., i] * alpha) for i, c in enumerate("RGB")}
        chans["A"] = alpha
        path = tmp_path / f"r{int(ok)}.exr"
        with OpenEXR.File({"type": OpenEXR.scanlineimage}, chans) as f:
            f.write(str(path))
        if ok:
            assert np.allclose(read_render(path, 8, 6, 3), 0.5)
        else:
            with pytest.raises(RenderError, match="has transparent pixels .* composite it over its background"):
                read_render(path, 8, 6, 3)


def test_a_scene_yaml_copied_under_a_new_name_says_what_to_add(tmp_path, capsys):
    """`name: my_cubes` without a source ended in a ModuleNotFoundError traceback inside the worker."""
    from datagen.config import SCENES_DIR

    text = (SCENES_DIR / "cubes.yaml").read_text().replace("name: cubes", "name: my_cubes")
    mine = tmp_path / "my_cubes.yaml"
    mine.write_text(text)
    rc, err = run(["dataset", "--preset", "tiny", "--scene-config", mine, "--out", tmp_path / "data"], capsys)
    assert rc == 1 and "'my_cubes' is not a built-in scene" in err and "source: {builtin: cubes}" in err
    assert "Traceback" not in err and not (tmp_path / "data").exists()
    (tmp_path / "gone.yaml").write_text("name: gone\nkind: object\nsource:\n  file: /nowhere/gone.blend\n")
    rc, err = run(["dataset", "--preset", "tiny", "--scene-config", tmp_path / "gone.yaml", "--out", tmp_path / "data"],
                  capsys)
    assert rc == 1 and "source.file: /nowhere/gone.blend: no such file" in err and not (tmp_path / "data").exists()
    mine.write_text(text + "source:\n  builtin: nope\n")
    rc, err = run(["dataset", "--preset", "tiny", "--scene-config", mine, "--out", tmp_path / "data"], capsys)
    assert rc == 1 and "source.builtin: 'nope' is not a built-in scene" in err


def test_a_renamed_variant_of_a_built_in_scene_builds_from_its_builder(tmp_path, capsys):

    from datagen.config import SCENES_DIR
    from scene_format.reader import SceneDataset

    mine = tmp_path / "my_cubes.yaml"
    mine.write_text((SCENES_DIR / "cubes.yaml").read_text().replace("name: cubes", "name: my_cubes")
                    + "source:\n  builtin: cubes\n")
    assert main(["dataset", "--preset", "tiny", "--scene-config", str(mine), "--out", str(tmp_path / "data")]) == 0
    ds = SceneDataset(tmp_path / "data" / "my_cubes")
    assert ds.config.name == "my_cubes" and ds.config.source.builtin == "cubes" and ds.n_cameras > 0


def test_sizes_beyond_their_meaning_or_the_machine_are_refused_before_a_file_is_written(motion_scene, tmp_path,
                                                                                        capsys, monkeypatch):
    """fourier=1000000 allocated 24 GB and was OOM-killed with no message, leaving config.yaml and run.json."""
    import recon
    from recon import memory

    out = tmp_path / "run"
    rc, err = run(["train", motion_scene, "--out", out, "--set", "train.deform_field.fourier=1000000"], capsys)
    assert rc == 1 and "fourier: expected 0 .. 64" in err and not out.exists(), err
    rc, err = run(["train", motion_scene, "--out", out, "--set", "train.iterations=1000000000000"], capsys)
    assert rc == 1 and "iterations: expected 1 .. 1e+07" in err and not out.exists(), err
    # within every range, but more than this machine has: the estimate names the field to lower
    big = {"train.init.n_points_object": 10_000_000, "train.densify.max_gaussians": 20_000_000}
    need, field = memory.training_bytes(recon.resolve_config("d3dgs", overrides=big).train, "object")
    assert field == "train.densify.max_gaussians" and need == 20_000_000 * (16 * (11 + 48) + 512)
    monkeypatch.setattr("common.machine.available_memory_bytes", lambda: need - 1)
    with pytest.raises(ValueError, match=r"train.densify.max_gaussians: the run would hold up to 20,000,000 Gaussians"):
        recon.fit(motion_scene, "d3dgs", overrides=big, out_dir=out, progress=False)
    assert not out.exists()
    traj = {"train.deform_field.kind": "trajectory", "train.deform_field.fourier": 64, "train.deform_field.degree": 16}
    assert memory.training_bytes(recon.resolve_config("d3dgs", overrides=traj).train, "object")[1] == \
        "train.deform_field.fourier / degree"


def test_a_yaml_alias_bomb_and_a_binary_preset_are_refused_at_once(tmp_path, capsys):
    """A ~350-byte YAML whose aliases expand to 9^9 values hung every command that read it."""
    import time

    parts = ['&a ["x","x","x","x","x","x","x","x","x"]'] + \
        [f'&{k} [' + ",".join([f"*{p}"] * 9) + ']' for p, k in zip("abcdefgh", "bcdefghi")]
    bomb = "[" + ", ".join(parts) + "]"
    files = {"preset": ("scenes: [cubes]\noverrides:\n  description: " + bomb + "\n"),
             "scene": "name: cubes\nkind: object\ndescription: " + bomb + "\n",
             "bench": "description: " + bomb + "\n"}
    for name, text in files.items():
        (tmp_path / f"{name}.yaml").write_text(text)
    assert all(len(t) < 600 for t in files.values())
    for argv in (["dataset", "--preset", tmp_path / "preset.yaml", "--out", tmp_path / "d"],
                 ["dataset", "--preset", "tiny", "--scene-config", tmp_path / "scene.yaml", "--out", tmp_path / "d"],
                 ["bench", "--preset", tmp_path / "bench.yaml", "--out", tmp_path / "r"]):
        t0 = time.perf_counter()
        rc, err = run(argv, capsys)
        assert rc == 1 and "aliases (*name) expand to" in err and time.perf_counter() - t0 < 10, err
        assert err.count(".yaml: ") == 1, err                 # the file named once
    binary = tmp_path / "binary.yaml"
    binary.write_bytes(bytes(range(256)) * 4)
    rc, err = run(["dataset", "--preset", binary, "--out", tmp_path / "d"], capsys)
    assert rc == 1 and f"{binary}: not a text file" in err
    assert not (tmp_path / "d").exists() and not (tmp_path / "r").exists()


def test_a_model_is_not_rendered_on_another_scenes_test_views(motion_scene, tmp_path, capsys):
    import shutil

    run_dir = tmp_path / "run"
    assert main(["train", str(motion_scene), "--out", str(run_dir), "--set", "train.iterations=2",
                 "--set", "train.init.n_points_object=200"]) == 0
    other = tmp_path / "other"
    shutil.copytree(motion_scene, other)
    text = (other / "scene.yaml").read_text()
    (other / "scene.yaml").write_text(text.replace(f"name: {motion_scene.name}", "name: other", 1))
    capsys.readouterr()
    rc, err = run(["render", run_dir, "--test-views", other, "--out", tmp_path / "renders"], capsys)
    assert rc == 1 and f"trained on scene '{motion_scene.name}', these are the views of 'other'" in err, err
    assert not (tmp_path / "renders").exists()


def test_a_full_disk_under_train_names_the_file_torch_could_not_write(motion_scene, small_disk, capsys):
    """torch.save on a full disk said '[enforce fail at inline_container.cc:672] . unexpected pos ...'."""
    rc, err = run(["train", motion_scene, "--out", small_disk / "run", "--set", "train.iterations=3",
                   "--set", "train.init.n_points_object=20000"], capsys)
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if "error" in ln]
    assert rc == 1 and len(lines) == 1 and f"{small_disk / 'run'}" in lines[0] and "No space left on device" in lines[0], err
    assert "enforce fail" not in err and list(small_disk.iterdir()) == []


def test_masks_on_a_scene_whose_source_file_is_gone_says_so(motion_scene, tmp_path, capsys):
    import shutil

    scene = tmp_path / "scene"
    shutil.copytree(motion_scene, scene)
    (scene / "scene.yaml").write_text((scene / "scene.yaml").read_text() + "source:\n  file: /nowhere/walker.blend\n"
                                      if "source:" not in (scene / "scene.yaml").read_text() else
                                      (scene / "scene.yaml").read_text().replace("file: ''", "file: /nowhere/walker.blend"))
    shutil.rmtree(scene / "dynamic", ignore_errors=True)
    rc, err = run(["masks", scene], capsys)
    assert rc == 1 and "its source file /nowhere/walker.blend is gone" in err, err
