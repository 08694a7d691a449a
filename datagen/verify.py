"""`e4dgs check`: verify a generated scene (or every scene under a dataset root) against its
manifest: each listed file exists with the recorded size and SHA-256, and each event file passes
the readers' content checks (simulator.event_check).

    problems = verify_scene(Path("data/quick/lego"))     # [] when everything matches
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

from common.fileio import sha256_file
from simulator.h5io import EventFileError, read_info


def scene_dirs(path: Path) -> list[Path]:
    """`path` itself if it holds a manifest, else its sub-folders that do (sorted); [] if none."""
    if (path / "manifest.json").is_file():
        return [path]
    if not path.is_dir():
        return []
    return sorted(p for p in path.iterdir() if (p / "manifest.json").is_file())


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
    return problems
