"""The dataset as a library call: generate a preset's scenes, one worker process per scene (bpy keeps
global state, so each scene renders in its own interpreter), several side by side.

    failed = generate_dataset("quick", ["lego"], Path("data/quick"), jobs=1)   # [] when every scene finished
    failed = generate_dataset("quick", None, Path("/shared/data/quick"), ray=RayOptions("auto"))  # on a cluster
    failed = generate_dataset("quick", ["walker"], out, scene_args={"walker": ["--scene", "walker", "--scene-config", "walker.yaml"]})

With `ray` (a common.taskpool.RayOptions) each scene is a Ray task that runs the same worker process on
whichever node Ray picks; `out` must then be a path every node sees (a shared file system). A task
whose worker dies is retried (the scene resumes from its checkpoint); one that refuses its input
(exits with an error status) is not, and its error line is reported as the plain path prints it;
the worker's output goes to out/logs/<scene>.log, Ray's own messages to out/logs/ray.log.
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

from common.taskpool import die_with_parent
from datagen.config import load_preset


def preset_scenes(preset: str | Path, wanted: list[str] | None = None) -> list[str]:
    """The preset's scenes, or the subset `wanted` (ValueError naming the unknown ones)."""
    scenes = list(load_preset(preset).scenes)
    if wanted:
        unknown = [s for s in wanted if s not in scenes]
        if unknown:
            raise ValueError(f"--scenes: {', '.join(unknown)} not in preset {str(preset)!r} (it has {', '.join(scenes)})")
        return list(wanted)
    return scenes


def _worker_cmd(preset: str | Path, scene: str, out: Path, checkpoint_every: int,
                extra: list[str] | None = None) -> list[str]:
    """The worker's command line; `extra` replaces `--scene NAME` for scenes from files
    (["--scene-file", F, "--kind", K]) or adds a scene YAML (["--scene", NAME, "--scene-config", Y])."""
    head = list(extra) if extra else ["--scene", scene]
    return [sys.executable, "-m", "datagen.generate", *head, "--preset", str(preset),
            "--out", str(out), "--checkpoint-every", str(checkpoint_every)]


def generate_scene_task(preset: str | Path, scene: str, out: Path, checkpoint_every: int,
                        extra: list[str] | None = None) -> str:
    """A Ray task: one scene's worker process, its output into the task's log; raises if it fails."""
    from common.taskpool import child_env

    proc = subprocess.run(_worker_cmd(preset, scene, out, checkpoint_every, extra) + ["--no-progress"],
                          stdout=sys.stdout, stderr=subprocess.PIPE, text=True, env=child_env(),
                          preexec_fn=die_with_parent)
    sys.stderr.write(proc.stderr)                       # into the task's log, as the plain path shows it
    if proc.returncode != 0:
        said = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
        line = next((ln for ln in reversed(said) if ln.startswith("error:")), said[-1] if said else "")
        if crashed(proc.returncode):                    # a crash: Ray runs it again, from its checkpoint
            raise RuntimeError(f"scene {scene}: worker died from signal {-proc.returncode}")
        # its own error status: a refusal of the input, the same on every attempt (not retried)
        raise ValueError(f"scene {scene}: {line.removeprefix('error: ') or f'worker exited with status {proc.returncode}'}")
    return scene


def _absolute_paths(extra: list[str]) -> list[str]:
    """Worker arguments with the file paths made absolute (a Ray worker runs in another folder)."""
    return [str(Path(a).resolve()) if i and extra[i - 1] in ("--scene-file", "--scene-config") else a
            for i, a in enumerate(extra)]


