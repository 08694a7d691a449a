"""The public Python API in the sweep: every reading function of `eventio`, `scene_format`, `recon`
and `common.flow` given a missing file, an empty one, a truncated one and files of another kind
raises the documented kind of error (a ValueError subclass: DatasetError, EventFileError,
FormatError, ConfigError; or an OSError for a missing file) with one message naming the path, never
a TypeError, KeyError, AttributeError or IndexError; and the index arguments of the reader and of a
trained model refuse wrong types and out-of-range values the same way.

The readers are found from the modules (their public functions whose first parameter is a path), so
a new reader is swept without being listed."""
import inspect
import shutil
from pathlib import Path

import numpy as np
import pytest

import common.flow
import eventio
import eventio.export
import eventio.formats
import eventio.h5io
import eventio.vendor_formats
import recon
import scene_format.cameras
import scene_format.config
import scene_format.reader

MODULES = (eventio, eventio.formats, eventio.h5io, eventio.export, eventio.vendor_formats, scene_format.cameras,
           scene_format.config, scene_format.reader, recon, common.flow)
PATH_NAMES = {"path", "scene_dir", "model_path", "run_dir", "folder"}
OUTPUTS = ("write", "save", "export_", "encode", "remove")      # writers: swept by the writer properties


def readers() -> list[tuple[str, object]]:
    found = {}
    for mod in MODULES:
        for name, fn in vars(mod).items():
            if name.startswith("_") or not (inspect.isfunction(fn) or inspect.isclass(fn)) or name.startswith(OUTPUTS):
                continue
            if not getattr(fn, "__module__", "").startswith(("eventio", "scene_format", "recon", "common.flow")):
                continue
            try:
                params = list(inspect.signature(fn).parameters.values())
            except (TypeError, ValueError):
                continue
            if params and params[0].name in PATH_NAMES and all(
                    p.default is not inspect.Parameter.empty or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
                    for p in params[1:] if p.name not in ("t0_us", "t1_us")):
                found[f"{fn.__module__}.{name}"] = fn
    return sorted(found.items())


READERS = readers()
EXTRA = {"eventio.h5io.read_window": (0, 1000)}


def bad_files(folder: Path, good_h5: Path) -> dict[str, Path]:
    out = {"missing": folder / "missing.h5", "empty": folder / "empty.h5", "truncated": folder / "truncated.h5",
           "png": folder / "picture.png", "text": folder / "notes.txt", "folder": folder / "a_folder"}
    out["empty"].write_bytes(b"")
    out["truncated"].write_bytes(good_h5.read_bytes()[:300])
    import cv2

    cv2.imwrite(str(out["png"]), np.zeros((4, 4, 3), np.uint8))
    out["text"].write_text("hello\nthese are notes\n")
    out["folder"].mkdir()
    return out


@pytest.fixture(scope="module")
def good_h5(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("good") / "e.h5"
    eventio.write_events(path, eventio.EventStream(eventio.make_events([1, 5, 9], [0, 1, 2], [0, 1, 1], [1, -1, 1]), 4, 4))
    return path


def test_the_sweep_finds_the_readers():
    names = {n.rsplit(".", 1)[1] for n, _ in READERS}
    assert {"read_recording", "read_events", "read_window", "detect_format", "read_flow", "load", "fit",
            "SceneDataset", "read_scene_config", "load_cameras"} <= names, names


@pytest.mark.parametrize("name,fn", READERS, ids=[n for n, _ in READERS])
@pytest.mark.parametrize("kind", ["missing", "empty", "truncated", "png", "text", "folder"])
def test_every_reader_refuses_a_bad_file_naming_it(name, fn, kind, good_h5, tmp_path):
    if name.endswith("detect_format") and kind in ("truncated", "text"):
        pytest.skip("detect_format reads a signature and a name, not the content: an .h5 head or a .txt is that format")
    path = bad_files(tmp_path, good_h5)[kind]
    with pytest.raises(Exception) as info:
        fn(path, *EXTRA.get(name, ()))
    exc = info.value
    assert isinstance(exc, (ValueError, OSError)) and not isinstance(exc, (KeyError, IndexError)), \
        f"{name}({kind}): {type(exc).__name__}: {exc}"
    assert path.name in str(exc) or str(path) in str(exc), f"{name}({kind}): the message does not name the file: {exc}"
    assert len(str(exc).splitlines()) <= 2, f"{name}({kind}): {exc}"


# -- index arguments ------------------------------------------------------------------------------------
BAD_INDICES = [True, -1, 99, 1.5, "0", None]


@pytest.mark.parametrize("value", BAD_INDICES, ids=repr)
@pytest.mark.parametrize("call", ["ground_truth_camera", "ground_truth_frame", "event_file", "pose"])
def test_the_readers_indices_refuse_wrong_types_and_ranges(gt_scene, call, value):
    ds = scene_format.reader.SceneDataset(gt_scene)
    fn = {"ground_truth_camera": lambda v: ds.ground_truth(v, 0), "ground_truth_frame": lambda v: ds.ground_truth(0, v),
          "event_file": lambda v: ds.event_file(v), "pose": lambda v: ds.pose(v, 0)}[call]
    with pytest.raises(scene_format.reader.DatasetError, match="expected an integer"):
        fn(value)


@pytest.fixture(scope="module")
def trained(motion_scene, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    tiny = {"train.iterations": 2, "train.scale_schedule": False, "train.densify.enabled": False,
            "train.init.n_points_object": 100, "train.snapshots": [1.0]}
    return recon.fit(motion_scene, "d3dgs", overrides=tiny, out_dir=out / "run", progress=False).model


@pytest.mark.parametrize("camera,t,words", [(99, 0.5, "camera index 99"), (True, 0.5, "camera"),
                                            (-1, 0.5, "camera index -1"), (0, 1.5, "got 1.5"),
                                            (0, float("nan"), "got nan"), (0, "0.5", "t")],
                         ids=["camera-99", "camera-bool", "camera-neg", "t-over", "t-nan", "t-text"])
def test_a_models_render_refuses_a_bad_camera_or_time(trained, camera, t, words):
    with pytest.raises(ValueError, match=words):
        trained.render(camera, t)


def test_copies_of_real_folders_are_not_swept_by_accident(tmp_path, good_h5):
    """The sweep's files are what they say (a guard on the fixture itself)."""
    files = bad_files(tmp_path, good_h5)
    assert not files["missing"].exists() and files["empty"].stat().st_size == 0 and files["folder"].is_dir()
    shutil.rmtree(files["folder"])
