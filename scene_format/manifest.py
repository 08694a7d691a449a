"""A generated scene folder's manifest.json as typed facts: what the benchmark, the test views and the
viewer read of it (its speed, events, blur levels and masks), so no reader walks the raw JSON with
`.get` chains. The manifest itself is written by datagen.generate; `SceneDataset.facts` is this view
of it (scene_format.reader)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from scene_format.naming import SHUTTER_LEVEL


@dataclass(frozen=True)
class BlurLevelFacts:
    """One blur level as measured: its exposure (rendered frames, real-time ms), the blur length (px:
    median and p90 over every camera, and per camera) and the blurred frames' PSNR against the sharp
    ones (median over frames, dB; None where not measured)."""
    name: str
    n_frames: int
    exposure_ms: float
    median_px: float | None
    p90_px: float | None
    per_camera_median_px: tuple[float | None, ...] = ()
    target_px: float | None = None
    psnr_vs_sharp_db: float | None = None

    @classmethod
    def from_dict(cls, name: str, d: dict[str, Any]) -> "BlurLevelFacts":
        return cls(name, int(d["n_frames"]), float(d["exposure_ms"]), d.get("median_px"), d.get("p90_px"),
                   tuple(c.get("median_px") for c in d.get("per_camera", [])), d.get("target_px"),
                   (d.get("psnr_vs_sharp_db") or {}).get("median_db"))


@dataclass(frozen=True)
class SceneManifest:
    """speed: the folder's time compression (1.0 for a scene; its factor for a speed variant);
    events_per_second_per_camera: one figure per camera; blur: level name -> its facts, in the
    manifest's order; has_masks: the folder holds dynamic-region masks (generated with them, or added
    by `e4dgs masks`)."""
    scene: str
    speed: float
    events_per_camera: tuple[int, ...]
    events_per_second_per_camera: tuple[float, ...]
    blur: dict[str, BlurLevelFacts] = field(default_factory=dict)
    has_masks: bool = False

    @classmethod
    def from_dict(cls, m: dict[str, Any], scene_dir: Path) -> "SceneManifest":
        levels = (m.get("blur") or {}).get("levels") or {}
        return cls(scene=m.get("scene", scene_dir.name), speed=float((m.get("speed") or {}).get("factor", 1.0)),
                   events_per_camera=tuple((m.get("counts") or {}).get("events_per_camera") or ()),
                   events_per_second_per_camera=tuple(m.get("events_per_second_per_camera") or ()),
                   blur={name: BlurLevelFacts.from_dict(name, d) for name, d in levels.items()},
                   has_masks=(scene_dir / "dynamic" / "masks.json").exists())

    @property
    def shutter(self) -> BlurLevelFacts | None:
        """A speed variant's fixed shutter (its one blur level); None for a scene."""
        return self.blur.get(SHUTTER_LEVEL)

    @property
    def mean_events_per_second(self) -> float:
        """Events per second per camera, the mean over cameras (0 where none were counted)."""
        rates = self.events_per_second_per_camera or (0,)
        return sum(rates) / len(rates)


# Files a scene folder may gain after generation that no method trains on: dynamic-region masks
# (`e4dgs masks`) are a scoring aid, so adding them does not make the scene another dataset.
NOT_TRAINED_ON = ("dynamic/",)


def content_digest(manifest: dict[str, Any]) -> str:
    """SHA-256 of what a scene folder holds: every file's digest (the manifest's `files`, masks left
    out: NOT_TRAINED_ON), the format version, the scene config's digest and the generation seed; not
    when or how fast it was generated. Two folders with the same digest train the same model."""
    import hashlib
    import json

    files = {k: v for k, v in (manifest.get("files") or {}).items() if not k.startswith(NOT_TRAINED_ON)}
    payload = {"files": files, **{k: manifest.get(k) for k in ("format_version", "config_sha256", "seed")}}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def folder_digest(scene_dir: Path) -> str:
    """content_digest of a scene folder as it is on disk: the manifest's facts with every listed file's
    digest taken from the file itself (common.fileio.sha256_files_cached), not from the manifest, so a
    file copied over another (events from elsewhere, say) makes the folder another dataset even when
    the manifest was left as it was. "absent" where the folder has no manifest yet (not generated),
    "unreadable" where it is not a JSON manifest, "missing <file>" where a listed file is not there."""
    import json

    from common.fileio import sha256_files_cached

    scene_dir = Path(scene_dir)
    path = scene_dir / "manifest.json"
    try:
        manifest = json.loads(path.read_bytes())
        files = manifest.get("files") or {}
        if not isinstance(files, dict):
            return "unreadable"
    except FileNotFoundError:
        return "absent"
    except (ValueError, AttributeError):
        return "unreadable"
    names = sorted(n for n in files if not n.startswith(NOT_TRAINED_ON))
    missing = next((n for n in names if not (scene_dir / n).is_file()), None)
    if missing is not None:
        return f"missing {missing}"
    on_disk = dict(zip(names, sha256_files_cached([scene_dir / n for n in names])))
    return content_digest({**manifest, "files": on_disk})


def masks_digest(scene_dir: Path) -> str:
    """SHA-256 of a scene folder's dynamic-region masks as they are on disk (dynamic/: the masks and
    masks.json, whose threshold says how they were made); "none" where the folder has none. The
    scores over moving pixels are computed with them, so a row holds the digest it was scored with."""
    import hashlib

    from common.fileio import sha256_files_cached

    folder = Path(scene_dir) / NOT_TRAINED_ON[0]
    files = sorted(p for p in folder.rglob("*") if p.is_file()) if folder.is_dir() else []
    if not files:
        return "none"
    h = hashlib.sha256()
    for p, digest in zip(files, sha256_files_cached(files)):
        h.update(p.relative_to(folder).as_posix().encode() + b"\0" + digest.encode() + b"\0")
    return h.hexdigest()[:16]
