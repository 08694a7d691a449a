"""tools.seed_spread: per-scene seed spreads and the pooled figure a preset's seed_spread holds."""
import math

import pytest

from tools.seed_spread import main, spread_table


def _rows():
    rows = []
    for scene, psnrs in (("a", (30.0, 31.0, 32.0)), ("b", (20.0, 22.0, 21.0))):
        for seed, p in enumerate(psnrs):
            rows.append({"key": f"main/{scene}/e4dgs" + (f"/seed{seed}" if seed else ""), "study": "main",
                         "scene": scene, "cell": "e4dgs", "seed": seed or None, "psnr": p, "ssim": 0.5 + seed / 100,
                         "lpips": 0.2, "label": "E-4DGS"})
    return rows + [{"key": "main/a/d3dgs", "study": "main", "scene": "a", "cell": "d3dgs", "psnr": 25.0, "ssim": 0.4}]


def test_the_table_gives_each_scenes_seeds_and_the_pooled_sd():
    text, pooled = spread_table(_rows())
    assert "| E-4DGS | a | 3 | 30.00 / 31.00 / 32.00 | 31.00 ± 1.00 |" in text
    assert "| E-4DGS | b | 3 | 20.00 / 22.00 / 21.00 | 21.00 ± 1.00 |" in text
    assert pooled["e4dgs"]["psnr"] == pytest.approx(1.0) and pooled["e4dgs"]["lpips"] == pytest.approx(0.0, abs=1e-12)
    assert pooled["e4dgs"]["ssim"] == pytest.approx(0.01) and "d3dgs" not in pooled and math.isfinite(pooled["e4dgs"]["ssim"])


def test_a_file_without_seeds_is_one_line(tmp_path, capsys):
    import json

    path = tmp_path / "results.jsonl"
    path.write_text(json.dumps(_rows()[-1]) + "\n")
    with pytest.raises(SystemExit, match="no main cell has rows at two seeds or more"):
        main([str(path)])
