"""The speed study: its jobs from a preset, the crossing speed solved by hand, and its tables and plot
built from results rows."""
import json
import math

import pytest

from bench_cells import LABELS, MAIN_CELLS, described
from benchmark.config import BenchConfig, CellSpec
from benchmark.grid import jobs
from benchmark.report import write_report
from benchmark.speed_report import crossing_speed, speed_tables
from common.config import ConfigError, build_config

CELLS = {c: CellSpec({"d3dgs_sharp": "d3dgs", "d3dgs_blur": "d3dgs", "deblur_d3dgs": "deblur_d3dgs",
                      "e2vid_d3dgs": "e2vid_d3dgs", "e4dgs": "e4dgs", "e4dgs_rgb": "e4dgs_rgb"}[c], label=LABELS[c])
         for c in MAIN_CELLS}


def _cfg(**extra) -> BenchConfig:
    cells = {**CELLS, "d3dgs_blur": CellSpec("d3dgs", LABELS["d3dgs_blur"], speed="mild"),
             "e4dgs": CellSpec("e4dgs", LABELS["e4dgs"], speed="mild"),
             "e4dgs_rgb": CellSpec("e4dgs_rgb", LABELS["e4dgs_rgb"], speed="mild")}
    raw = {"scenes": ["g", "h"], "cells": cells, "speed_levels": {"mild": 6.0, "medium": 8.0, "strong": 20.0},
           "blur": {"scene": "h", "cells": ["d3dgs_blur", "e4dgs"]},
           "speed": {"scenes": ["g"], "speeds": [1, 6, 20], "cells": ["d3dgs_blur", "e4dgs"]}, **extra}
    return build_config(BenchConfig, raw)


def test_cells_at_a_speed_level_train_on_that_variant_and_its_shutter_frames():
    by = {j.key: j for j in jobs(_cfg())}
    main = by["main/g/d3dgs_blur"]
    assert main.speed == 6.0 and main.data_scene == "g_x6" and main.overrides == {"frames": "shutter"}
    assert by["main/g/e4dgs_rgb"].overrides == {"rgb_frames": "shutter"}       # its own blur-level field
    assert by["main/g/e4dgs"].data_scene == "g_x6" and by["main/g/e4dgs"].overrides == {}
    assert by["main/g/d3dgs_sharp"].speed is None and by["main/g/d3dgs_sharp"].data_scene == "g"
    # the blur study's levels are speeds: events-only cells are trained at each level too
    assert by["blur/h/e4dgs/strong"].data_scene == "h_x20" and by["blur/h/d3dgs_blur/medium"].data_scene == "h_x8"
    # the speed study's point at the mild speed is the main cell's training folder: trained once
    assert by["speed/g/d3dgs_blur/x6"].folder == main.folder and by["speed/g/e4dgs/x6"].folder == by["main/g/e4dgs"].folder
    assert by["speed/g/d3dgs_blur/x1"].folder != main.folder and by["speed/g/d3dgs_blur/x1"].data_scene == "g_x1"
    assert sum(j.study == "speed" for j in jobs(_cfg())) == 6 + 1      # and the sharp reference
    assert by["speed/g/d3dgs_sharp/sharp"].folder == by["main/g/d3dgs_sharp"].folder


def test_speed_settings_are_checked_when_loaded():
    with pytest.raises(ConfigError, match=r"cells.d3dgs_blur.speed: 'fast' is not one of speed_levels"):
        build_config(BenchConfig, {"scenes": ["g"], "cells": {**CELLS, "d3dgs_blur": CellSpec("d3dgs", speed="fast")}})
    with pytest.raises(ConfigError, match=r"speed.speeds: expected distinct speed factors >= 1"):
        _cfg(speed={"scenes": ["g"], "speeds": [0.5, 2]})
    with pytest.raises(ConfigError, match=r"blur.levels: 'medium' is not one of speed_levels"):
        _cfg(speed_levels={"mild": 6.0, "strong": 20.0})


