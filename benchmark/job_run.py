"""One benchmark job's work, shared by the serial path and the Ray path (benchmark.distributed): its
scene folder, its typed config, training or reuse, scoring the final model, its floor and its
snapshots, and the row it becomes. Both paths are executors with one interface (`JobExecutor`):
`run_jobs_here` below, `distributed.run_jobs_on_ray`; each trains every training folder once (the
folder's other jobs reuse its row) and hands the rows to the driver's `record`."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable, Protocol

from benchmark.config import BenchConfig
from benchmark.grid import Job, scoring_note, wants_lpips  # noqa: F401 - wants_lpips: for callers
from benchmark.rows import ResultRow
from common import provenance
from common.machine import cpu_summary
from common.provenance import git_commit
from scene_format.manifest import masks_digest
from scene_format.reader import SceneDataset


def versions() -> dict:
    return provenance.versions("torch")


def job_data_dir(job: Job, data_root: Path) -> Path:
    """The scene folder a job trains on: data_root/<scene or its speed variant>, or that folder in the
    sibling dataset job.dataset (data/<dataset>/...)."""
    return (data_root.parent / job.dataset if job.dataset else data_root) / job.data_scene


def evaluate_model(model, dataset: SceneDataset, lpips_net: str | None, placement=None, method_cfg=None,
                   views_out: Path | None = None, views_meta: dict | None = None) -> dict:
    """Scores of `model` on the scene's test views through `recon.evaluate`, rendered on the run's
    (device, backend) (default: CPU, auto), over the whole images and, where the scene has dynamic
    masks, over the moving pixels (`*_dyn`); `method_cfg`: the run's config, already resolved."""
    from recon.api import evaluate

    device, backend = placement or ("cpu", "auto")
    return evaluate(model, dataset, "test", lpips_net=lpips_net, backend=backend, device=device, config=method_cfg,
                    views_out=views_out, views_meta=views_meta)


def has_masks(job: Job, data_root: Path) -> bool:
    """Whether the job's scene folder has dynamic masks (`e4dgs masks`, or generated with them)."""
    return (job_data_dir(job, data_root) / "dynamic" / "masks.json").exists()


def complete_row(row: dict, job: Job, cfg: BenchConfig, data_root: Path) -> bool:
    """Whether a finished row holds every score the job needs now: LPIPS where it is wanted, and the
    dynamic-region scores once its scene has masks (a row scored before is scored again, from the
    trained model: nothing is trained twice)."""
    return (row.get("status") != "failed" and (row.get("lpips") is not None or not wants_lpips(job, cfg))
            and ("psnr_dyn" in row or not has_masks(job, data_root)) and scoring_note(row, job, cfg) is None)


def data_stats(dataset: SceneDataset) -> dict:
    """What the scene folder holds, for the tables: its speed, the events per second per camera (mean
    over cameras), and for a speed variant its shutter's exposure, blur (median / p90 px) and
    blurred-vs-sharp PSNR."""
    facts = dataset.facts
    out = {"speed": facts.speed, "events_per_s_per_camera": facts.mean_events_per_second}
    level = facts.shutter
    if level:
        out.update(exposure_ms=level.exposure_ms, blur_median_px=level.median_px, blur_p90_px=level.p90_px,
                   blur_psnr_db=level.psnr_vs_sharp_db)
    return out


def scores_snapshots(job: Job) -> bool:
    """Whether a job's earlier snapshots are scored again on every test view: the main study's (the
    accuracy-vs-time curves); the studies' curves stay in their log.jsonl (~25 s of a task saved)."""
    return job.study == "main"


