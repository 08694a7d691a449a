"""Scale-out on Ray (a local Ray with 2 worker CPUs): the tiny bench grid gives the serial run's
numbers, a worker killed mid-job is retried and every row arrives, a job that keeps failing becomes
a 'failed' row without losing the others, scene files are verified on the worker, and a dataset
generated through Ray is byte-identical to the serial one. The serial paths never import Ray."""
import json
import re
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import pytest

from benchmark.config import BenchConfig, CellSpec
from benchmark.report import write_report
from benchmark.runner import read_results, run_bench
from common.config import build_config
from common.taskpool import RayOptions, TaskSpec, run_tasks

ROOT = Path(__file__).resolve().parents[2]
TINY = {"train.iterations": 12, "train.scale_schedule": False, "train.warm_up": 200,
        "train.densify.enabled": False, "train.init.n_points_object": 300, "train.checkpoint_every": 5,
        "train.snapshots": [0.5, 1.0]}
GRID = ["d3dgs_sharp", "d3dgs_blur", "e4dgs"]       # + the ablation's w/o AES: 5 jobs, 4 training folders
METRICS = ("psnr", "ssim", "lpips", "iterations", "n_gaussians", "n_test_images", "channels", "config_hash")


@pytest.fixture(scope="module")
def local_ray():
    import ray

    ray.init(num_cpus=2, log_to_driver=False, include_dashboard=False)   # two single-CPU workers at a time
    yield RayOptions(retries=2)
    ray.shutdown()


def _grid(scene: Path, long: dict | None = None) -> BenchConfig:
    """The six bundled cells with the quick preset's labels; the tests run a subset with `cells=`."""
    cells = {"d3dgs_sharp": CellSpec("d3dgs", overrides={**TINY, "frames": "sharp", **(long or {})}),
             "d3dgs_blur": CellSpec("d3dgs", overrides={**TINY, "frames": "strong"}),
             "deblur_d3dgs": CellSpec("deblur_d3dgs", overrides={**TINY, "frames": "strong"}),
             "e2vid_d3dgs": CellSpec("e2vid_d3dgs", overrides=TINY),
             "e4dgs": CellSpec("e4dgs", overrides=TINY),
             "e4dgs_rgb": CellSpec("e4dgs_rgb", overrides={**TINY, "rgb_frames": "strong"})}
    from dataclasses import replace

    from bench_cells import LABELS

    cells = {c: replace(spec, label=LABELS[c]) for c, spec in cells.items()}
    return build_config(BenchConfig, {"dataset": "tiny_motion", "scenes": [scene.name], "cells": cells,
                                      "ablation": {"scene": scene.name, "switches": {"w/o AES": {"events.aes": False}}},
                                      "lpips_net": "alex"})


def _metrics(rows):
    out = {}
    for r in rows:
        out[r["key"]] = {k: r[k] for k in METRICS} | {"snapshots": [(s["iteration"], s["psnr"]) for s in r["snapshots"]]}
    return out


def test_tiny_grid_on_ray_gives_the_serial_numbers(motion_scene, tmp_path, local_ray):
    cfg = _grid(motion_scene)
    quiet = lambda s: None  # noqa: E731
    import numba
    import torch

    # A 1-CPU Ray task trains on one torch and one numba thread; the serial run does the same here, since
    # the CPU rasterizer sums per-thread gradient buffers (another thread count changes the last bits).
    threads = torch.get_num_threads(), numba.get_num_threads()
    torch.set_num_threads(1)
    numba.set_num_threads(1)
    try:
        serial = run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "serial", cells=GRID, progress=False, log=quiet)
    finally:
        torch.set_num_threads(threads[0])
        numba.set_num_threads(threads[1])
    t0 = time.time()
    on_ray = run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "ray", cells=GRID, progress=False, log=quiet,
                       ray=local_ray)
    assert time.time() - t0 < 300
    assert len(serial) == 5 and {r["key"] for r in on_ray} == {r["key"] for r in serial}
    assert _metrics(read_results(tmp_path / "ray" / "results.jsonl")) == _metrics(serial)   # identical numbers
    assert all(r.get("status") != "failed" for r in on_ray)
    # the ablation's full seed-0 run shares the main E-4DGS folder: trained once, by one task
    logs = sorted(p.name for p in (tmp_path / "ray" / "logs").iterdir())
    assert len(logs) == 4 and all("attempt started" in (tmp_path / "ray" / "logs" / n).read_text() for n in logs)
    shared = [r for r in on_ray if r.get("scored_as")]          # ... and scored once: its row is copied
    assert [(r["study"], r["variant"], r["eval_s"]) for r in shared] == [("ablation", "full", 0.0)]
    # a second run reuses every row and submits nothing
    again = run_bench(cfg, "tiny", motion_scene.parent, tmp_path / "ray", cells=GRID, progress=False, log=quiet,
                      ray=local_ray)
    assert _metrics(again) == _metrics(on_ray)


