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
