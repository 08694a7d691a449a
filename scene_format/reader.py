"""Read a generated scene folder (no bpy): config, camera trajectories, frame lists, masks, event files.

This is the boundary every reader of a scene goes through (recon, benchmark, viewer); reconstruction
reads the scene's config as a `SceneDescription`, the few facts it needs, not the generator's whole
`SceneConfig`. Images are returned as float32 in
[0, 1], sRGB-encoded as stored (metrics are computed on these); linear frames come from `frames/`.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from scene_format.cameras import CameraTrajectory, load_cameras
from scene_format.manifest import SceneManifest
from scene_format.config import SceneConfig, read_scene_config


class DatasetError(ValueError):
    """A scene folder is missing, incomplete or inconsistent."""


@dataclass(frozen=True)
class SceneDescription:
    """What reconstruction knows of a scene besides its frames and events (from its scene.yaml)."""
    name: str
    kind: str                                      # "object" (cameras around it) | "room" (cameras inside)
    background_linear: tuple[float, float, float]  # linear RGB of the empty background (colour x exposure, clipped)
    rig_target: tuple[float, float, float]         # world point the cameras look at, metres
    rig_radius_m: float                            # the rig's distance from the target
    blur_levels: tuple[str, ...]                   # blur level names, weakest first

    @classmethod
    def of(cls, cfg: SceneConfig) -> "SceneDescription":
        light = cfg.lighting
        bg = np.clip(np.asarray(light.background, np.float64) * light.exposure, 0, 1)
        return cls(cfg.name, cfg.kind, tuple(float(c) for c in bg), tuple(float(c) for c in cfg.camera.target),
                   float(cfg.camera.radius), tuple(cfg.blur.levels))


def mask_path(scene_dir: Path, camera: int, index: int) -> Path:
    """A test view's dynamic-region mask: <scene>/dynamic/cam<k>/<index>.png (255 = dynamic)."""
    return Path(scene_dir) / "dynamic" / f"cam{camera}" / f"{index:05d}.png"


@dataclass(frozen=True)
class FrameRecord:
    camera: int
    index: int
    t_us: int
    time: float          # normalised clip time in [0, 1]
    path: Path           # sRGB PNG (sharp RGB, or a blurred frame)
    gray_path: Path | None = None
    exposure_us: tuple[int, int] | None = None   # first and last rendered frame of a blurred frame

    @property
    def stem(self) -> str:
        """cam<k>/<index>: the frame's name in rgb/, gray/, and the name its render must have for `e4dgs score`."""
        return f"cam{self.camera}/{self.index:05d}"


@dataclass(frozen=True)
class GroundTruth:
    """One kept frame's per-pixel ground truth (what the scene's `ground_truth` asked for; None where
    absent). Conventions: the manifest's `ground_truth.conventions`, docs/reference/dataset_layout.md."""
    camera: int
    index: int
    t_us: int                                  # the kept frame's time (cameras.json's clock); pose(camera, t_us)
    depth_m: np.ndarray | None = None          # float32 [H, W] z-depth, metres; 0 = no surface
    normals: np.ndarray | None = None          # float32 [H, W, 3] unit, camera frame (OpenCV); 0 = no surface
    ids: np.ndarray | None = None              # uint16 [H, W] 1 + part index (objects()); 0 = no surface
    flow_px: np.ndarray | None = None          # float32 [H, W, 2] to kept frame index + 1 (None for the last)
    flow_valid: np.ndarray | None = None       # bool [H, W]
    flow_occluded: np.ndarray | None = None    # bool [H, W]
    velocity_px_per_ms: np.ndarray | None = None   # float32 [H, W, 2] image velocity at the frame


def read_json(path: Path, raw: bytes | None = None):
    """A dataset's JSON file (or its bytes `raw`, already read); a missing or malformed one is a
    DatasetError naming it."""
    try:
        return json.loads(path.read_text() if raw is None else raw)
    except FileNotFoundError:
        raise DatasetError(f"{path}: missing (the scene is incomplete; `e4dgs check` lists what differs)") from None
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{path}: not valid JSON ({exc}); the file is damaged (`e4dgs check` verifies the scene)") from None


# the fields of a transforms file's frame and what each must be
_FRAME_FIELDS = {"camera": (int, "a camera index"), "index": (int, "a kept-frame index"),
                 "timestamp_us": (int, "microseconds"), "time": ((int, float), "a time in [0, 1]"),
                 "file_path": (str, "a frame path")}


