"""tools.dataset_summary on a folder without finished scenes: an error and a non-zero exit, not a
header-only table."""
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_a_folder_without_scenes_is_an_error(tmp_path):
    r = subprocess.run([sys.executable, "-m", "tools.dataset_summary", str(tmp_path)], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 1 and "no finished scene folder" in r.stderr and "| scene |" not in r.stdout, r


def test_check_of_a_manifest_that_is_not_a_mapping_says_so(tmp_path):
    scene = tmp_path / "s"
    (scene / "events").mkdir(parents=True)
    (scene / "manifest.json").write_text("[]")
    r = subprocess.run([sys.executable, "-m", "e4dgs.cli", "check", str(scene)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 1 and "not a readable manifest" in r.stdout and "internal error" not in r.stderr, r