def run_job(job: Job, cfg: BenchConfig, data_root: Path, out_root: Path, progress: bool, method_cfg=None) -> dict:
    """Train (or resume, or reuse the finished model of) one job through `recon.fit`, score the result,
    its untrained floor and its snapshots through `recon.evaluate`, and make its results row."""
    from recon.api import fit
    from recon.model import load

    method_cfg = method_cfg if method_cfg is not None else job.method_config
    dataset = SceneDataset(job_data_dir(job, data_root))       # opened once: training and every score below
    result = fit(dataset, job.method, method_cfg, out_root / job.folder, progress=progress, keep_initial=True)
    model, placement = result.model, (result.device, result.backend)       # score where it trained
    t1 = time.time()
    lpips_net = cfg.lpips_net if wants_lpips(job, cfg) else None
    owner = views_owner(job)
    final = evaluate_model(model, dataset, lpips_net, placement, method_cfg, out_root / job.folder / VIEWS_DIR, owner)
    # the floor: what the method's own starting model scores after the same correction (an events-only
    # score means something about events only as far as it rises above this); its views are kept too
    floor = evaluate_model(result.initial, dataset, None, placement, method_cfg, out_root / job.folder / FLOOR_VIEWS_DIR,
                           {**owner, "floor": True})
    snapshots = []
    for row in result.log:
        if "snapshot" not in row:
            continue
        if row["iteration"] == model.meta.iteration:
            scores = {k: final[k] for k in ("psnr", "ssim", "lpips") if k in final}
        elif not scores_snapshots(job):      # the tables plot the main study's curves only: the others keep
            continue                         # their training log's test PSNR (log.jsonl), not re-rendered
        else:
            s = evaluate_model(load(result.run_dir / row["snapshot"]), dataset, None, placement, method_cfg)
            scores = {k: s[k] for k in cfg.snapshot_metrics if k in s}
        snapshots.append({"iteration": row["iteration"], "wall_s": row["wall_s"], **scores})
    return ResultRow.of(
        job.identity(), final, floor, data=data_stats(dataset), iterations=result.iterations, n_gaussians=len(model),
        channels=model.meta.channels, device=result.device, backend=result.backend, precision=model.meta.precision,
        cpu=cpu_summary(), wall_s=result.train_s, train_elapsed_s=round(result.elapsed_s, 1),
        eval_s=round(time.time() - t1, 1), snapshots=snapshots, versions=versions(), git_commit=git_commit(),
        lpips_net=lpips_net, recipe=recipe_of(method_cfg), gpu=gpu_name(result.device),
        views_sha256=final["views_sha256"], views_dir=f"{job.folder}/{VIEWS_DIR}",
        floor_views_sha256=floor["views_sha256"], floor_views_dir=f"{job.folder}/{FLOOR_VIEWS_DIR}",
        masks=masks_digest(job_data_dir(job, data_root))).to_dict()


VIEWS_DIR = "views"         # a training folder's scored test views (recon.view_record), the row's audit
FLOOR_VIEWS_DIR = "floor_views"     # the untrained model's scored views (the row's floor_psnr)


def views_owner(job: Job) -> dict:
    """What a run's kept views belong to, written into views.json and checked by `e4dgs verify`: the
    training folder, the method, the scene folder and the identity digest."""
    return {"run_dir": job.folder, "method": job.method, "data_scene": job.data_scene, "dataset": job.dataset,
            "config_hash": job.config_hash()}


def recipe_of(method_cfg) -> dict:
    """The resolved fields that decide a result, for the tables and a reader of the row (the whole
    config is the run's run.json; its digest is the row's identity.config): iterations, seed, the
    deformation field, the coarse-to-fine schedule and the precision asked for (the row's `precision`
    is what ran)."""
    t = getattr(method_cfg, "train", None)
    if t is None:                         # a plug-in without the shared TrainConfig
        return {}
    c2f = t.coarse_to_fine
    return {"iterations": t.iterations, "seed": t.seed,
            "deform_field": t.deform_field.kind if t.deform else "none",
            "coarse_to_fine": [[f, u] for f, u in zip(c2f.factors, c2f.until)], "precision": t.precision}


def gpu_name(device: str) -> str | None:
    """The GPU's model for a run on CUDA (None on the CPU)."""
    if not str(device).startswith("cuda"):
        return None
    import torch

    return torch.cuda.get_device_name(torch.device(device))


