"""A scene's plan: what one scene folder's generation will write, as a plain value computed once
before the first frame is rendered. The render loop (datagen.generate.SceneJob), the folder's
writers (datagen.scene_folder, datagen.ground_truth_files), the geometry cache and `e4dgs masks`
(datagen.add_masks) all take a plan; none of them takes the loop.

    plan = make_plan(cfg, Path("data/quick"), preset="quick")   # times, poses, kept frames, variants
    measure(plan)          # with the scene built in Blender: blur exposures, dynamic masks, render schedule
    plan.plans             # [the scene, its speed variants]: each its own folder, sharing the scene's frames

Fixed when made: the folder, timestamps (t_us, tau), camera poses, intrinsics, kept frames, the
speed variants' plans. Measured from the scene geometry (`measure`, or restored by
datagen.geometry_cache): blur exposures and windows, dynamic masks, the render schedule.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from datagen.blur_geometry import BlurReport, measure_blur_many
from datagen.rig import scene_poses
from datagen.speed import check_interpolation, check_speeds, variant_config
from scene_format.cameras import Intrinsics, intrinsics_from_fov
from scene_format.config import SceneConfig
from datagen.scene_folder import config_fingerprint
from scene_format.naming import variant_name


def timestamps_us(cfg: SceneConfig) -> np.ndarray:
    """Real time (us) of every rendered frame: i / (fps * speed)."""
    return np.round(np.arange(cfg.n_timestamps) * 1e6 / cfg.real_fps).astype(np.int64)


@dataclass
class ScenePlan:
    """One scene folder's plan (a scene or one of its speed variants)."""
    cfg: SceneConfig
    dir: Path                      # the folder it writes
    preset: str                    # the dataset preset named in its manifest
    t_us: np.ndarray               # [T] int64: real time of every timestamp, microseconds
    tau: np.ndarray                # [T] scene time in [0, 1] (a variant shows its scene's)
    poses: np.ndarray              # [C, T, 4, 4] OpenCV camera-to-world
    intr: Intrinsics
    kept: np.ndarray               # [K] timestamps whose frames are written
    is_variant: bool               # a speed variant: its events and blur are its own, its frames the scene's
    fingerprint: str               # the scene config's fingerprint (scene_format.manifest)
    variants: list["ScenePlan"] = field(default_factory=list)
    # measured from the geometry (measure, or datagen.geometry_cache)
    blur: BlurReport | None = None
    windows: dict[str, dict[int, tuple[int, int]]] = field(default_factory=dict)   # level -> blurred frame -> (first, last)
    dynamic: dict[tuple[int, int], np.ndarray] = field(default_factory=dict)      # (camera, kept index) -> [H, W] bool
    rendered: np.ndarray | None = None     # timestamps rendered (the others blended: datagen.temporal_sampling)
    render_plan: dict = field(default_factory=dict)    # the manifest's render_plan entry

    @property
    def plans(self) -> list["ScenePlan"]:
        """This scene and its speed variants, which share its render loop."""
        return [self] + self.variants

    @functools.cached_property
    def kept_index(self) -> dict[int, int]:
        """timestamp -> kept frame number."""
        return {int(i): j for j, i in enumerate(self.kept)}

    def dynamic_views(self) -> list[tuple[int, int]]:
        """(camera, kept index) of the views with a dynamic mask: the test views, and the contact sheet's."""
        test = [j for j in range(len(self.kept)) if j % self.cfg.frames.test_every == 0]
        return [(k, j) for k in range(self.cfg.camera.n_cameras) for j in sorted(set(test) | {len(self.kept) // 2})]


def make_plan(cfg: SceneConfig, out_root: Path, preset: str = "custom", folder: str | None = None,
              tau: np.ndarray | None = None, poses: np.ndarray | None = None) -> ScenePlan:
    """The plan of scene `cfg` in out_root/<folder or cfg.name>, with its speed variants' plans.
    tau: a variant's scene time (its scene's); poses [C, T, 4, 4]: a file's own cameras (else the rig's)."""
    t_us = timestamps_us(cfg)
    if tau is None:        # a speed variant shows its scene's frames: it takes the scene's tau
        tau = t_us / t_us[-1] if t_us[-1] > 0 else np.zeros(len(t_us))
    check_speeds(cfg.name, cfg.speeds.factors, cfg.speeds.exposure_ms, cfg.render.fps, cfg.n_timestamps)
    poses = scene_poses(cfg, tau) if poses is None else poses
    d = Path(out_root) / (folder or cfg.name)
    plan = ScenePlan(cfg=cfg, dir=d, preset=preset, t_us=t_us, tau=tau, poses=poses,
                     intr=intrinsics_from_fov(cfg.render.width, cfg.render.height, cfg.camera.fov_x_deg),
                     kept=np.arange(0, cfg.n_timestamps, cfg.frames.keep_every), is_variant=d.name != cfg.name,
                     fingerprint=config_fingerprint(cfg))
    plan.variants = [make_plan(variant_config(cfg, s), out_root, preset, variant_name(cfg.name, s), tau, poses)
                     for s in cfg.speeds.factors]
    return plan


# -- measured from the scene geometry (the scene built in Blender) ----------------------------------
def measure(plan: ScenePlan, log=print) -> None:
    """Blur exposures, dynamic masks and the render schedule of plan and its variants, from the
    scene built in Blender. A blur level out of reach raises before anything is written."""
    motion = _Motion(plan)
    measure_blur(plan, motion, log)
    measure_dynamic(plan)
    plan_renders(plan, motion, log)


class _Motion:
    """(part motion, surface samples) of the scene's geometry at the kept frames (render_geometry),
    measured once for the blur levels and the render schedule."""

    def __init__(self, plan: ScenePlan):
        self.plan, self._value = plan, None

    def get(self):
        if self._value is None:
            from datagen.render_geometry import RigidMotionError, sample_scene_motion

            p, cfg = self.plan, self.plan.cfg
            try:
                self._value = sample_scene_motion(p.tau, p.kept, p.poses, p.intr.K, cfg.render.width,
                                                  cfg.render.height, cfg.blur.sample_stride_px)
            except RigidMotionError as exc:
                raise RigidMotionError(f"scene {cfg.name}: {exc}") from None
        return self._value


def measure_blur(plan: ScenePlan, motion: _Motion | None = None, log=print) -> None:
    """Every blur level's exposure from the scene geometry (datagen.blur_geometry), the scene's and
    its speed variants'; refuses variants the render moves too fast for."""
    cfg = plan.cfg
    plans = [p for p in plan.plans if p.cfg.blur.target_px or p.cfg.blur.exposure_ms]
    if not plans:
        return
    mats, samples = (motion or _Motion(plan)).get()
    reports = measure_blur_many(samples, mats, plan.poses, plan.intr.K, plan.kept,
                                [(p.cfg.blur, p.cfg.real_fps) for p in plans], cfg.name)
    for p, report in zip(plans, reports):       # variants show the scene's frames: same poses and kept frames
        p.blur, p.windows = report, report.windows
    if plan.variants:
        check_interpolation(cfg.name, cfg.speeds.factors, plan.variants[0].blur.manifest["px_per_frame"].get("p90", 0.0),
                            cfg.speeds.max_px_per_frame)
    for p in plan.plans:
        levels = p.blur.manifest["levels"] if p.blur else {}
        log(f"{p.dir.name}: blur exposures " + ", ".join(
            f"{name} {lv['n_frames']} frames ({lv['exposure_ms']:.2f} ms): {lv['median_px']:.1f} px"
            for name, lv in levels.items()))
        fitted = {name: lv for name, lv in levels.items() if lv.get("fitted")}
        if fitted:
            log(f"{p.dir.name}: blur targets fitted to this scene and size (target -> got): "
                + ", ".join(f"{name} {lv['declared_target_px']:g} -> {lv['median_px']:.2f} px" for name, lv in fitted.items()))


def measure_dynamic(plan: ScenePlan) -> None:
    """The dynamic masks (datagen.dynamic) of the scene currently built, for it and its speed
    variants (the same views of the same frames)."""
    from datagen.dynamic import THRESHOLD_PX
    from datagen.render_geometry import RigidMotionError, dynamic_masks

    views = plan.dynamic_views()
    try:
        by_time = dynamic_masks(plan.tau, [(k, int(plan.kept[j])) for k, j in views], plan.poses, plan.intr.K,
                                plan.cfg.render.width, plan.cfg.render.height, THRESHOLD_PX)
    except RigidMotionError as exc:
        raise RigidMotionError(f"scene {plan.cfg.name}: {exc}") from None
    for p in plan.plans:
        p.dynamic = {(k, j): by_time[(k, int(plan.kept[j]))] for k, j in views}


def plan_renders(plan: ScenePlan, motion: _Motion | None = None, log=print) -> None:
    """The rendered timestamps (every one, or render.adaptive_px's schedule from the scene geometry:
    datagen.temporal_sampling) and the manifest's render_plan, for the scene and its variants."""
    cfg, T = plan.cfg, plan.cfg.n_timestamps
    if cfg.render.adaptive_px:
        from datagen.temporal_sampling import frame_steps_px, plan_renders as schedule

        mats, samples = (motion or _Motion(plan)).get()
        steps = frame_steps_px(samples, mats, plan.poses, plan.intr.K, plan.kept, T)
        rendered, info = schedule(steps, plan.kept, cfg.render.adaptive_px, cfg.render.max_stride)
        log(f"{cfg.name}: adaptive render: {len(rendered)} of {T} frames (<= {cfg.render.adaptive_px:g} px "
            f"between rendered frames, <= {cfg.render.max_stride} apart)")
    else:
        rendered, info = np.arange(T), {"adaptive_px": 0.0, "rendered_frames": T, "timestamps": T}
    for p in plan.plans:                       # the variants show the scene's frames
        p.rendered, p.render_plan = rendered, info
