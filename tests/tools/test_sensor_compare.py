"""tools.sensor_compare: two results folders' main cells side by side with Welch's test."""
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _rows(folder: Path, values: dict) -> None:
    folder.mkdir()
    lines = [json.dumps({"study": "main", "cell": cell, "scene": "hinge", "psnr": v, "inputs": ["events"]})
             for cell, vs in values.items() for v in vs]
    (folder / "results.jsonl").write_text("\n".join(lines) + "\n")


def test_a_clear_difference_and_a_tie(tmp_path):
    _rows(tmp_path / "a", {"e4dgs": [32.1, 32.2, 32.15], "e2vid_d3dgs": [27.4, 27.5, 27.45]})
    _rows(tmp_path / "b", {"e4dgs": [29.3, 29.4, 29.35], "e2vid_d3dgs": [27.5, 27.3, 27.6]})
    r = subprocess.run([sys.executable, "-m", "tools.sensor_compare", str(tmp_path / "a"), str(tmp_path / "b")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    rows = {ln.split(" | ")[0].strip("| "): ln for ln in r.stdout.splitlines() if ln.startswith("| e")}
    assert "32.15 ± 0.05 | 29.35 ± 0.05 | -2.80 (p < 0.05)" in rows["e4dgs"]
    assert "(tie)" in rows["e2vid_d3dgs"]


def test_an_empty_folder_is_an_error(tmp_path):
    (tmp_path / "a").mkdir()
    r = subprocess.run([sys.executable, "-m", "tools.sensor_compare", str(tmp_path / "a"), str(tmp_path / "a")],
                       capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 1 and "no such results file" in r.stderr