def test_a_worker_killed_mid_job_is_retried_and_every_row_arrives(motion_scene, tmp_path, local_ray):
    cfg = _grid(motion_scene, long={"train.iterations": 400, "train.checkpoint_every": 10})
    out = tmp_path / "runs"
    result = {}
    driver = threading.Thread(target=lambda: result.update(rows=run_bench(
        cfg, "tiny", motion_scene.parent, out, cells=["d3dgs_sharp", "e4dgs"], studies=("main",), progress=False,
        log=lambda s: None, ray=local_ray)))
    driver.start()
    killed = None
    deadline = time.time() + 240
    while killed is None and time.time() < deadline and driver.is_alive():
        for lock in (out / motion_scene.name).glob(".d3dgs-*.lock") if (out / motion_scene.name).exists() else []:
            run_dir = lock.with_name(lock.name[1:-len(".lock")])
            pid = lock.read_text().strip()
            if pid.isdigit() and int(pid) != os.getpid() and (run_dir / "checkpoint.pt").exists():
                os.kill(int(pid), signal.SIGKILL)          # the Ray worker training this job dies mid-job
                killed = (int(pid), run_dir)
                break
        time.sleep(0.05)
    driver.join(timeout=300)
    assert killed is not None, "never saw the D3DGS job mid-training"
    assert not driver.is_alive()
    rows = {r["key"]: r for r in result["rows"]}
    assert set(rows) == {f"main/{motion_scene.name}/d3dgs_sharp", f"main/{motion_scene.name}/e4dgs"}
    assert all(r.get("status") != "failed" for r in rows.values())
    assert rows[f"main/{motion_scene.name}/d3dgs_sharp"]["iterations"] == 400
    log = (out / "logs" / f"{motion_scene.name}__{killed[1].name}.log").read_text()
    assert log.count("attempt started") == 2 and f"(pid {killed[0]})" in log   # the retry is a new worker
    assert "resuming" in log.split("attempt started")[2]            # from the killed attempt's checkpoint


