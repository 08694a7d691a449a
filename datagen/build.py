"""The dataset as a library call: generate a preset's scenes, one worker process per scene (bpy keeps
global state, so each scene renders in its own interpreter), several side by side.

    failed = generate_dataset("quick", ["lego"], Path("data/quick"), jobs=1)   # [] when every scene finished
"""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

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


def generate_dataset(preset: str | Path, scenes: list[str] | None, out: Path, jobs: int = 1,
                     checkpoint_every: int = 100, log: Callable[[str], None] = print) -> list[str]:
    """Generate (or resume, or skip when complete) each scene into out/<scene>; returns the scenes
    whose worker failed. Finished scenes are skipped by their workers, killed ones resume."""
    if jobs < 1 or checkpoint_every < 1:
        raise ValueError(f"jobs and checkpoint_every must be >= 1, got {jobs}, {checkpoint_every}")
    scenes = preset_scenes(preset, scenes)
    log(f"dataset: preset {preset}, {len(scenes)} scene(s) -> {out} ({jobs} at a time)")
    t0 = time.time()
    pending = list(scenes)
    running: list[tuple[str, subprocess.Popen]] = []
    failed: list[str] = []
    while pending or running:
        while pending and len(running) < jobs:
            scene = pending.pop(0)
            cmd = [sys.executable, "-m", "datagen.generate", "--scene", scene, "--preset", str(preset),
                   "--out", str(out), "--checkpoint-every", str(checkpoint_every), "--position", str(len(running))]
            running.append((scene, subprocess.Popen(cmd)))
        for scene, proc in list(running):
            if proc.poll() is not None:
                running.remove((scene, proc))
                if proc.returncode != 0:
                    failed.append(scene)
        time.sleep(0.2)
    log(f"dataset: {len(scenes) - len(failed)} of {len(scenes)} scene(s) done in {time.time() - t0:.0f} s -> {out}")
    return failed