def _checked_frames(path: Path, doc, n_cameras: int) -> list[dict]:
    """A transforms file's frames, each with its fields of the right type; DatasetError naming the
    file, the frame and the field otherwise (a hand-edited file must not end in a TypeError)."""
    frames = doc.get("frames") if isinstance(doc, dict) else None
    if not isinstance(frames, list):
        raise DatasetError(f"{path}: frames: expected a list of frames, got {type(frames).__name__}")
    for i, f in enumerate(frames):
        if not isinstance(f, dict):
            raise DatasetError(f"{path}: frames[{i}]: expected a mapping of its fields, got {type(f).__name__}")
        for key, (kind, what) in _FRAME_FIELDS.items():
            v = f.get(key)
            if v is None or isinstance(v, bool) or not isinstance(v, kind):
                raise DatasetError(f"{path}: frames[{i}].{key}: expected {what}, got {v!r}")
        if not 0 <= f["camera"] < n_cameras:
            raise DatasetError(f"{path}: frames[{i}].camera: {f['camera']} is not one of the scene's {n_cameras} cameras")
        if "gray_path" in f and not isinstance(f["gray_path"], str):
            raise DatasetError(f"{path}: frames[{i}].gray_path: expected a frame path, got {f['gray_path']!r}")
    return frames