def test_realistic_sensor_jobs_train_on_the_other_dataset():
    cfg = _cfg(speed={"scenes": ["h", "g"], "speeds": [1, 6], "cells": ["d3dgs_blur"], "sensor_dataset": "quick_dvs",
                      "sensor_scene": "g", "sensor_cells": ["e4dgs"]})
    sensor = [j for j in jobs(cfg) if j.dataset]
    assert [j.key for j in sensor] == ["speed/quick_dvs/g/e4dgs/x1", "speed/quick_dvs/g/e4dgs/x6"]
    with pytest.raises(ConfigError, match="speed.sensor_scene: 'x' is not one of speed.scenes"):
        _cfg(speed={"scenes": ["g"], "speeds": [1], "sensor_dataset": "d", "sensor_scene": "x"})
    assert sensor[1].folder.startswith("quick_dvs/g_x6/") and sensor[1].config_hash() != \
        next(j for j in jobs(cfg) if j.key == "main/g/e4dgs").config_hash()


def test_crossing_speed_is_interpolated_in_log_speed():
    # behind by 0.5 at x2, ahead by 0.5 at x4: the difference is zero half-way in log speed, at 2 * sqrt(2)
    s, how = crossing_speed([1, 2, 4, 8], [-1.0, -0.5, 0.5, 1.0])
    assert how == "crosses" and s == pytest.approx(2 * math.sqrt(2))
    assert crossing_speed([1, 2, 4], [0.1, 0.2, 0.3]) == (1, "ahead at every speed")
    assert crossing_speed([1, 2, 4], [-0.1, 0.2, -0.3]) == (None, "never ahead")
    s, how = crossing_speed([1, 2, 4, 8], [0.5, -0.5, -1.0, 3.0])     # ahead, behind, then ahead for good
    assert how == "crosses" and s == pytest.approx(4 * 2 ** (1 / 4))
    assert crossing_speed([1, 2], [None, None]) == (None, "no data")
    assert crossing_speed([1, 2, 4], [-0.5, -0.2, None]) == (None, "never ahead")   # no row at x4


def _row(study, scene, cell, psnr, speed=None, floor=18.0, variant=""):
    return described({"key": f"{study}/{scene}/{cell}/{variant}", "study": study, "scene": scene, "cell": cell, "variant": variant,
            "seed": None, "speed": speed, "dataset": "", "psnr": psnr, "psnr_luma": psnr + 1.0, "ssim": 0.8, "lpips": 0.3,
            "floor_psnr": floor, "floor_psnr_luma": floor + 1.0, "wall_s": 100.0, "iterations": 10, "n_gaussians": 5,
            "snapshots": [], "data": {"speed": speed or 1.0, "events_per_s_per_camera": 5e7 * (speed or 1),
                                      "blur_median_px": 3.0 * (speed or 1), "blur_p90_px": 5.0 * (speed or 1),
                                      "blur_psnr_db": 33.0 - (speed or 1)}})


