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
