"""Rendering with bpy: engine setup, cameras, one view into a NumPy array.

Blender has no in-memory read-back of a render in background mode, so each view is rendered to an
EXR in /dev/shm (RAM) and read back (< 0.02 s). EXR output is scene-linear: no view transform is
applied on this path, which is what the event simulator needs.
"""
from __future__ import annotations

import contextlib
import math
import os
import tempfile
from pathlib import Path

import bpy
import mathutils
import numpy as np

from scene_format.cameras import FLIP_YZ, Intrinsics
from scene_format.config import SceneConfig
from blender_scenes.common import ANIM_FRAMES
from common.imageio import read_exr

ENGINE_IDS = {"workbench": "BLENDER_WORKBENCH", "cycles": "CYCLES", "eevee": "BLENDER_EEVEE"}


def reset_scene() -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def setup_render(cfg: SceneConfig) -> None:
    """The engine, image and colour settings every scene renders with (a file's scene keeps its own
    frame range and rate, and for path-traced engines its own world and lights; without lights it
    gets the toolkit's sun)."""
    sc = bpy.context.scene
    r = cfg.render
    from_file = bool(cfg.source.file)
    if r.engine == "cycles":
        import addon_utils

        addon_utils.enable("cycles", default_set=True)
    sc.render.engine = ENGINE_IDS[r.engine]
    sc.render.resolution_x, sc.render.resolution_y = r.width, r.height
    sc.render.resolution_percentage = 100
    sc.render.pixel_aspect_x = sc.render.pixel_aspect_y = 1.0
    if not from_file:
        sc.render.fps = 30
        sc.frame_start, sc.frame_end = 1, 1 + ANIM_FRAMES
    sc.render.use_motion_blur = False
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.image_settings.exr_codec = "NONE"
    sc.render.image_settings.color_mode = "RGB"
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    keep_world = from_file and r.engine != "workbench" and sc.world is not None
    world = sc.world or bpy.data.worlds.new("World")
    sc.world = world
    if not keep_world:
        world.use_nodes = False
        world.color = cfg.lighting.background
    if from_file and r.engine != "workbench" and not any(o.type == "LIGHT" for o in sc.objects):
        from blender_scenes.common import sun_and_world

        sun_and_world(direction=cfg.lighting.light_direction)
    if r.engine == "workbench":
        lt = cfg.lighting
        sc.display.render_aa = {1: "OFF"}.get(r.samples, str(r.samples))
        sh = sc.display.shading
        sh.light = "STUDIO" if lt.shading == "studio" else "FLAT"
        sh.studio_light = lt.studio_light
        sh.use_world_space_lighting = True   # shading fixed in the world, not to the moving camera
        sh.studiolight_rotate_z = math.radians(lt.rotate_z_deg)
        sh.color_type = "TEXTURE"
        sh.show_shadows = lt.shadows
        sh.shadow_intensity = lt.shadow_intensity
        sh.show_cavity = lt.cavity
        sh.show_specular_highlight = False   # view-dependent highlights would break brightness constancy
        sc.display.light_direction = lt.light_direction
    elif r.engine == "cycles":
        sc.cycles.device = "CPU"
        sc.cycles.samples = r.samples
        sc.cycles.use_denoising = False
        sc.cycles.use_adaptive_sampling = False
        sc.cycles.use_animated_seed = False  # `set_noise_seed` gives every timestamp its own seed
    else:
        sc.eevee.taa_render_samples = r.samples


def make_cameras(n: int, intr: Intrinsics) -> list[bpy.types.Object]:
    """n camera objects whose projection equals K (horizontal sensor fit, centred principal point)."""
    cams = []
    for k in range(n):
        data = bpy.data.cameras.new(f"cam{k}")
        data.sensor_fit = "HORIZONTAL"
        data.sensor_width = 36.0
        data.lens = intr.fx * data.sensor_width / intr.width
        data.shift_x = (intr.width / 2.0 - intr.cx) / intr.width
        data.shift_y = (intr.cy - intr.height / 2.0) / intr.width
        data.clip_start, data.clip_end = 0.01, 1000.0
        obj = bpy.data.objects.new(f"cam{k}", data)
        bpy.context.scene.collection.objects.link(obj)
        cams.append(obj)
    return cams


def set_pose(cam: bpy.types.Object, c2w_opencv: np.ndarray) -> None:
    cam.matrix_world = mathutils.Matrix((c2w_opencv @ FLIP_YZ).tolist())