def test_data_is_verified_on_the_worker_and_a_failing_job_is_reported_not_fatal(motion_scene, tmp_path, local_ray):
    data = tmp_path / "data"
    shutil.copytree(motion_scene, data / motion_scene.name)
    cfg = _grid(motion_scene)
    out = tmp_path / "runs"
    quiet = lambda s: None  # noqa: E731
    ok = run_bench(cfg, "tiny", data, out, cells=["d3dgs_sharp"], studies=("main",), progress=False, log=quiet,
                   ray=local_ray)
    assert [r["cell"] for r in ok] == ["d3dgs_sharp"]
    h5 = next((data / motion_scene.name).rglob("*.h5"))
    original = h5.read_bytes()
    blob = bytearray(original)
    blob[len(blob) // 2] ^= 0xFF                           # one flipped byte in an event file
    h5.write_bytes(bytes(blob))
    rows = run_bench(cfg, "tiny", data, out, cells=["e4dgs"], studies=("main",), progress=False, log=quiet,
                     ray=RayOptions(retries=0))
    by = {r["cell"]: r for r in rows}
    assert by["d3dgs_sharp"].get("status") is None and by["d3dgs_sharp"]["psnr"] > 0   # earlier rows are kept
    assert by["e4dgs"]["status"] == "failed" and h5.name in by["e4dgs"]["error"] and "SHA-256" in by["e4dgs"]["error"]
    write_report(rows, out)
    board = (out / "leaderboard.md").read_text()
    assert "| E-4DGS (events) | failed |" in board and "### Failed jobs" in board
    h5.write_bytes(original)
    rows = run_bench(cfg, "tiny", data, out, cells=["e4dgs"], studies=("main",), progress=False, log=quiet,
                     ray=local_ray)                        # repaired: the failed job runs again and succeeds
    assert all(r.get("status") is None for r in rows) and {r["cell"] for r in rows} == {"d3dgs_sharp", "e4dgs"}


def test_taskpool_reports_each_outcome_once_and_retries_failures(tmp_path, local_ray):
    from common.argtypes import positive_int        # a package function: workers import it by name

    seen = []
    specs = [TaskSpec(f"t{x}", positive_int, (str(x),), log_path=tmp_path / f"t{x}.log") for x in (1, 2, 0, 3)]
    outcomes = run_tasks(specs, RayOptions(retries=1), seen.append, progress=False)
    assert sorted(o.key for o in seen) == ["t0", "t1", "t2", "t3"] and len(outcomes) == 4
    by = {o.key: o for o in seen}
    assert [by[f"t{x}"].value for x in (1, 2, 3)] == [1, 2, 3] and all(by[f"t{x}"].ok for x in (1, 2, 3))
    assert not by["t0"].ok and by["t0"].error == "ArgumentTypeError: expected an integer in 1 .. 1,000,000,000, got '0'"
    assert (tmp_path / "t0.log").read_text().count("attempt started") == 2      # one retry
    assert "Traceback" in (tmp_path / "t0.log").read_text()                     # kept in the job's log
    with pytest.raises(ValueError, match="unique"):
        run_tasks(specs + specs[:1], RayOptions(), seen.append, progress=False)


def test_a_refused_input_is_not_retried_and_reads_as_on_the_plain_path(tmp_path, local_ray):
    """A task whose input is refused (ValueError) runs once and reports the plain path's words; a
    failure of another kind is retried."""
    import operator

    specs = [TaskSpec("refused", int, ("seven",), log_path=tmp_path / "refused.log"),
             TaskSpec("broken", operator.truediv, (1, 0), log_path=tmp_path / "broken.log")]
    by = {o.key: o for o in run_tasks(specs, RayOptions(retries=2), lambda o: None, progress=False)}
    assert by["refused"].refused and by["refused"].error == "ValueError: invalid literal for int() with base 10: 'seven'"
    assert (tmp_path / "refused.log").read_text().count("attempt started") == 1
    assert not by["broken"].refused and by["broken"].error.startswith("ZeroDivisionError")
    assert (tmp_path / "broken.log").read_text().count("attempt started") == 3


def test_a_scene_refused_on_ray_says_what_the_plain_path_says(tmp_path, local_ray):
    """A scene whose blur target cannot be reached: the worker's own error line reaches the console with
    and without Ray, the refusal is not retried, and Ray leaves its log under the output folder."""
    import tempfile

    from datagen.build import generate_dataset

    preset = tmp_path / "p.yaml"
    preset.write_text("scenes: [cubes]\noverrides:\n  duration_s: 0.02\n  render: {width: 32, height: 24, samples: 1}\n"
                      "  camera: {n_cameras: 1}\n  blur: {target_px: {strong: 400.0}, max_exposure_ms: 2.0}\n")
    before = set(Path(tempfile.gettempdir()).glob("e4dgs-ray-*.log"))
    said: list[str] = []
    assert generate_dataset(str(preset), None, tmp_path / "ray", log=said.append, ray=RayOptions(retries=2)) == ["cubes"]
    line = next(s for s in said if "cubes failed" in s)
    assert "blur" in line and "cannot be reached" in line and "status" not in line, said
    assert (tmp_path / "ray" / "logs" / "cubes.log").read_text().count("attempt started") == 1
    plain = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset", str(preset),
                            "--out", str(tmp_path / "plain"), "--no-progress"], capture_output=True, text=True, cwd=ROOT)
    error = plain.stderr.strip().splitlines()[-1].removeprefix("error: ")
    assert plain.returncode != 0 and error in line, (error, line)
    assert set(Path(tempfile.gettempdir()).glob("e4dgs-ray-*.log")) == before


