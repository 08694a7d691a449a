"""`e4dgs check`: verify a generated scene (or every scene under a dataset root) against its
manifest: each listed file exists with the recorded size and SHA-256, each event file passes the
readers' content checks (eventio.event_check), and each ground-truth map, event-label file and
exported event file is what its place says (a manifest re-signed over a wrong file fails).

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
    hw = _sensor_size(scene_dir)          # the cameras' size, read once for every map's check
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
        else:
            problem = content_problem(scene_dir, rel, path, hw)
            if problem:
                problems.append(problem)
    return problems + count_problems(scene_dir, manifest)


def _sensor_size(scene_dir: Path) -> tuple[int, int] | None:
    """(height, width) of the scene's cameras, from its first event file; None if unreadable."""
    try:
        info = read_info(scene_dir / "events" / "cam0.h5")
        return int(info["height"]), int(info["width"])
    except (EventFileError, OSError, KeyError, ValueError):
        return None


def content_problem(scene_dir: Path, rel: str, path: Path, hw: tuple[int, int] | None) -> str | None:
    """What is wrong with the content of a listed file whose hash matches (a manifest re-signed over a
    wrong file): ground-truth maps of the sensor's size and type, one event label per event, and
    exported event files that read as event files (hw: the cameras' (height, width), None when
    unknown). None when it is what its place says."""
    import numpy as np

    parts = rel.split("/")
    try:
        if parts[0] == "ground_truth" and len(parts) == 4 and parts[1] in ("flow", "ids", "depth", "normals", "velocity"):
            kind, suffix = parts[1], path.suffix.lower()
            if suffix == ".png":
                import cv2

                img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
                channels = 3 if kind == "flow" else 1
                if img is None or img.dtype != np.uint16 or (img.shape[2] if img.ndim == 3 else 1) != channels:
                    return (f"{path}: not a 16-bit {channels}-channel PNG (a ground-truth {kind} map; "
                            f"got {'an unreadable file' if img is None else f'{img.dtype}, shape {img.shape}'})")
                if hw is not None and img.shape[:2] != hw:
                    return f"{path}: {img.shape[1]}x{img.shape[0]} pixels, the scene's cameras {hw[1]}x{hw[0]}"
            elif suffix == ".exr":
                from common.imageio import read_exr

                img = read_exr(path)
                if hw is not None and img.shape[:2] != hw or not np.isfinite(img).all():
                    return f"{path}: not a finite {kind} map of the cameras' size (shape {img.shape})"
            elif suffix == ".npz":
                from common.flow import read_flow

                flow, _ = read_flow(path)
                if hw is not None and flow.shape[:2] != hw:
                    return f"{path}: {flow.shape[1]}x{flow.shape[0]} pixels, the scene's cameras {hw[1]}x{hw[0]}"
        elif parts[0] == "ground_truth" and parts[1] == "event_ids" and len(parts) == 3:
            labels = np.load(path, mmap_mode="r", allow_pickle=False)
            n = int(read_info(scene_dir / "events" / parts[2].replace(".npy", ".h5"))["n_events"])
            if labels.ndim != 1 or len(labels) != n:
                return f"{path}: {len(labels)} labels for {n} events in events/{parts[2].replace('.npy', '.h5')}"
        elif parts[0] == "exports" and path.suffix.lower() in (".aedat4", ".raw", ".bag", ".npz", ".txt", ".mcap", ".db3"):
            from eventio.formats import detect_format

            if path.suffix.lower() not in (".mcap", ".db3"):     # a ROS2 bag is checked as its folder's parts
                found = detect_format(path)
                expected = parts[1] if len(parts) == 3 else "rosbag"
                if found != expected:
                    return f"{path}: holds {found}, not the {expected} events its folder says"
                if found == "txt":                              # E2VID text: a "width height" first line
                    with open(path) as fh:
                        head = fh.readline().split()
                    if len(head) != 2 or not all(v.isdigit() for v in head):
                        return f"{path}: not an E2VID event text file (its first line is not 'width height')"
    except (OSError, ValueError, KeyError, EventFileError) as exc:
        return f"{path}: {' '.join(str(exc).split())}"
    return None


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