def reused_row(job: Job, row: dict) -> dict:
    """The results row of `job` taken from `row`, a finished job with the same training folder: the
    same config hash, so the same model and the same scores (the blur study's level of the main
    cells, the ablation's full seed-0 run). Nothing is trained or scored twice."""
    return {**row, **job.identity(), "train_elapsed_s": 0.0, "eval_s": 0.0, "scored_as": row["key"]}


def run_folder(jobs: list[Job], cfg: BenchConfig, data_root: Path, out_root: Path, progress: bool,
               method_cfgs: list) -> list[dict]:
    """Train and score the first of `jobs` (which share one training folder; one that needs LPIPS goes
    first), the rest reuse its row."""
    order = sorted(range(len(jobs)), key=lambda i: not wants_lpips(jobs[i], cfg))
    jobs, method_cfgs = [jobs[i] for i in order], [method_cfgs[i] for i in order]
    first = run_job(jobs[0], cfg, data_root, out_root, progress, method_cfg=method_cfgs[0])
    return [first] + [reused_row(job, first) for job in jobs[1:]]


def row_summary(row: dict) -> str:
    lpips = f" LPIPS {row['lpips']:.3f}" if row.get("lpips") is not None else ""
    return f"{row['key']}: PSNR {row['psnr']:.2f} SSIM {row['ssim']:.3f}{lpips}, {row['wall_s']:.0f} s training"


class JobExecutor(Protocol):
    """Runs `todo` (their typed configs in `resolved`, by job key), calling `record(rows)` as each
    training folder's jobs finish; the serial and the Ray executors take the same arguments."""
    def __call__(self, todo: list[Job], resolved: dict, cfg: BenchConfig, data_root: Path, out_root: Path,
                 record: Callable[[list[dict]], None], progress: bool = True,
                 log: Callable[[str], None] = print) -> None: ...


def by_folder(todo: list[Job]) -> dict[str, list[Job]]:
    """Jobs grouped by training folder, in the order their folders first appear (one training each)."""
    groups: dict[str, list[Job]] = {}
    for job in todo:
        groups.setdefault(job.folder, []).append(job)
    return groups


def run_jobs_here(todo: list[Job], resolved: dict, cfg: BenchConfig, data_root: Path, out_root: Path,
                  record: Callable[[list[dict]], None], progress: bool = True,
                  log: Callable[[str], None] = print) -> None:
    """The serial executor: the jobs in this process one after another, in their order; a job whose
    training folder an earlier job of this call trained and scored completely reuses its row. A job
    that fails (a method's error, a plug-in's included) costs only its own cells, as on Ray: its row is
    recorded with status "failed" and the error, the other jobs run, and a later run retries it. A
    kill (KeyboardInterrupt) stops the run; the recorded rows stay and a later run resumes the rest."""
    trained: dict[str, dict] = {}
    failed: dict[str, str] = {}                     # training folder -> its error
    t0 = time.time()
    for n, job in enumerate(todo, 1):
        log(f"bench [{n}/{len(todo)}] {job.key} ({job.method}, {time.time() - t0:.0f} s so far)")
        earlier = trained.get(job.folder)
        if job.folder in failed:
            row = failed_row(job, failed[job.folder])
        elif earlier is not None and complete_row(earlier, job, cfg, data_root):
            row = reused_row(job, earlier)
        else:
            try:
                row = trained[job.folder] = run_job(job, cfg, data_root, out_root, progress, method_cfg=resolved[job.key])
            except Exception as exc:                 # noqa: BLE001 -- one job's failure is its row, not the run's end
                failed[job.folder] = f"{type(exc).__name__}: {exc}"
                row = failed_row(job, failed[job.folder])
        record([row])
        log(f"bench [{n}/{len(todo)}] " + (f"{job.key}: FAILED: {row['error']}" if row.get("status") == "failed"
                                           else row_summary(row)))


def failed_row(job: Job, error: str) -> dict:
    """The results row of a job that failed: its identity, status "failed" and the error (one line)."""
    return {**job.identity(), "status": "failed", "error": " ".join(error.split())[:2000]}