def test_taskpool_bar_redraws_on_a_change_not_every_poll(tmp_path, local_ray, capsys):
    """A 6-s task polled every second: its status line is drawn when it changes (and around the
    outcome's log line), so a job log (stderr not a terminal) is not filled with one bar per second."""
    outcomes = run_tasks([TaskSpec("nap", time.sleep, (6.0,), log_path=tmp_path / "nap.log")], RayOptions(),
                         lambda o: None, progress=True)
    assert outcomes[0].ok
    draws = capsys.readouterr().err.split("\r")
    while_running = [d for d in draws if "0/1 [" in d and "running 1," in d]
    assert 1 <= len(while_running) <= 2    # the change, and the redraw around the outcome's log line


def test_dataset_through_ray_is_byte_identical_to_the_serial_one(motion_scene, tmp_path, local_ray):
    from datagen.build import generate_dataset

    failed = generate_dataset("tiny_motion", ["cubes"], tmp_path, log=lambda s: None, ray=local_ray)
    assert failed == []
    serial = json.loads((motion_scene / "manifest.json").read_text())["files"]
    on_ray = json.loads((tmp_path / "cubes" / "manifest.json").read_text())["files"]
    assert len(serial) > 10 and on_ray == serial                   # every file: same size and SHA-256
    assert "attempt started" in (tmp_path / "logs" / "cubes.log").read_text()