def test_speed_tables_and_plot_from_rows(tmp_path):
    rows = [_row("main", "g", c, 20.0) for c in MAIN_CELLS]
    rows[0]["psnr"] = 21.0                                      # the sharp reference line
    for s, rgb, ev in ((1, 20.5, 19.0), (2, 20.0, 19.5), (4, 18.0, 19.2), (8, 16.0, 18.5)):
        rows += [_row("speed", "g", "d3dgs_blur", rgb, s, variant=f"x{s}"),
                 _row("speed", "g", "e4dgs", ev, s, floor=18.5 if s < 8 else 18.0, variant=f"x{s}")]
    (tmp_path / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    write_report(rows, tmp_path, "# t")
    md = (tmp_path / "speed.md").read_text()
    assert md == speed_tables(rows) and (tmp_path / "speed.png").stat().st_size > 1000
    assert "x4: 12 / 20 px, 29.0 dB, 200 Mev/s" in md
    ref = next(l for l in md.splitlines() if l.startswith(f"| {LABELS['d3dgs_sharp']} (reference) |"))
    assert ref.count("21.00") == 4
    e4 = next(l for l in md.splitlines() if l.startswith(f"| {LABELS['e4dgs']} |"))
    assert e4 == f"| {LABELS['e4dgs']} | 19.00 (18.50) | 19.50 (18.50) | 19.20 (18.50) | 18.50 (18.00) |"
    # behind by 0.5 at x2, ahead by 1.2 at x4: crosses at 2 * 2^(0.5 / 1.7); at x4 only 0.7 dB above its floor
    s_x = 2 * 2 ** (0.5 / 1.7)
    assert f"E-4DGS (events): overtakes it at x{s_x:.3g}; at x4 it is 0.70 dB above its floor (rests on the floor)." \
        .replace("E-4DGS (events)", LABELS["e4dgs"]) in md
    assert md.count("overtakes it at") == 2                       # paper protocol and luma (same differences)
    rows.append(_row("speed", "g", "d3dgs_blur", 30.0, 16, variant="x16"))   # a speed with no event run, RGB far ahead
    rows += [_row("speed", "g", "e2vid_d3dgs", 10.0, s, variant=f"x{s}") for s in (1, 2)]
    rows.append({"key": "speed/g/e4dgs/x16", "study": "speed", "scene": "g", "cell": "e4dgs", "speed": 16.0,
                 "dataset": "", "status": "failed", "error": "ValueError: no events"})
    md = speed_tables(rows)
    assert f"- failed: {LABELS['e4dgs']} at x16: ValueError: no events" in md
    rows.append({**_row("speed", "g", "e4dgs", 17.0, 8, floor=16.5, variant="x8"), "dataset": "dvs"})
    dvs = speed_tables(rows).split("sensor of dataset `dvs`")[1]
    # the same frames: the scene's blurred-RGB run is the other sensor's reference (16.0 at x8: 1 dB behind it)
    assert f"| {LABELS['d3dgs_blur']} |" in dvs and f"{LABELS['e4dgs']}: ahead at every speed of the sweep; at x8 " \
           f"it is 0.50 dB above its floor (rests on the floor)." in dvs
    e4 = next(l for l in md.splitlines() if l.startswith(f"| {LABELS['e4dgs']} |"))
    assert e4.endswith("| failed |")
    assert f"- {LABELS['e2vid_d3dgs']}: does not overtake {LABELS['d3dgs_blur']} within the sweep (up to x2, where it " \
           f"is -10.00 dB)." in md



def test_leaderboard_puts_every_score_next_to_its_floor_and_names_the_speeds(tmp_path):
    rows = [_row("main", "g", c, 20.0 + k, speed=6.0 if c != "d3dgs_sharp" else None, floor=10.0 + k)
            for k, c in enumerate(MAIN_CELLS)]
    write_report(rows, tmp_path, "# t")
    md = (tmp_path / "leaderboard.md").read_text()
    floors = md.split("### Above the untrained floor")[1]
    e4 = next(l for l in floors.splitlines() if l.startswith(f"| {LABELS['e4dgs']} |"))
    assert e4 == f"| {LABELS['e4dgs']} | 24.00 (14.00) | 25.00 (15.00) |"
    assert f"{LABELS['d3dgs_blur']} at x6" in md and f"{LABELS['d3dgs_sharp']} at" not in md


def test_level_speeds_are_interpolated_in_log_speed_and_out_of_reach_is_said():
    from tools.calibrate import PAPER_GARAGE_COST_DB, costs_from_rows, level_speed

    costs = [(1, -0.1), (16, 0.0), (32, 0.5), (64, 2.5)]
    # 1.5 dB is half-way from 0.5 (x32) to 2.5 (x64): x32 * 2^0.5
    assert level_speed(costs, 1.5) == (pytest.approx(32 * math.sqrt(2)), "interpolated")
    assert level_speed(costs, 2.5) == (64, "measured")
    assert level_speed(costs, 3.0) == (None, "out of reach")
    assert PAPER_GARAGE_COST_DB["mild"] == pytest.approx(1.31) and PAPER_GARAGE_COST_DB["strong"] == pytest.approx(3.38)
    rows = [_row("main", "g", "d3dgs_sharp", 20.0), _row("speed", "g", "d3dgs_blur", 19.5, 4),
            _row("speed", "g", "d3dgs_blur", 20.5, 1), {**_row("speed", "g", "d3dgs_blur", 1.0, 8), "dataset": "other"}]
    ref, got = costs_from_rows(rows, "g")
    assert ref == 20.0 and [(s, c) for s, c, _ in got] == [(1.0, -0.5), (4.0, 0.5)]
    with pytest.raises(ValueError, match="no D3DGS \\(sharp RGB\\) row for scene 'h'"):
        costs_from_rows(rows, "h")


def test_speed_study_end_to_end_on_the_tiny_scene(tmp_path):
    """Speed variants of the tiny scene, a preset whose blurred cells train at a speed level and a
    speed study over two speeds: every row carries its floor and its data; the study's own runs skip
    LPIPS; the tables come out."""
    import subprocess
    import sys
    from pathlib import Path

    from benchmark.runner import read_results, run_bench

    root = Path(__file__).resolve().parents[2]
    preset = tmp_path / "tiny_speed.yaml"
    preset.write_text((root / "tests" / "fixtures" / "configs" / "datasets" / "tiny_motion.yaml").read_text()
                      + "  speeds: {factors: [1, 3], exposure_ms: 1.0, max_px_per_frame: 10.0}\n")
    data = tmp_path / "data"
    r = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset", str(preset),
                        "--out", str(data), "--no-progress"], capture_output=True, text=True, cwd=root)
    assert r.returncode == 0, r.stderr
    tiny = {"train.iterations": 8, "train.scale_schedule": False, "train.warm_up": 200, "train.densify.enabled": False,
            "train.init.n_points_object": 200, "train.snapshots": [1.0]}
    cells = {c: CellSpec(spec.method, overrides=tiny, speed="" if c == "d3dgs_sharp" else "fast")
             for c, spec in CELLS.items()}
    cells["d3dgs_sharp"] = CellSpec("d3dgs", overrides={**tiny, "frames": "sharp"})
    cfg = build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": ["cubes"], "cells": cells,
                                     "speed_levels": {"fast": 3}, "lpips_net": "alex",
                                     "speed": {"scenes": ["cubes"], "speeds": [1, 3], "cells": ["d3dgs_blur", "e4dgs"]}})
    out = tmp_path / "runs"
    run_bench(cfg, "tiny", data, out, cells=["d3dgs_sharp", "d3dgs_blur", "e4dgs"], studies=("main", "speed"),
              progress=False, log=lambda s: None)
    rows = {row["key"]: row for row in read_results(out / "results.jsonl")}
    blur_main, blur_x1 = rows["main/cubes/d3dgs_blur"], rows["speed/cubes/d3dgs_blur/x1"]
    assert blur_main["run_dir"].startswith("cubes_x3/") and blur_main["data"]["speed"] == 3.0
    assert blur_main["lpips"] is not None and blur_x1["lpips"] is None          # the study reads PSNR only
    assert rows["speed/cubes/d3dgs_blur/x3"]["scored_as"] == "main/cubes/d3dgs_blur"   # trained once
    # 1 ms at 3000 FPS * s: 3 and 9 rendered frames; the blur grows with the speed
    assert blur_main["data"]["blur_median_px"] > 2 * blur_x1["data"]["blur_median_px"] > 0
    for row in rows.values():
        assert math.isfinite(row["floor_psnr"]) and math.isfinite(row["floor_psnr_luma"])
    e4 = rows["speed/cubes/e4dgs/x3"]
    assert e4["data"]["events_per_s_per_camera"] == pytest.approx(3 * rows["speed/cubes/e4dgs/x1"]["data"]["events_per_s_per_camera"], rel=0.02)
    write_report(list(rows.values()), out)
    assert "## cubes" in (out / "speed.md").read_text() and (out / "speed.png").exists()
    # a leaderboard job whose folder the study scored first, without LPIPS, scores it again with LPIPS
    results = out / "results.jsonl"
    study_first = [{**r, "lpips": None, "scored_as": None} if r["key"] == "speed/cubes/e4dgs/x3" else r
                   for r in read_results(results) if r["key"] != "main/cubes/e4dgs"]
    results.write_text("".join(json.dumps(r) + "\n" for r in study_first))
    again = {r["key"]: r for r in run_bench(cfg, "tiny", data, out, cells=["e4dgs"], studies=("main",),
                                             progress=False, log=lambda s: None)}
    assert again["main/cubes/e4dgs"]["lpips"] is not None and not again["main/cubes/e4dgs"].get("scored_as")
    assert again["main/cubes/e4dgs"]["psnr"] == pytest.approx(rows["speed/cubes/e4dgs/x3"]["psnr"])


def test_blur_table_at_speed_levels_names_each_speed_and_includes_events_only_cells():
    from benchmark.report import blur_table

    rows = [{**_row("blur", "h", c, 20.0 + k, speed=s, variant=lv), "key": f"blur/h/{c}/{lv}"}
            for k, c in enumerate(("d3dgs_blur", "e4dgs")) for lv, s in (("mild", 6.0), ("medium", 8.0), ("strong", 20.0))]
    md = blur_table(rows)
    assert "- strong: speed x20, blur 60.0 / 100.0 px (median / p90), blurred frames 13.0 dB from sharp" in md
    assert "- mild: speed x6," in md
    e4 = next(l for l in md.splitlines() if l.startswith(f"| {LABELS['e4dgs']} |"))
    assert e4.count("21.00") == 3 and "every method, events-only ones included" in md
