"""tools.plateau: each cell's PSNR at half its steps, at the end and the gain between, mean over seeds."""
import json

import pytest

from tools.plateau import half_and_end, main, plateau_table


def row(scene, cell, psnrs, seed=None, n=1000):
    its = [n // 10, n // 4, n // 2, n]
    return {"key": f"main/{scene}/{cell}" + (f"/seed{seed}" if seed else ""), "study": "main", "scene": scene,
            "cell": cell, "seed": seed, "iterations": n, "train_elapsed_s": 100.0, "label": cell.upper(),
            "psnr": psnrs[-1], "ssim": 0.9,
            "snapshots": [{"iteration": i, "psnr": p, "wall_s": 1.0} for i, p in zip(its, psnrs)]}


def test_the_gain_is_the_second_half_of_the_curve_averaged_over_seeds():
    rows = [row("hinge", "e4dgs", [20, 25, 30, 32]), row("hinge", "e4dgs", [20, 25, 31, 32], seed=1),
            row("hinge", "d3dgs", [20, 27, 28, 28])]
    assert half_and_end(rows[0]) == (30, 32)
    text = plateau_table(rows)
    assert "| hinge | E4DGS | 2 | 1,000 | 100 | 30.50 | 32.00 | +1.50 |" in text
    assert "| hinge | D3DGS | 1 | 1,000 | 100 | 28.00 | 28.00 | +0.00 |" in text


def test_rows_without_curves_and_other_studies_are_left_out(tmp_path, capsys):
    rows = [{**row("hinge", "e4dgs", [1, 2, 3, 4]), "study": "blur"}, {**row("lego", "e4dgs", [1, 2, 3, 4]), "snapshots": []}]
    path = tmp_path / "results.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    with pytest.raises(SystemExit, match="no main-study row has its learning curve"):
        main([str(path)])
