"""`e4dgs dataset`: generate a preset's scenes, one process per scene, several side by side."""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

from e4dgs.argtypes import positive_int


def add_dataset_parser(sub) -> None:
    p = sub.add_parser("dataset", help="generate the synthetic multi-view event dataset (Blender + simulator)",
                       description="Render, simulate and write every scene of a preset. Each scene runs in its own "
                                   "process; finished scenes are skipped and killed ones resume.")
    p.add_argument("--preset", default="quick", help="quick | paper | tiny, or a preset YAML file (default quick)")
    p.add_argument("--scenes", default=None, help="comma-separated subset of the preset's scenes")
    p.add_argument("--out", type=Path, default=None, help="dataset root (default data/<preset>)")
    p.add_argument("--jobs", type=positive_int, default=1, help="scenes generated side by side (default 1)")
    p.add_argument("--checkpoint-every", type=positive_int, default=100, metavar="N", help="timestamps between checkpoints")
    p.set_defaults(func=run_dataset)


def run_dataset(args: argparse.Namespace) -> int:
    from datagen.config import load_preset
    from e4dgs.config import ConfigError

    try:
        preset = load_preset(args.preset)
    except ConfigError as exc:
        raise SystemExit(f"error: {exc}") from None
    scenes = list(preset.scenes)
    if args.scenes:
        wanted = [s.strip() for s in args.scenes.split(",") if s.strip()]
        unknown = [s for s in wanted if s not in scenes]
        if unknown:
            raise SystemExit(f"error: --scenes: {', '.join(unknown)} not in preset {args.preset!r} "
                             f"(it has {', '.join(scenes)})")
        scenes = wanted
    out = args.out or Path("data") / Path(str(args.preset)).stem.removeprefix("dataset_")
    print(f"dataset: preset {args.preset}, {len(scenes)} scene(s) -> {out} ({args.jobs} at a time)")
    t0 = time.time()
    pending = list(enumerate(scenes))
    running: list[tuple[str, subprocess.Popen]] = []
    failed = []
    while pending or running:
        while pending and len(running) < args.jobs:
            slot, scene = pending.pop(0)
            cmd = [sys.executable, "-m", "datagen.generate", "--scene", scene, "--preset", str(args.preset),
                   "--out", str(out), "--checkpoint-every", str(args.checkpoint_every), "--position", str(len(running))]
            running.append((scene, subprocess.Popen(cmd)))
        for scene, proc in list(running):
            if proc.poll() is not None:
                running.remove((scene, proc))
                if proc.returncode != 0:
                    failed.append(scene)
        time.sleep(0.2)
    print(f"dataset: {len(scenes) - len(failed)} of {len(scenes)} scene(s) done in {time.time() - t0:.0f} s -> {out}")
    done = [s for s in scenes if s not in failed]
    if done and out.is_dir():
        from datagen.summary import blur_table

        print("\nblur levels (median blur length over geometry; PSNR of blurred vs sharp frames):\n" + blur_table(out, done))
    if failed:
        print(f"dataset: failed: {', '.join(failed)} (run again to resume them)", file=sys.stderr)
        return 1
    return 0


def add_check_parser(sub) -> None:
    p = sub.add_parser("check", help="verify a dataset against its manifests (sizes, SHA-256, event files)",
                       description="Check every file a scene's manifest.json lists: present, same size and SHA-256, "
                                   "and event files readable and well-formed. Exit status 1 if anything differs.")
    p.add_argument("path", type=Path, help="a scene folder, or a dataset root holding scene folders")
    p.set_defaults(func=run_check)


def run_check(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from datagen.verify import scene_dirs, verify_scene

    scenes = scene_dirs(args.path)
    if not scenes:
        raise SystemExit(f"error: {args.path}: no manifest.json in it or in its sub-folders (not a generated dataset)")
    failed = 0
    for d in scenes:
        try:
            n = len(json.loads((d / "manifest.json").read_text()).get("files", {}))
        except ValueError:
            n = 0
        with tqdm(total=n, desc=f"check {d.name}", unit="file", leave=False) as bar:
            problems = verify_scene(d, progress=lambda _: bar.update(1))
        if problems:
            failed += 1
            print(f"{d}: {len(problems)} problem(s)")
            for line in problems:
                print(f"  {line}")
        else:
            print(f"{d}: OK ({n} files match the manifest)")
    return 1 if failed else 0