class SceneDataset:
    def __init__(self, scene_dir: str | Path):
        self.dir = Path(scene_dir)
        if not self.dir.is_dir():
            raise DatasetError(f"{self.dir}: no such scene folder (expected a generated scene, e.g. data/quick/lego)")
        if not (self.dir / "manifest.json").exists():
            raise DatasetError(f"{self.dir}: no manifest.json: not a generated scene, or its generation has not "
                               "finished (run `e4dgs dataset` again to resume it)")
        self.manifest_bytes = (self.dir / "manifest.json").read_bytes()    # read once: its digest is a run's input
        self.manifest = read_json(self.dir / "manifest.json", self.manifest_bytes)
        self.config: SceneConfig = read_scene_config(self.dir / "scene.yaml")
        self.scene = SceneDescription.of(self.config)
        self.cameras: list[CameraTrajectory] = load_cameras(self.dir / "cameras.json")
        self.intrinsics = self.cameras[0].intrinsics
        self.duration_us = int(self.cameras[0].times_us[-1])

    @property
    def n_cameras(self) -> int:
        return len(self.cameras)

    @property
    def facts(self) -> SceneManifest:
        """The manifest as typed facts (speed, events, blur levels, masks): scene_format.manifest."""
        return SceneManifest.from_dict(self.manifest, self.dir)

    def _read_transforms(self, path: Path, blur: dict | None = None) -> list[FrameRecord]:
        if not path.exists():
            raise DatasetError(f"{path}: missing")
        frames = []
        for f in _checked_frames(path, read_json(path), self.n_cameras):
            gray = self._frame_path(path, f["gray_path"]) if "gray_path" in f else None
            exposure = blur.get((f["camera"], f["index"])) if blur else None
            frames.append(FrameRecord(f["camera"], f["index"], int(f["timestamp_us"]), float(f["time"]),
                                      self._frame_path(path, f["file_path"]), gray, exposure))
        return frames

    def _frame_path(self, transforms: Path, file_path: str) -> Path:
        """A frame's PNG: file_path is relative to the transforms file's folder (as D-NeRF style loaders
        read it); scenes written before blur levels followed that gave it relative to the scene folder."""
        p = Path(os.path.normpath(transforms.parent / (file_path + ".png")))
        if p.exists() or transforms.parent == self.dir:
            return p
        old = self.dir / (file_path + ".png")
        return old if old.exists() else p

    def frames(self, split: str) -> list[FrameRecord]:
        """Sharp frames of split 'train' or 'test' (every test_every-th kept timestamp per camera)."""
        if split not in ("train", "test"):
            raise ValueError(f"split must be 'train' or 'test', got {split!r}")
        return self._read_transforms(self.dir / f"transforms_{split}.json")

    def blur_levels(self) -> list[str]:
        """Blur level names from the weakest to the strongest."""
        return list(self.scene.blur_levels)

    def blurred_frames(self, level: str) -> list[FrameRecord]:
        """Training frames of a blur level; their t_us / time is the exposure centre."""
        if level not in self.scene.blur_levels:
            raise DatasetError(f"{self.dir}: no blur level {level!r} (have: {', '.join(self.blur_levels()) or 'none'})")
        exposures = read_json(self.dir / "blur" / level / "exposures.json")
        spans = {(e["camera"], e["index"]): (e["first_frame_us"], e["last_frame_us"]) for e in exposures}
        return self._read_transforms(self.dir / "blur" / level / "transforms_train.json", spans)

    def dynamic_mask(self, rec: FrameRecord) -> np.ndarray | None:
        """bool [H, W]: the test view's pixels whose surface moves (datagen.dynamic); None when the scene
        has no masks."""
        p = mask_path(self.dir, rec.camera, rec.index)
        if not (self.dir / "dynamic" / "masks.json").exists():      # written last: the masks are complete
            return None
        m = cv2.imread(str(p), cv2.IMREAD_UNCHANGED) if p.exists() else None
        if m is None or m.ndim != 2:
            raise DatasetError(f"{p}: missing or not a single-channel mask image (`e4dgs masks --force` writes it again)")
        return m > 127

    def _index(self, what: str, value, count: int, where: str) -> int:
        """An integer index 0 .. count - 1 (bools and floats are not indices), else DatasetError."""
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) < count:
            raise DatasetError(f"{self.dir}: {where}: {what} {value!r}: expected an integer 0 to {count - 1}")
        return int(value)

    def event_file(self, camera: int) -> Path:
        """The event file of a camera (DatasetError for a camera the scene does not have)."""
        return self.dir / "events" / f"cam{self._index('camera', camera, self.n_cameras, 'event file')}.h5"

    @property
    def kept_times_us(self) -> np.ndarray:
        """int64 [J]: the time of each kept frame (rgb/, frames/, the test views and the ground truth's
        frame index j), every `frames.keep_every`-th rendered timestamp."""
        return self.cameras[0].times_us[::self.config.frames.keep_every].astype(np.int64)

    @property
    def ground_truth_kinds(self) -> tuple[str, ...]:
        """Which per-pixel ground truth the scene holds (depth, flow, normals, ids); () for none."""
        return tuple((self.manifest.get("ground_truth") or {}).get("kinds", ()))

    def objects(self) -> dict[int, str]:
        """{object id: part name} of the ids ground truth (0, no surface, is not listed)."""
        gt = self.manifest.get("ground_truth") or {}
        return {int(k): v for k, v in gt.get("objects", {}).items()}

    def joined_parts(self) -> dict[int, list[str]]:
        """{object id: the scene parts it holds} for objects the renderer joined (static parts that
        share a parent are one object, named after its first part: a room's "floor" is its whole
        static shell and fixtures)."""
        gt = self.manifest.get("ground_truth") or {}
        return {int(k): list(v) for k, v in gt.get("joined", {}).items()}

    def ground_truth(self, camera: int, index: int) -> GroundTruth:
        """Kept frame `index` of `camera`'s ground truth as typed arrays. DatasetError when the scene
        has none, when the camera or frame is not an integer index of the scene's (bools and floats
        are not indices), and when a file the scene's ground truth holds is missing or unreadable: a
        missing file is an error naming it, never an absent map. Every kind the manifest lists is
        read; a flow exists for every kept frame but the last, a velocity for every kept frame."""
        from common.imageio import read_exr

        kinds = self.ground_truth_kinds
        if not kinds:
            raise DatasetError(f"{self.dir}: no ground truth (generate it with `ground_truth: [depth, flow, normals, "
                               "ids]` in the scene's or the preset's config)")
        camera = self._index("camera", camera, self.n_cameras, "ground truth")
        index = self._index("kept frame", index, len(self.kept_times_us), "ground truth")
        root, name = self.dir / "ground_truth", f"cam{camera}/{index:05d}"
        gt = self.manifest["ground_truth"]
        source = self.dir.parent / gt["shared_with"] / "ground_truth" if gt.get("shared_with") else root

        def need(path: Path) -> Path:
            if not path.is_file():
                raise DatasetError(f"{path}: missing (the scene's manifest lists {', '.join(kinds)} ground truth for "
                                   f"camera {camera}, kept frame {index})")
            return path

        def exr(path: Path) -> np.ndarray:
            try:
                return read_exr(need(path))
            except ValueError as exc:
                raise DatasetError(str(exc)) from None

        out = {}
        if "depth" in kinds:
            out["depth_m"] = exr(root / "depth" / f"{name}.exr")
        if "normals" in kinds:
            out["normals"] = exr(root / "normals" / f"{name}.exr")
        if "ids" in kinds:
            path = need(root / "ids" / f"{name}.png")
            ids = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
            if ids is None or ids.ndim != 2:
                raise DatasetError(f"{path}: not a one-channel id image")
            out["ids"] = ids
        if "flow" in kinds:
            if index < len(self.kept_times_us) - 1:                      # every kept frame but the last
                forward = need(root / "flow" / f"{name}.npz")
                try:
                    with np.load(forward) as z:
                        out.update(flow_px=z["forward_px"], flow_valid=z["valid"], flow_occluded=z["occluded"])
                except (OSError, ValueError, KeyError) as exc:
                    raise DatasetError(f"{forward}: not a flow file ({exc})") from None
            velocity = need(source / "velocity" / f"{name}.npz")      # a speed variant's is its scene's, scaled
            try:
                with np.load(velocity) as z:
                    out["velocity_px_per_ms"] = (z["px_per_ms"] * float(gt.get("velocity_scale", 1.0))).astype(np.float32)
            except (OSError, ValueError, KeyError) as exc:
                raise DatasetError(f"{velocity}: not a velocity file ({exc})") from None
        return GroundTruth(camera, index, int(self.kept_times_us[index]), **out)

    def pose(self, camera: int, t_us) -> np.ndarray:
        """OpenCV camera-to-world [4, 4] of a camera at any time inside the clip."""
        return self.cameras[self._index("camera", camera, self.n_cameras, "pose")].pose_at(t_us)

    @staticmethod
    def load_image(path: Path) -> np.ndarray:
        """float32 [H, W, 3] or [H, W] in [0, 1] (sRGB-encoded as stored)."""
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise DatasetError(f"{path}: cannot read image")
        img = img.astype(np.float32) / 255.0
        return img[..., ::-1].copy() if img.ndim == 3 else img