def set_noise_seed(seed: int) -> None:
    """Independent path-tracing noise per rendered timestamp (Cycles; other engines have none)."""
    sc = bpy.context.scene
    if sc.render.engine == "CYCLES":
        sc.cycles.seed = int(seed) % (2**31 - 1)


# Blender frame of normalised time 0, and frames per unit of normalised time: the built-in scenes'
# keyframes span 1 .. 1 + ANIM_FRAMES; a file's scene spans its own range (set by build_scene)
_TIME_MAP = [1.0, float(ANIM_FRAMES)]


def set_time(tau: float) -> None:
    f = _TIME_MAP[0] + _TIME_MAP[1] * tau
    bpy.context.scene.frame_set(int(math.floor(f)), subframe=f - math.floor(f))


@contextlib.contextmanager
def _quiet_stdout():
    """Blender prints a line per saved render to fd 1; keep the terminal for progress bars."""
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)


class ViewRenderer:
    """Renders the current scene state from a camera into float32 linear RGB [H, W, 3]."""

    def __init__(self):
        shm = Path("/dev/shm") if Path("/dev/shm").is_dir() else Path(tempfile.gettempdir())
        self._dir = Path(tempfile.mkdtemp(prefix="e4dgs-render-", dir=shm))
        self._path = self._dir / "view.exr"
        bpy.context.scene.render.filepath = str(self._path)

    def render(self, cam: bpy.types.Object) -> np.ndarray:
        sc = bpy.context.scene
        sc.camera = cam
        with _quiet_stdout():
            bpy.ops.render.render(write_still=True)
        img = read_exr(self._path)
        return np.ascontiguousarray(img[..., :3], dtype=np.float32)

    def close(self) -> None:
        self._path.unlink(missing_ok=True)
        with contextlib.suppress(OSError):
            self._dir.rmdir()


def blender_version() -> str:
    return bpy.app.version_string


def build_scene(cfg: SceneConfig, intr: Intrinsics) -> list:
    """Reset Blender, set up the engine, build cfg's scene and its cameras (returned)."""
    import importlib

    from blender_scenes.common import consolidate

    if cfg.source.file:                  # a file's scene: its own objects, animation and materials
        from datagen.scene_file import load_file

        load_file(cfg.source.file)
        _TIME_MAP[:] = [float(cfg.source.frame_start), float(cfg.source.frame_end - cfg.source.frame_start)]
        setup_render(cfg)
        return make_cameras(cfg.camera.n_cameras, intr)
    _TIME_MAP[:] = [1.0, float(ANIM_FRAMES)]
    reset_scene()
    setup_render(cfg)
    importlib.import_module(f"blender_scenes.{cfg.source.builtin or cfg.name}").build(cfg)
    consolidate()  # fewer, larger objects render faster in Workbench
    return make_cameras(cfg.camera.n_cameras, intr)


def render_clip(cfg: SceneConfig, tau: np.ndarray, camera_ids=(0,), camera_tau: np.ndarray | None = None,
                progress: bool = False) -> tuple[np.ndarray, float]:
    """Build `cfg`'s scene and render cameras `camera_ids` at normalised times tau [T].

    camera_tau [T] (default tau) places the cameras, so a frozen camera over a moving scene (or
    the reverse) can be rendered. Returns (linear RGB frames [C, T, H, W, 3] float32 including the
    scene's exposure gain, render seconds).
    """
    import time

    from scene_format.cameras import intrinsics_from_fov
    from datagen.rig import scene_poses

    cams = build_scene(cfg, intrinsics_from_fov(cfg.render.width, cfg.render.height, cfg.camera.fov_x_deg))
    poses = scene_poses(cfg, tau if camera_tau is None else camera_tau)
    renderer = ViewRenderer()
    out = np.empty((len(camera_ids), len(tau), cfg.render.height, cfg.render.width, 3), np.float32)
    seconds = 0.0
    try:
        for i, t in enumerate(tau):
            set_time(float(t))
            set_noise_seed(cfg.seed * 100_003 + i)
            for c, k in enumerate(camera_ids):
                set_pose(cams[k], poses[k, i])
                t0 = time.perf_counter()
                out[c, i] = renderer.render(cams[k]) * np.float32(cfg.lighting.exposure)
                seconds += time.perf_counter() - t0
            if progress and i % 20 == 0:
                print(f"  rendered {i + 1}/{len(tau)}", flush=True)
    finally:
        renderer.close()
    return out, seconds
