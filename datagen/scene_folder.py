"""A scene folder's files beside the render loop (datagen.generate.SceneJob): the kept frames, the
metadata (cameras.json, transforms, scene.yaml, masks, previews), the manifest with every file's
SHA-256 (written last: a folder without it is incomplete), the speed variants' manifests and the
extra event formats. Each writer takes the scene's plan (`plan`: a datagen.scene_plan.ScenePlan)
and writes; none renders or simulates.
"""
from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np

from common import provenance
from common.config import dump_config
from common.color import rec709_luma
from common.fileio import sha256_file, write_text_atomic
from common.imageio import write_exr, write_png_srgb
from common.provenance import git_commit as _git_commit
from datagen import render as R
from datagen.preview import blur_psnr, contact_sheet, speed_sheet
from eventio.h5io import read_info
from scene_format.config import SceneConfig
from scene_format.naming import SHUTTER_LEVEL
from scene_format.transforms import write_transforms as _write_transforms_file

FORMAT_VERSION = 1


def config_fingerprint(cfg: SceneConfig, release: str | None = None) -> str:
    """What a finished scene folder was made with: the scene config and the folder's format version,
    not the toolkit's release (a new release that writes the same files keeps every dataset;
    `release`: the fingerprint of a folder written by release 0.2 or earlier, which hashed it). A scene built in code leaves `source` out, so
    folders generated before scenes could come from files keep their fingerprint; `formats` (extra
    exports, datagen.exports) changes nothing in the scene and is left out, and so is `ground_truth`
    when off; `blur.fit` is left out
    at its default, so folders generated before it existed keep theirs."""
    import yaml

    from common.config import to_dict

    data = to_dict(cfg)
    if not cfg.source.file:
        data.pop("source")
    data.pop("formats")
    if not cfg.ground_truth:                        # off: folders generated before it keep their fingerprint
        data.pop("ground_truth")
    if cfg.sensor_seed is None:                     # the scene's seed: folders generated before it keep theirs
        data.pop("sensor_seed")
    for key in ("sensor_preset", "sensor_effects"):  # the sensor itself is recorded resolved, below
        if not data[key]:
            data.pop(key)
    from simulator.config import LATER_FIELDS

    for key, off in LATER_FIELDS.items():           # sensor effects added later, at their off value
        if data["sensor"].get(key) == off:
            data["sensor"].pop(key)
    if not cfg.blur.fit:
        data["blur"].pop("fit")
    if not cfg.render.adaptive_px:                  # every frame rendered: max_stride says nothing
        data["render"].pop("adaptive_px")
        data["render"].pop("max_stride")
    text = yaml.safe_dump(data, sort_keys=False)
    head = f"{FORMAT_VERSION}\n{release}\n" if release is not None else f"{FORMAT_VERSION}\n"
    return hashlib.sha256(f"{head}{text}".encode()).hexdigest()


def same_config(manifest: dict, cfg: SceneConfig) -> bool:
    """Whether a manifest's `config_sha256` is `cfg`'s fingerprint, or the fingerprint a release up to
    0.2 (which hashed its version, recorded in the manifest's versions.toolkit) gave the same config."""
    recorded = manifest.get("config_sha256")
    if recorded == config_fingerprint(cfg):
        return True
    release = (manifest.get("versions") or {}).get("toolkit")
    return isinstance(release, str) and recorded == config_fingerprint(cfg, release)



def versions() -> dict:
    return provenance.versions("numba", "h5py", bpy=R.blender_version())


def write_kept(folder: Path, k: int, j: int, rgb: np.ndarray) -> None:
    """Kept frame j of camera k: linear half-float EXR, sRGB PNG, its Rec.709 luma as PNG."""
    name = f"{j:05d}"
    write_exr(folder / "frames" / f"cam{k}" / f"{name}.exr", rgb, half=True)
    write_png_srgb(folder / "rgb" / f"cam{k}" / f"{name}.png", rgb)
    write_png_srgb(folder / "gray" / f"cam{k}" / f"{name}.png", rec709_luma(rgb))


def write_exports(plan) -> None:
    """The extra formats the config asks for, of the scene and its variants (datagen.exports)."""
    if plan.cfg.formats:
        from datagen.exports import ensure_exports

        for p in plan.plans:
            ensure_exports(p.dir, p.cfg.formats)


