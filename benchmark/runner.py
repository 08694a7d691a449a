"""`e4dgs bench`: train every job of a preset, score the held-out views, append to results.jsonl.

runs/<preset>/
  results.jsonl            one row per job (study x scene x cell x variant); rewritten atomically
  <scene>/<method>-<hash>/ the training folder (shared by jobs with the same method and config)
  bench.json               the preset as run

A job whose row exists with the same identity (config_hash: its resolved config, input files, the
scene folder's content and the code version, benchmark.grid.Job.identity_parts) is reused; a row
made by another identity is not: the job trains again, unless `reuse_older`, which keeps a row of
the same resolved config made by another code version or dataset (the tables mark it). A training
folder resumes from its checkpoint, so a killed benchmark picks up where it stopped. Each row holds the final model's
PSNR / SSIM / LPIPS (means of per-image values over the scene's held-out views), snapshot scores
against training wall-clock seconds, iterations, Gaussian count, package versions, git commit.
"""
from __future__ import annotations

import json
import time
from functools import partial
from pathlib import Path
from typing import Callable

from benchmark.config import BenchConfig, dump
from benchmark.grid import Job, jobs, older_note
from benchmark.job_run import JobExecutor, complete_row, reused_row, run_jobs_here
from benchmark.rows import read_results, write_results  # noqa: F401 - read_results: for callers
from common.fileio import write_text_atomic


def ensure_dataset(dataset: str, scenes: list[str], data_root: Path, log: Callable[[str], None], ray=None) -> None:
    """Generate the scenes of dataset preset `dataset` that data_root lacks (skips complete ones).
    `scenes` may name speed variants (garage_x4): their scene is generated, which writes them."""
    from scene_format.naming import split_variant

    missing = sorted({split_variant(s)[0] for s in scenes if not (data_root / s / "manifest.json").exists()})
    if not missing:
        return
    from datagen.build import generate_dataset

    log(f"bench: generating dataset {dataset} for {', '.join(missing)} -> {data_root}")
    failed = generate_dataset(dataset, missing, data_root, jobs=min(2, len(missing)), log=log, ray=ray)
    if failed:
        raise RuntimeError(f"dataset generation failed for {', '.join(failed)} (the error lines above say why: a "
                           "scene that was killed or crashed resumes when `e4dgs bench` runs again; one refused for "
                           "its input needs that input fixed first)")


def run_bench(cfg: BenchConfig, preset_name: str, data_root: Path, out_root: Path, scenes: list[str] | None = None,
              cells: list[str] | None = None, studies: tuple[str, ...] = ("main", "blur", "ablation"),
              progress: bool = True, log: Callable[[str], None] = print, ray=None,
              reuse_older: bool = False) -> list[dict]:
    """Run every job not yet in results.jsonl, in this process one after another, or as Ray tasks
    when `ray` is a common.taskpool.RayOptions (Ray is imported only then). Returns all rows."""
    todo = [j for j in jobs(cfg, data_root) if j.study in studies and (not scenes or j.scene in scenes)
            and (not cells or j.cell in cells)]
    if not todo:          # before any folder or dataset is made
        from common.config import ConfigError

        asked = ", ".join(f"{k} {v}" for k, v in (("studies", ",".join(studies)), ("scenes", ",".join(scenes or [])),
                                                    ("cells", ",".join(cells or []))) if v)
        raise ConfigError(f"bench preset {preset_name!r}: no job for {asked} (a study the preset does not declare, "
                          "or scenes / cells outside it); nothing to run")
    needed = sorted({j.data_scene for j in todo if not j.dataset})
    resolved = {j.key: j.method_config for j in todo}   # every job's config, checked before any work
    t_start = time.time()
    ensure_dataset(cfg.dataset, needed, data_root, log, ray)
    for other in sorted({j.dataset for j in todo if j.dataset}):    # the realistic-sensor variants
        ensure_dataset(other, sorted({j.data_scene for j in todo if j.dataset == other}), data_root.parent / other, log, ray)
    dataset_s = time.time() - t_start
    out_root.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out_root / "bench.json", json.dumps({"preset": preset_name, **dump(cfg)}, indent=1))
    results_path = out_root / "results.jsonl"
    rows = read_results(results_path)
    by_key = {j.key: j for j in todo}
    done = {(r["key"], r["config_hash"]) for r in rows
            if r.get("status") != "failed" and (r["key"] not in by_key or complete_row(r, by_key[r["key"]], cfg, data_root))}
    older = {r["key"]: older_note(r, by_key[r["key"]]) for r in rows if r.get("key") in by_key
             and r.get("config_hash") != by_key[r["key"]].config_hash() and r.get("status") != "failed"}
    kept_older = {k: n for k, n in older.items() if reuse_older and n and n != "config"
                  and complete_row(next(r for r in rows if r["key"] == k), by_key[k], cfg, data_root)}
    if cfg.description:
        log(f"bench {preset_name}: " + " ".join(cfg.description.split()))
    log(f"bench {preset_name}: {len(todo)} job(s) on {', '.join(needed)}; "
        f"{sum((j.key, j.config_hash()) in done for j in todo)} already in {results_path}")
    newer = {k: n for k, n in older.items() if n and n != "config"}
    if kept_older:
        log(f"bench {preset_name}: --reuse-older keeps {len(kept_older)} row(s) made by another version "
            f"(marked in the tables), e.g. {next(iter(kept_older))}: {next(iter(kept_older.values()))}")
    elif newer:
        log(f"bench {preset_name}: {len(newer)} row(s) were made by another version and train again "
            f"(e.g. {next(iter(newer))}: {next(iter(newer.values()))}; --reuse-older keeps them, marked)")

    def record(new_rows: list[dict]) -> None:          # the driver is the only writer of results.jsonl
        nonlocal rows
        old = {(r["key"], r.get("config_hash")): r for r in rows}
        for r in new_rows:                              # scored again from a finished model: its training time stays
            before = old.get((r["key"], r.get("config_hash")))
            if before and (before.get("train_elapsed_s") or 0) > (r.get("train_elapsed_s") or 0):
                r.update(train_elapsed_s=before["train_elapsed_s"], rescored_unix=int(time.time()))
        keys = {r["key"] for r in new_rows}
        rows = [r for r in rows if r["key"] not in keys] + new_rows
        write_results(results_path, rows)

    def scored(job: Job) -> dict | None:   # a finished row of the same training folder, if any
        return next((r for r in rows if r.get("run_dir") == job.folder and r.get("config_hash") == job.config_hash()
                     and complete_row(r, job, cfg, data_root)), None)

    t0 = time.time()
    remaining = [j for j in todo if (j.key, j.config_hash()) not in done and j.key not in kept_older]
    reusable = [(j, scored(j)) for j in remaining]
    if any(r for _, r in reusable):
        record([reused_row(j, r) for j, r in reusable if r])
        remaining = [j for j, r in reusable if not r]
    executor: JobExecutor = run_jobs_here
    if ray is not None:
        from benchmark.distributed import run_jobs_on_ray

        executor = partial(run_jobs_on_ray, opts=ray)
    executor(remaining, resolved, cfg, data_root, out_root, record, progress, log)
    log(f"bench {preset_name}: done in {time.time() - t_start:.0f} s ({dataset_s:.0f} s dataset, "
        f"{time.time() - t0:.0f} s jobs) -> {results_path}")
    return rows

