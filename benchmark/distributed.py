"""`e4dgs bench --ray`: the benchmark's jobs as Ray tasks (the engine is common.taskpool).

Jobs that share a training folder (the ablation's full seed-0 run is the main E-4DGS cell) form one
task, so two workers never train into the same folder. A task verifies its scene against the
manifest on the worker (sizes and SHA-256: the data path must show every node the same files),
trains or resumes, scores once and returns the rows (the folder's other jobs reuse the scores);
only the driver writes results.jsonl, once per finished task. A task that still fails after its
retries becomes a row with status "failed" (the leaderboard names it); a later `e4dgs bench` runs
it again.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from benchmark.config import BenchConfig
from benchmark.grid import Job
from benchmark.job_run import by_folder, failed_row, job_data_dir, row_summary, run_folder
from common.taskpool import RayOptions, TaskOutcome, TaskSpec, cluster_gpus, ray_session, run_tasks


def run_group(jobs: list[Job], cfg: BenchConfig, data_root: Path, out_root: Path, method_cfgs: list) -> list[dict]:
    """On a worker: check the scene's files, then train (or resume) and score each job of one folder."""
    from scene_format.verify import verify_scene

    scene_dir = job_data_dir(jobs[0], data_root)
    problems = verify_scene(scene_dir)
    if problems:
        raise ValueError(f"{scene_dir} on this node does not match its manifest: {problems[0]}"
                         + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""))
    return run_folder(jobs, cfg, data_root, out_root, False, method_cfgs)


def wants_gpu(method_cfg) -> bool:
    """Training asks for a GPU when its device may be CUDA (auto or cuda[:N])."""
    return str(method_cfg.train.device).split(":")[0] in ("auto", "cuda")


def run_jobs_on_ray(todo: list[Job], resolved: dict, cfg: BenchConfig, data_root: Path, out_root: Path,
                    record: Callable[[list[dict]], None], progress: bool = True,
                    log: Callable[[str], None] = print, *, opts: RayOptions) -> None:
    """The Ray executor (job_run.JobExecutor, with the Ray options bound): `todo` as Ray tasks, calling
    record(rows) on the driver as each task ends (a task that failed every attempt records rows with
    status "failed" and the error)."""
    data_root, out_root = Path(data_root).resolve(), Path(out_root).resolve()   # workers may run elsewhere
    groups = by_folder(todo)
    with ray_session(opts, out_root / "logs" / "ray.log"):
        gpus = cluster_gpus()
        specs = []
        for run_dir, group in groups.items():
            mcs = [resolved[j.key] for j in group]
            specs.append(TaskSpec(run_dir, run_group, (group, cfg, data_root, out_root, mcs),
                                  num_cpus=opts.cpus_per_task, num_gpus=1.0 if gpus and wants_gpu(mcs[0]) else 0.0,
                                  log_path=out_root / "logs" / f"{run_dir.replace('/', '__')}.log"))
        log(f"bench: {len(todo)} job(s) as {len(specs)} Ray task(s), {opts.cpus_per_task:g} CPU each"
            f"{', one GPU per training task' if gpus else ''}; {opts.retries} retries; logs in {out_root / 'logs'}")

        def done(outcome: TaskOutcome) -> None:
            if outcome.ok:
                record(outcome.value)
                for row in outcome.value:
                    log(f"bench {row_summary(row)}")
            else:
                record([failed_row(j, outcome.error) for j in groups[outcome.key]])
                tries = "" if outcome.refused else f" after {opts.retries} retries"
                log(f"bench {outcome.key}: FAILED{tries}: {outcome.error}")

        run_tasks(specs, opts, done, desc="bench", progress=progress)