def test_a_scene_from_a_file_generates_on_ray_as_it_does_serially(tmp_path, local_ray):
    """--scene-file scenes take the preset scenes' path on Ray too; the file's path, given relative to
    the caller's folder, reaches the worker (which runs elsewhere) and the files are identical."""
    from datagen.build import generate_dataset

    r = subprocess.run([sys.executable, str(ROOT / "examples" / "scenes" / "make_scenes.py"), str(tmp_path / "files")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-1500:]
    preset = tmp_path / "p.yaml"
    preset.write_text("scenes: [cubes]\noverrides:\n  duration_s: 0.01\n  render: {width: 48, height: 32, samples: 5}\n"
                      "  camera: {n_cameras: 2}\n  frames: {keep_every: 3, test_every: 2}\n")
    glb = os.path.relpath(tmp_path / "files" / "spinner.glb")
    args = {"spinner": ["--scene-file", glb, "--kind", "object"]}
    assert generate_dataset(preset, None, tmp_path / "serial", log=lambda s: None, scene_args=args) == []
    assert generate_dataset(preset, None, tmp_path / "ray", log=lambda s: None, scene_args=args, ray=local_ray) == []
    serial = json.loads((tmp_path / "serial" / "spinner" / "manifest.json").read_text())["files"]
    on_ray = json.loads((tmp_path / "ray" / "spinner" / "manifest.json").read_text())["files"]
    assert len(serial) > 10 and on_ray == serial


def test_serial_commands_never_import_ray():
    code = ("import sys, e4dgs.cli, benchmark.runner, datagen.build, common.argtypes; "
            "p = e4dgs.cli.build_parser(); p.parse_args(['bench', '--report']); "
            "assert 'ray' not in sys.modules, 'ray imported'")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr


def test_ray_options_are_range_checked(capsys):
    from e4dgs.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench", "--ray", "--ray-retries", "-1"])
    assert "--ray-retries" in capsys.readouterr().err
    args = build_parser().parse_args(["dataset", "--ray", "--ray-cpus", "2"])
    assert args.ray == "local" and args.ray_cpus == 2.0
    assert build_parser().parse_args(["bench", "--ray", "auto"]).ray == "auto"
    assert build_parser().parse_args(["bench"]).ray is None
    with pytest.raises(ValueError, match="retries"):
        RayOptions(retries=-1)


def test_the_commands_take_ray(motion_scene, tmp_path, local_ray, capsys):
    """`e4dgs dataset --ray` and `e4dgs bench --ray` end to end (through the module's local Ray)."""
    import yaml

    from e4dgs.cli import main

    assert main(["dataset", "--preset", "tiny", "--out", str(tmp_path / "data"), "--ray"]) == 0
    assert (tmp_path / "data" / "cubes" / "manifest.json").exists() and (tmp_path / "data" / "logs" / "cubes.log").exists()
    preset = tmp_path / "grid.yaml"
    preset.write_text(yaml.safe_dump({"dataset": "tiny_motion", "scenes": [motion_scene.name], "lpips_net": "alex",
                                      "cells": {c: {"method": s.method, "label": s.label, "overrides": s.overrides}
                                                for c, s in _grid(motion_scene).cells.items()}}))
    out = tmp_path / "runs"
    assert main(["bench", "--preset", str(preset), "--data", str(motion_scene.parent), "--out", str(out),
                 "--studies", "main", "--cells", "e4dgs", "--ray", "--ray-retries", "0", "--no-progress"]) == 0
    rows = read_results(out / "results.jsonl")
    assert [r["cell"] for r in rows] == ["e4dgs"] and rows[0]["psnr"] > 0
    assert "E-4DGS (events)" in (out / "leaderboard.md").read_text()


def test_limit_threads_leaves_numba_able_to_compile():
    """A worker whose numba pool already runs (a 2-thread pool) is limited to 1 thread and must
    still compile new kernels: numba re-reads NUMBA_NUM_THREADS at every compilation and refuses a
    changed value, which failed every bench job on a fresh numba cache. A task's child processes
    get the limit through child_env."""
    code = textwrap.dedent("""
        import numpy as np, numba
        from numba import njit, prange

        @njit(parallel=True)
        def total(x):
            s = 0.0
            for i in prange(x.shape[0]):
                s += x[i]
            return s

        assert total(np.ones(8)) == 8.0                  # launches the pool at 2 threads
        from common.taskpool import child_env, limit_threads
        limit_threads(1)

        @njit
        def plus_one(v):
            return v + 1

        assert plus_one(1) == 2                          # a compilation after the limit
        assert numba.get_num_threads() == 1
        assert child_env()["NUMBA_NUM_THREADS"] == "1"
        print("ok")
    """)
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_NUM_THREADS",)}
    env["NUMBA_NUM_THREADS"] = "2"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]


def test_losing_the_progress_actor_costs_the_display_never_the_grid(tmp_path, local_ray, capsys):
    """Ray's memory monitor killed the tracking actor in a `make benchmark` beside a memory-hungry process
    and `e4dgs bench` died with it; now the tasks still finish and every outcome arrives."""
    import ray

    from common.argtypes import positive_int
    from common.taskpool import tracker_name

    seen = []

    def kill_tracker(outcome):
        seen.append(outcome)
        if len(seen) == 1:
            ray.kill(ray.get_actor(tracker_name()), no_restart=True)

    specs = [TaskSpec("quick", positive_int, ("1",), log_path=tmp_path / "q.log"),
             TaskSpec("nap", time.sleep, (4.0,), log_path=tmp_path / "n.log"),
             TaskSpec("later", positive_int, ("3",), log_path=tmp_path / "l.log")]
    outcomes = run_tasks(specs, RayOptions(retries=1), kill_tracker, progress=True)
    assert sorted(o.key for o in outcomes) == ["later", "nap", "quick"] and all(o.ok for o in outcomes)
    assert {o.key: o.value for o in outcomes} == {"quick": 1, "nap": None, "later": 3}
    assert "running ?" in capsys.readouterr().err          # the display says it lost count, and goes on


