"""Extra event formats a scene asks for (`formats:` in a scene YAML or a preset's overrides), written
beside the canonical HDF5 after the scene is complete: `<scene>/exports/<format>/cam<k>.<ext>` (one
file per camera), or for ROS `<scene>/exports/<scene>.bag` (ROS1) / `<scene>/exports/<scene>_ros2/`
(every camera as topics with camera info, poses and frames; scene_format.export). Each export is
written whole or not at all, then added to the manifest (`files` with their SHA-256, so `e4dgs check`
verifies them, and `exports`: format -> paths); a scene that gains a format later, or was killed
between its manifest and its exports, gets the missing ones on its next run without being generated
again. The config's fingerprint leaves `formats` out: they change no byte of the scene itself."""
from __future__ import annotations

import json
import time
from pathlib import Path

from common.fileio import sha256_file, write_text_atomic


def export_target(scene_dir: Path, fmt: str) -> Path:
    """Where format `fmt` of the scene goes."""
    if fmt == "rosbag":
        return scene_dir / "exports" / f"{scene_dir.name}.bag"
    if fmt == "rosbag2":
        return scene_dir / "exports" / f"{scene_dir.name}_ros2"
    return scene_dir / "exports" / fmt


def ensure_exports(scene_dir: Path, formats: tuple[str, ...], log=print) -> list[str]:
    """Write the formats of a complete scene (one with its manifest) that its manifest does not list
    yet and list them; returns the formats written."""
    from scene_format.export import export_scene

    manifest_path = scene_dir / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    done = manifest.get("exports", {})
    todo = [f for f in formats if f != "h5" and f not in done]
    for fmt in todo:
        t0 = time.perf_counter()
        target = export_target(scene_dir, fmt)
        target.parent.mkdir(exist_ok=True)
        if target.exists():                 # left by a run killed after the export, before the manifest
            _remove(target)
        paths = export_scene(scene_dir, fmt, target)
        files = sorted(p for q in paths for p in ([q] if q.is_file() else q.rglob("*")) if p.is_file())
        for p in files:
            manifest["files"][p.relative_to(scene_dir).as_posix()] = {"bytes": p.stat().st_size, "sha256": sha256_file(p)}
        done[fmt] = [p.relative_to(scene_dir).as_posix() for p in files]
        manifest["exports"] = done
        manifest.setdefault("seconds", {})["export"] = round(manifest["seconds"].get("export", 0.0)
                                                             + time.perf_counter() - t0, 3)
        write_text_atomic(manifest_path, json.dumps(manifest, indent=1))
        log(f"{scene_dir.name}: wrote {fmt} ({len(files)} file(s) under {target.relative_to(scene_dir)})")
    return todo


def _remove(path: Path) -> None:
    import shutil

    shutil.rmtree(path) if path.is_dir() else path.unlink()
