import os
from pathlib import Path

import numpy as np
import pytest

# the test-only dataset presets (tiny_motion, tiny_pan) live in tests/fixtures/configs/datasets/: the
# config lookup searches E4DGS_CONFIG_PATH after the shipped folders, here and in every subprocess
os.environ["E4DGS_CONFIG_PATH"] = os.pathsep.join(
    [str(Path(__file__).resolve().parent / "fixtures" / "configs")] + [p for p in os.environ.get("E4DGS_CONFIG_PATH", "").split(os.pathsep) if p])

from simulator import SimulatorConfig

EPS = SimulatorConfig().log_eps


def frame_from_log(L) -> np.ndarray:
    """Linear float64 frame whose log(I + eps) equals L (up to float rounding)."""
    return np.exp(np.asarray(L, dtype=np.float64)) - EPS


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def generate_cubes(tmp_path_factory, preset: str):
    """The cubes scene of dataset preset `preset`, generated into a fresh temporary folder."""
    import subprocess
    import sys
    from pathlib import Path

    out = tmp_path_factory.mktemp(preset)
    root = Path(__file__).resolve().parent.parent
    r = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset", preset,
                        "--out", str(out), "--no-progress"], capture_output=True, text=True, cwd=root)
    assert r.returncode == 0, r.stderr
    return out / "cubes"


@pytest.fixture(scope="session")
def motion_scene(tmp_path_factory):
    """The `tiny_motion` preset's cubes scene (Blender + simulator, ~4 s): 2 cameras, 64x48, 61
    timestamps, 46 train / 16 test frames, blur levels mild and strong. Shared by the recon tests.

    On a machine without Blender (a GPU box running tests/recon/test_gsplat_cuda.py), set
    E4DGS_TEST_MOTION_SCENE to a copy of that scene generated elsewhere (`python -m datagen.generate
    --scene cubes --preset tiny_motion --out DIR`); it is copied, so the tests cannot alter it."""
    import os
    import shutil
    from pathlib import Path

    given = os.environ.get("E4DGS_TEST_MOTION_SCENE")
    if given:
        src = Path(given)
        if not (src / "manifest.json").is_file():
            pytest.exit(f"E4DGS_TEST_MOTION_SCENE={given}: expected a generated scene folder holding manifest.json")
        return Path(shutil.copytree(src, tmp_path_factory.mktemp("tiny_motion") / src.name))
    return generate_cubes(tmp_path_factory, "tiny_motion")


_EXIT_STATUS = None


def pytest_sessionfinish(session, exitstatus):
    global _EXIT_STATUS
    _EXIT_STATUS = int(exitstatus)


def pytest_unconfigure(config):
    """After the summary: leave at once when Ray was imported. Its gRPC client threads outlive
    ray.shutdown() and, on these machines, kept the finished pytest process waiting at interpreter
    exit (seen with 621 tests passed and the process still alive minutes later)."""
    import os
    import sys

    if "ray" in sys.modules and _EXIT_STATUS is not None:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_EXIT_STATUS)


def mount_tmpfs(folder, options: str) -> bool:
    """Mount a tmpfs with `options` (size=1m, ro, ...) on `folder`; False where this user cannot."""
    import subprocess

    return subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True).returncode == 0


def unmount(folder) -> None:
    import subprocess

    subprocess.run(["umount", str(folder)], check=True)


@pytest.fixture(scope="session")
def gt_scene(tmp_path_factory):
    """The tiny preset's cubes with every kind of ground truth (depth, flow, normals, ids) and a speed
    variant x4 beside it (data/cubes_x4; ~5 s)."""
    import subprocess
    import sys

    import yaml

    root = Path(__file__).resolve().parent.parent
    out = tmp_path_factory.mktemp("gt_scene")
    preset = yaml.safe_load((root / "configs" / "datasets" / "tiny.yaml").read_text())
    preset["overrides"]["ground_truth"] = ["depth", "flow", "normals", "ids"]
    preset["overrides"]["speeds"] = {"factors": [4], "exposure_ms": 0.3333, "max_px_per_frame": 10.0}
    (out / "preset.yaml").write_text(yaml.safe_dump(preset))
    r = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset", str(out / "preset.yaml"),
                        "--out", str(out / "data"), "--no-progress"], capture_output=True, text=True, cwd=root)
    assert r.returncode == 0, r.stderr
    return out / "data" / "cubes"