def write_metadata(plan, seconds: dict, ground_truth: dict | None = None) -> None:
    """cameras.json, transforms, scene.yaml, masks, previews and, last, manifest.json of one folder
    (ground_truth: the manifest's entry, when the scene wrote ground truth)."""
    cfg, d = plan.cfg, plan.dir
    t_write = time.perf_counter()
    C = cfg.camera.n_cameras
    cameras = {
        "convention": "OpenCV camera axes (x right, y down, z forward); c2w = camera-to-world. "
                      "Pixel (u, v) centre samples the image plane at (u + 0.5, v + 0.5).",
        "intrinsics": plan.intr.to_dict(),
        "cameras": [{"camera": k, "timestamps_us": plan.t_us.tolist(),
                     "c2w_opencv": np.round(plan.poses[k], 12).tolist()} for k in range(C)],
    }
    write_text_atomic(d / "cameras.json", json.dumps(cameras))
    write_transforms(plan)
    write_text_atomic(d / "scene.yaml", f"# resolved scene config (preset: {plan.preset})\n" + dump_config(cfg))
    mid = len(plan.kept) // 2
    window = max(int(round(cfg.frames.keep_every * 1e6 / cfg.real_fps)), int(round(1000 / cfg.speed)))
    blur = plan.blur.manifest if plan.blur else None
    if blur:
        for level in plan.windows:
            blur["levels"][level]["psnr_vs_sharp_db"] = blur_psnr(d, level, C, len(plan.kept))
    labels = {level: [f"{m:.1f} px" for m in plan.blur.view_median_px[level][:, mid]] for level in plan.windows}
    if plan.is_variant:
        labels = {f"x{cfg.speed:g} {lv} {cfg.blur.exposure_ms[lv]:g} ms": v for lv, v in labels.items()}
    if plan.dynamic:
        from datagen.dynamic import write_masks

        write_masks(d, test_masks(plan))
    contact_sheet(d, C, mid, int(plan.t_us[plan.kept[mid]]), window, labels, d / "preview" / "contact_sheet.png",
                  folders=list(plan.windows), dynamic=[plan.dynamic.get((k, mid)) for k in range(C)])
    if plan.variants:
        speed_sheet(d, [v.dir for v in plan.variants], mid, d / "preview" / "speeds.png")
    seconds["write"] += time.perf_counter() - t_write
    n_events = [read_info(d / "events" / f"cam{k}.h5")["n_events"] for k in range(C)]
    files = sorted(p for p in d.rglob("*") if p.is_file() and not p.name.startswith(".") and p.name != "manifest.json")
    manifest = {
        "scene": cfg.name, "preset": plan.preset, "format_version": FORMAT_VERSION,
        "config_sha256": plan.fingerprint, "seed": cfg.seed, "git_commit": _git_commit(),
        "versions": versions(), "created_unix": int(time.time()),
        "counts": {"cameras": C, "timestamps": cfg.n_timestamps, "kept_frames_per_camera": len(plan.kept),
                   "test_frames_per_camera": int(np.sum(np.arange(len(plan.kept)) % cfg.frames.test_every == 0)),
                   "events_per_camera": n_events},
        "events_per_second_per_camera": [round(n / cfg.real_duration_s) for n in n_events],
        "blur": blur,
        **({"ground_truth": ground_truth} if ground_truth else {}),
        **speed_manifest(plan),
        **({"render_plan": plan.render_plan} if plan.render_plan.get("adaptive_px") else {}),
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
        "files": {str(p.relative_to(d)): {"bytes": p.stat().st_size, "sha256": sha256_file(p)} for p in files},
    }
    write_text_atomic(d / "manifest.json", json.dumps(manifest, indent=1))

def test_masks(plan) -> dict:
    """{(camera, kept index): [H, W] bool} of the plan's dynamic masks at its test views."""
    return {v: m for v, m in plan.dynamic.items() if v[1] % plan.cfg.frames.test_every == 0}


def speed_manifest(plan) -> dict:
    """A variant's speed (factor, exposure, frames it integrates, real clip length); a scene's variants."""
    cfg = plan.cfg
    out = {}
    if plan.is_variant:
        out["speed"] = {"factor": cfg.speed, "exposure_ms": cfg.speeds.exposure_ms,
                        "n_frames": plan.blur.manifest["levels"][SHUTTER_LEVEL]["n_frames"],
                        "render_fps": cfg.render.fps, "real_fps": cfg.real_fps,
                        "real_duration_s": cfg.real_duration_s, "scene": cfg.name,
                        "construction": "time compression: the scene's rendered frames at timestamps divided by "
                                        "the factor; events simulated again at those timestamps; blurred frames of "
                                        "a fixed real-time exposure"}
    if plan.variants:
        out["speed_variants"] = {f"x{v.cfg.speed:g}": v.dir.name for v in plan.variants}
    return out

def write_transforms(plan) -> None:
    _write_transforms_file(plan.dir, plan.intr, plan.t_us, plan.poses, plan.kept, plan.windows, plan.cfg.frames.test_every,
                     plan.cfg.render.fps)
