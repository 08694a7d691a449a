"""tools.ground_truth_summary: the table and the picture of a scene with ground truth."""
import cv2

from tools.ground_truth_summary import main


def test_the_table_names_the_scene_and_its_warp_check_and_the_picture_has_four_tiles(gt_scene, tmp_path, capsys):
    assert main([str(gt_scene.parent), "--picture", str(tmp_path / "p.png"), "--frame", "1"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("| cubes |"))
    assert "depth, flow, normals, ids" in row and "(" in row.split("|")[7]
    img = cv2.imread(str(tmp_path / "p.png"))
    assert img.shape == (48 + 18, 4 * 64, 3)


def test_a_camera_or_frame_the_scene_lacks_is_named_in_one_line(gt_scene, tmp_path, capsys):
    from tools.tool_cli import run_tool

    for args, words in ((["--camera", "7"], "--camera 7: "), (["--frame", "4"], "--frame 4: expected a kept frame with a next one")):
        assert run_tool(main, [str(gt_scene.parent), "--picture", str(tmp_path / "p.png"), "--scene", "cubes", *args]) == 1
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err and not (tmp_path / "p.png").exists()


def test_every_tool_passes_its_exit_status_on(tmp_path):
    """A tool that prints an error exits non-zero: every `run_tool(main)` result goes to sys.exit."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "tools"
    for path in sorted(root.glob("*.py")):
        text = path.read_text()
        bare = [line for line in text.splitlines() if re.fullmatch(r"\s*run_tool\(main.*\)\s*", line)]
        assert not bare, f"{path.name}: {bare[0].strip()} drops the exit status (use sys.exit(run_tool(main)))"


def test_the_summary_exits_1_on_each_error_it_prints(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    (tmp_path / "empty").mkdir()
    for args in (["--scene", "bogus"], []):
        r = subprocess.run([sys.executable, "-m", "tools.ground_truth_summary", str(tmp_path / "empty"), *args],
                           capture_output=True, text=True, cwd=root)
        assert r.returncode == 1 and "error:" in r.stderr and r.stdout == "", (args, r.stderr)
