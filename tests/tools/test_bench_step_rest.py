"""tools.bench_step_rest: every part is timed against the form it replaced, and bad sizes are refused."""
import re


def test_step_rest_table_has_every_part_with_both_timings(motion_scene, capsys):
    from tools.bench_step_rest import main

    assert main(["--scene", str(motion_scene), "--gaussians", "64", "--reps", "1"]) == 0
    out = capsys.readouterr().out
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in out.splitlines()
            if line.startswith("| ") and not line.startswith("| part")]
    parts = [r[0] for r in rows]
    assert parts.count("D-SSIM, RGB") == parts.count("D-SSIM, gray") == 3      # full, 1/2, 1/4
    assert {"trajectory offsets", "Adam step", "event window"} <= set(parts)
    for r in rows:
        now, before = float(r[2]), float(r[3])
        assert now > 0 and before > 0 and re.fullmatch(r"\d+\.\dx", r[4])
    assert "CPU:" in out


def test_step_rest_refuses_empty_sizes(capsys):
    from tools.bench_step_rest import main

    import pytest

    with pytest.raises(SystemExit) as exc:
        main(["--gaussians", "0"])
    assert exc.value.code == 2 and "argument --gaussians: expected an integer in 1 .." in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:             # a scene named that is not there: before any timing
        main(["--scene", "/nowhere/scene"])
    assert exc.value.code == 2 and "--scene /nowhere/scene: no generated scene here" in capsys.readouterr().err
