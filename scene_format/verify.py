"""`e4dgs check`: verify a generated scene (or every scene under a dataset root) against its
manifest: each listed file exists with the recorded size and SHA-256, and each event file passes
the readers' content checks (eventio.event_check).

    problems = verify_scene(Path("data/quick/lego"))     # [] when everything matches
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

from common.fileio import sha256_file
from eventio.h5io import EventFileError, read_info


def scene_dirs(path: Path) -> list[Path]:
    """`path` itself if it holds a manifest, else its sub-folders that do (sorted); [] if none."""
    if (path / "manifest.json").is_file():
        return [path]
    if not path.is_dir():
        return []
    return sorted(p for p in path.iterdir() if (p / "manifest.json").is_file())


SCENE_MARKS = ("scene.yaml", "cameras.json", "events", "frames", "blur")   # what a generation writes first


def other_dirs(path: Path) -> tuple[list[Path], list[Path]]:
    """The sub-folders of a dataset root without a manifest: (unfinished: holding what a scene
    generation writes, so a scene whose generation has not finished; others: not scene folders)."""
    if (path / "manifest.json").is_file() or not path.is_dir():
        return [], []
    rest = sorted(p for p in path.iterdir() if p.is_dir() and not p.name.startswith(".")
                  and not (p / "manifest.json").is_file())
    unfinished = [p for p in rest if any((p / m).exists() for m in SCENE_MARKS)]
    return unfinished, [p for p in rest if p not in unfinished]


def verify_scene(scene_dir: Path, progress: Callable[[str], None] | None = None) -> list[str]:
    """Problems found in one scene (each names the file and what differs); [] when it matches."""
    manifest_path = scene_dir / "manifest.json"
    try:
        manifest = json.loads(manifest_path.read_text())
        files = manifest["files"]
        if not isinstance(files, dict):
            raise TypeError
    except (OSError, ValueError, KeyError, TypeError):
        return [f"{manifest_path}: not a readable manifest with a 'files' table"]
    problems = []
    for rel, rec in sorted(files.items()):
        path = scene_dir / rel
        if progress:
            progress(rel)
        if not path.is_file():
            problems.append(f"{path}: missing (listed in {manifest_path})")
            continue
        size = path.stat().st_size
        if size != rec.get("bytes"):
            problems.append(f"{path}: {size} bytes, the manifest records {rec.get('bytes')}")
            continue
        if sha256_file(path) != rec.get("sha256"):
            problems.append(f"{path}: SHA-256 differs from the manifest's (the file was modified or corrupted)")
            continue
        if path.suffix == ".h5":
            try:
                read_info(path)
            except EventFileError as exc:
                problems.append(str(exc))
    return problems + count_problems(scene_dir, manifest)


def unlisted_files(scene_dir: Path) -> list[str]:
    """Files in a scene folder its manifest does not list (added after generation; not verified)."""
    try:
        listed = set(json.loads((scene_dir / "manifest.json").read_text())["files"]) | {"manifest.json"}
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return sorted(rel for rel in (p.relative_to(scene_dir).as_posix() for p in scene_dir.rglob("*") if p.is_file())
                  if rel not in listed and not rel.split("/")[-1].startswith("."))


def count_problems(scene_dir: Path, manifest: dict) -> list[str]:
    """The manifest's own figures against the files: cameras, rendered timestamps, kept frames and
    events per camera (an edited manifest is otherwise believed by everything that reads it)."""
    where = scene_dir / "manifest.json"
    counts = manifest.get("counts")
    if not isinstance(counts, dict):
        return [f"{where}: no 'counts' table"]
    problems = []
    n_cams = len(sorted((scene_dir / "events").glob("cam*.h5")))
    if counts.get("cameras") != n_cams:
        problems.append(f"{where}: counts.cameras is {counts.get('cameras')!r}, the scene has {n_cams} event files")
    try:
        cams = json.loads((scene_dir / "cameras.json").read_text())["cameras"]
        n_ts = len(cams[0]["timestamps_us"])
        if counts.get("timestamps") != n_ts:
            problems.append(f"{where}: counts.timestamps is {counts.get('timestamps')!r}, cameras.json has {n_ts}")
    except (OSError, ValueError, KeyError, IndexError):
        problems.append(f"{scene_dir / 'cameras.json'}: not a readable camera file")
    for k in range(n_cams):
        kept = len(list((scene_dir / "rgb" / f"cam{k}").glob("*.png")))
        if counts.get("kept_frames_per_camera") != kept:
            problems.append(f"{where}: counts.kept_frames_per_camera is {counts.get('kept_frames_per_camera')!r}, "
                            f"rgb/cam{k} has {kept} frames")
            break
    recorded = counts.get("events_per_camera") or []
    for k in range(n_cams):
        try:
            n = int(read_info(scene_dir / "events" / f"cam{k}.h5")["n_events"])
        except EventFileError:
            continue                                      # reported above
        if k >= len(recorded) or recorded[k] != n:
            problems.append(f"{where}: counts.events_per_camera[{k}] is "
                            f"{recorded[k] if k < len(recorded) else 'missing'}, events/cam{k}.h5 holds {n}")
    return problems