def _generate_on_ray(preset, scenes: list[str], out: Path, checkpoint_every: int, ray,
                     log: Callable[[str], None], scene_args: dict[str, list[str]]) -> list[str]:
    from common.taskpool import TaskSpec, run_tasks

    out = Path(out).resolve()                                   # workers may run in another folder or node
    preset = Path(preset).resolve() if Path(preset).suffix in (".yaml", ".yml") else preset
    specs = [TaskSpec(s, generate_scene_task, (str(preset), s, out, checkpoint_every,
                                               _absolute_paths(scene_args.get(s, []))),
                      num_cpus=ray.cpus_per_task, log_path=out / "logs" / f"{s}.log") for s in scenes]
    failed: list[str] = []

    def done(outcome) -> None:
        if not outcome.ok:
            failed.append(outcome.key)
            log(f"dataset: {outcome.key} failed: {outcome.error} (log: {out / 'logs' / (outcome.key + '.log')})")

    run_tasks(specs, ray, done, desc="dataset")
    return failed


def crashed(returncode: int) -> bool:
    """A worker that died from a signal (a crash: SIGABRT from a corrupted heap, SIGSEGV, the OOM
    killer's SIGKILL), as opposed to one that exited with its own error status (bad input, which
    would fail again)."""
    return returncode < 0


def generate_dataset(preset: str | Path, scenes: list[str] | None, out: Path, jobs: int = 1,
                     checkpoint_every: int = 100, log: Callable[[str], None] = print, ray=None,
                     scene_args: dict[str, list[str]] | None = None, retries: int = 2) -> list[str]:
    """Generate (or resume, or skip when complete) each scene into out/<scene>; returns the scenes
    whose worker failed. Finished scenes are skipped by their workers, killed ones resume. `jobs`
    scenes run side by side here, or every scene as a Ray task when `ray` is given (ray.retries
    re-runs). Here a worker that crashes is started again `retries` times, resuming from the scene's
    last checkpoint; one that exits with an error status is not. `scene_args` gives scenes that are
    not the preset's (from a user's file or scene YAML) their worker arguments (see _worker_cmd); the
    preset then only supplies the render settings."""
    if jobs < 1 or checkpoint_every < 1 or retries < 0:
        raise ValueError(f"jobs and checkpoint_every must be >= 1 and retries >= 0, got {jobs}, {checkpoint_every}, {retries}")
    scene_args = dict(scene_args or {})
    if scene_args:
        scenes = list(scenes or scene_args)
        if missing := [s for s in scenes if s not in scene_args]:
            raise ValueError(f"scene_args: no worker arguments for {', '.join(missing)}")
    else:
        scenes = preset_scenes(preset, scenes)
    if ray is not None:
        log(f"dataset: preset {preset}, {len(scenes)} scene(s) -> {out} as Ray tasks "
            f"({ray.cpus_per_task:g} CPU each, {ray.retries} retries)")
        t0 = time.time()
        failed = _generate_on_ray(preset, scenes, out, checkpoint_every, ray, log, scene_args)
        log(f"dataset: {len(scenes) - len(failed)} of {len(scenes)} scene(s) done in {time.time() - t0:.0f} s -> {out}")
        return failed
    log(f"dataset: preset {preset}, {len(scenes)} scene(s) -> {out} ({jobs} at a time)")
    t0 = time.time()
    pending = list(scenes)
    running: list[tuple[str, subprocess.Popen]] = []
    failed: list[str] = []
    restarts = {s: 0 for s in scenes}
    while pending or running:
        while pending and len(running) < jobs:
            scene = pending.pop(0)
            cmd = _worker_cmd(preset, scene, out, checkpoint_every, scene_args.get(scene)) + [
                "--position", str(len(running))]
            running.append((scene, subprocess.Popen(cmd, preexec_fn=die_with_parent)))
        for scene, proc in list(running):
            if proc.poll() is not None:
                running.remove((scene, proc))
                if proc.returncode == 0:
                    continue
                if crashed(proc.returncode) and restarts[scene] < retries:
                    restarts[scene] += 1
                    log(f"dataset: {scene}: worker died from signal {-proc.returncode}; starting it again from "
                        f"its last checkpoint (restart {restarts[scene]} of {retries})")
                    pending.insert(0, scene)
                else:
                    failed.append(scene)
        time.sleep(0.2)
    log(f"dataset: {len(scenes) - len(failed)} of {len(scenes)} scene(s) done in {time.time() - t0:.0f} s -> {out}")
    return failed