def test_two_runs_in_one_process_never_share_a_progress_actor(tmp_path, local_ray):
    """`e4dgs bench --ray` calls run_tasks twice (the dataset's scenes, then the jobs); Ray removes an
    actor asynchronously, so on a busy machine the second call was once refused: its actor's name was
    still taken by the first's."""
    from common.argtypes import positive_int
    from common.taskpool import tracker_name

    names = []
    for k in range(3):
        out = run_tasks([TaskSpec(f"t{k}", positive_int, ("2",), log_path=tmp_path / f"t{k}.log")], RayOptions(),
                        lambda o: names.append(tracker_name()), progress=False)
        assert out[0].ok and out[0].value == 2
    assert len(set(names)) == 3


def test_rays_messages_go_to_the_log_with_one_line_on_the_console(tmp_path, capsys):
    """A memory kill printed a page of Ray's text (object store stats, top memory users, advice) into
    the console of `make benchmark`; it goes to the log now, one line on the console."""
    import ray._private.worker as ray_worker

    from common.taskpool import _ray_messages_to

    original = ray_worker.print_to_stdstream
    log = tmp_path / "logs" / "ray.log"
    undo = _ray_messages_to(log)
    page = "\nOOM kill reason: Memory usage 24151179264B exceeded threshold\nObject store memory usage: [...]\n" + "x\n" * 40
    ray_worker.print_to_stdstream({"lines": [page], "pid": "raylet", "is_err": False}, ignore_prefix=False)
    undo()
    err = capsys.readouterr()
    assert err.out == "" and err.err.count("\n") == 1
    assert err.err.startswith("ray: OOM kill reason: Memory usage 24151179264B exceeded threshold") and str(log) in err.err
    assert "Object store memory usage" in log.read_text() and ray_worker.print_to_stdstream is original


def _counting_job(n: int, child: bool) -> int:
    """A job that reports its position: in this process, or (child) from a subprocess it starts."""
    import subprocess
    import sys
    import time

    from common.progress import report

    if child:
        code = ("import time\nfrom common.progress import report\n"
                f"for i in range({n}):\n    report(i + 1, {n}, 'timestamps')\n    time.sleep(0.5)\n")
        subprocess.run([sys.executable, "-c", code], check=True, cwd=str(ROOT))
        return n
    for i in range(n):
        report(i + 1, n, "it")
        time.sleep(0.5)
    return n


def test_the_bar_shows_each_running_jobs_position_and_time_left_also_from_a_child_process(tmp_path, local_ray, capsys,
                                                                                            monkeypatch):
    """`make benchmark` renders its scenes as Ray tasks whose scene worker is a child process; the
    driver's bar names each running job's position in its unit (timestamps, iterations) with an
    estimate of the time left, read from the file the job (or its child) reports to."""
    import common.taskpool as taskpool

    monkeypatch.setattr(taskpool, "PROGRESS_EVERY_S", 0.5)
    specs = [TaskSpec("scene", _counting_job, (14, True), log_path=tmp_path / "scene.log"),
             TaskSpec("cell", _counting_job, (14, False), log_path=tmp_path / "cell.log")]
    outcomes = run_tasks(specs, RayOptions(retries=0), lambda o: None, progress=True)
    assert sorted(o.value for o in outcomes) == [14, 14]
    err = capsys.readouterr().err
    assert re.search(r"scene: \d+/14 timestamps, ~\d+ s left", err), err[-2000:]
    assert re.search(r"cell: \d+/14 it, ~\d+ s left", err), err[-2000:]
    assert not list(tmp_path.glob("*.progress"))          # a finished job's report is gone


def test_a_ray_that_cannot_start_is_a_connection_error_not_an_internal_one(monkeypatch):
    """ray.init failing (an unreachable address, a broken install) is one ConnectionError naming the
    address, which the command line prints as an error line."""
    import ray

    from common.taskpool import ray_session

    def refuse(*a, **k):
        raise RuntimeError("Failed to connect to GCS at address 10.0.0.9:6379 within 60 seconds")

    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setattr(ray, "init", refuse)
    with pytest.raises(ConnectionError, match=r"ray: cannot connect to Ray at '10.0.0.9:6379' \(RuntimeError: Failed"):
        with ray_session(RayOptions(address="10.0.0.9:6379")):
            pass
