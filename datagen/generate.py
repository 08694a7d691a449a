"""Generate one scene of the dataset: render, simulate, blur, write. Resumable.

    python -m datagen.generate --scene lego --preset quick --out data/quick

Per rendered timestamp the scene is evaluated once and every camera rendered; each linear frame goes
straight into that camera's simulator and its events are appended to the camera's spool. Frames are
written only at kept timestamps; blurred frames are running means over their exposure windows. The
scene's speed variants (`speeds.factors`, datagen.speed) take the same frames in the same pass, each
with its own simulators (at its compressed timestamps) and blur sums, and become the folders
`<scene>_x<s>`. A checkpoint (simulator states, spool counts, open blur sums, timings, of the scene
and of every variant) is saved every `checkpoint_every` timestamps; a killed run restarted with the
same config continues from it and ends with the same files; what it measured from the geometry before
rendering (blur windows, dynamic masks, render schedule) is kept beside the checkpoint
(datagen.geometry_cache) and not measured again. `manifest.json` is written last (the
variants' before the scene's): a scene folder without it is incomplete. The folder's writers (frames,
metadata, manifests, exports) are datagen.scene_folder; this module is the loop.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from common import progress

from datagen import geometry_cache, scene_folder
from datagen import render as R
from datagen.blur import BlurStack
from datagen.blur_geometry import BlurReport, measure_blur_many
from scene_format.cameras import intrinsics_from_fov
from datagen.rig import scene_poses
from scene_format.config import SceneConfig
from datagen.config import load_preset, resolve_scene
from datagen.temporal_sampling import blend_weights
from datagen.speed import check_interpolation, check_speeds, variant_config
from scene_format.naming import variant_name
from common.checkpoint import JobCheckpoint
from common.config import ConfigError
from common.argtypes import positive_int
from common.fileio import link_tree, output_lock
from common.imageio import write_png_srgb
from eventio.h5io import simulator_attrs
from common.color import rec709_luma
from simulator.resumable import EventSpool, can_resume
from simulator.simulator import EventSimulator

def timestamps_us(cfg: SceneConfig) -> np.ndarray:
    """Real time (us) of every rendered frame: i / (fps * speed)."""
    return np.round(np.arange(cfg.n_timestamps) * 1e6 / cfg.real_fps).astype(np.int64)


class SceneJob:
    """State of one scene's generation; `run()` does the work (resuming if a checkpoint matches)."""

    def __init__(self, cfg: SceneConfig, out_root: Path, preset: str = "custom", checkpoint_every: int = 100,
                 progress: bool = True, position: int = 0, folder: str | None = None, tau: np.ndarray | None = None,
                 poses: np.ndarray | None = None):
        self.cfg, self.preset, self.progress, self.position = cfg, preset, progress, position
        self.dir = Path(out_root) / (folder or cfg.name)
        if int(checkpoint_every) < 1:
            raise ValueError(f"checkpoint_every: expected an integer >= 1, got {checkpoint_every!r}")
        self.checkpoint_every = int(checkpoint_every)
        self.t_us = timestamps_us(cfg)
        if tau is None:        # a speed variant shows its scene's frames: it takes the scene's tau
            tau = self.t_us / self.t_us[-1] if self.t_us[-1] > 0 else np.zeros(len(self.t_us))
        self.tau = tau
        check_speeds(cfg.name, cfg.speeds.factors, cfg.speeds.exposure_ms, cfg.render.fps, cfg.n_timestamps)
        # [C, T, 4, 4] OpenCV c2w: the rig's, or given (a file's own cameras, read from it by the caller)
        self.poses = scene_poses(cfg, self.tau) if poses is None else poses
        self.variants = [SceneJob(variant_config(cfg, s), out_root, preset, checkpoint_every, False, position,
                                  variant_name(cfg.name, s), tau, self.poses) for s in cfg.speeds.factors]
        self.intr = intrinsics_from_fov(cfg.render.width, cfg.render.height, cfg.camera.fov_x_deg)
        self.kept = np.arange(0, cfg.n_timestamps, cfg.frames.keep_every)
        self._kept_index = {int(i): j for j, i in enumerate(self.kept)}   # timestamp -> kept frame number
        self.blur: BlurReport | None = None   # exposures chosen from the scene geometry (run() measures them)
        self.dynamic: dict[tuple[int, int], np.ndarray] = {}     # (camera, kept index) -> dynamic mask (test views)
        self.windows: dict[str, dict[int, tuple[int, int]]] = {}
        self.fingerprint = scene_folder.config_fingerprint(cfg)
        self.ground_truth: dict | None = None     # the manifest's ground_truth entry, once written
        self.ground_truth_ids: dict[int, np.ndarray] = {}   # camera -> [kept, H, W] object ids, once written

    # -- files -------------------------------------------------------------------------------
    def is_complete(self) -> bool:
        """Whether the scene (and so its variants, written before it) is complete with this config."""
        manifest = self.dir / "manifest.json"
        if not manifest.exists():
            return False
        if not scene_folder.same_config(json.loads(manifest.read_text()), self.cfg):
            raise ValueError(f"{self.dir} holds a complete scene generated with another config; "
                             "remove it or choose another --out")
        return True

    def _write_kept(self, k: int, j: int, rgb: np.ndarray) -> None:
        scene_folder.write_kept(self.dir, k, j, rgb)

    def _write_metadata(self, seconds: dict) -> None:
        scene_folder.write_metadata(self, seconds)

    def _exports(self) -> None:
        scene_folder.write_exports(self)

    # -- the loop ----------------------------------------------------------------------------
    def run(self) -> Path:
        """Generate the scene: measure the blur, then render, simulate and write every timestamp
        (resuming a checkpoint), then finish the event files and the metadata."""
        cfg = self.cfg
        if self.is_complete():
            print(f"{self.dir}: complete, skipped")
            self._exports()
            return self.dir
        t_start = time.perf_counter()
        cams = R.build_scene(cfg, self.intr)
        t_blur = time.perf_counter()
        cached = geometry_cache.load(self.dir, self.fingerprint, self.jobs)     # False without a folder or file
        if cached:      # an earlier start measured it (15-27 min in a paper-preset room)
            print(f"{cfg.name}: blur exposures, dynamic masks and render schedule from an earlier start "
                  f"({geometry_cache.FILE_NAME})", flush=True)
        else:
            self._measure_blur()  # before anything is written: a level out of reach leaves no output behind
            self.measure_dynamic()
            self._plan_renders()
        t_blur = time.perf_counter() - t_blur
        self.dir.mkdir(parents=True, exist_ok=True)
        if not cached:
            geometry_cache.save(self.dir, self.fingerprint, self.jobs)
        renderer = R.ViewRenderer()
        ckpt = JobCheckpoint(self.dir / ".generate.ckpt.npz", self.fingerprint)
        state = self._resumable_state(ckpt)
        streams = [job._open_streams(state, job._prefix()) for job in self.jobs]
        sims, spools, stacks = streams[0]
        start = int(state.get("next_index", 0))
        if start:
            print(f"{cfg.name}: resuming at timestamp {start} of {cfg.n_timestamps}", flush=True)
        seconds = [{name: float(state.get(f"{job._prefix()}seconds_{name}", 0.0))
                    for name in ("blur_geometry", "render", "simulate", "write", "total")} for job in self.jobs]
        seconds[0]["blur_geometry"] += t_blur
        bar = tqdm(range(start, cfg.n_timestamps), desc=cfg.name, unit="ts", initial=start, total=cfg.n_timestamps,
                   disable=not self.progress, dynamic_ncols=True, position=self.position)
        rendered = set(self.rendered.tolist())
        # the rendered frame before `start` (resuming an adaptive run): the blend anchor of the frames it skips
        anchor = (start - 1, self._render(start - 1, cams, renderer, seconds[0])) if start and len(rendered) < cfg.n_timestamps else None
        last_ckpt = start
        try:
            for i in bar:
                if i not in rendered:
                    continue
                frames = self._render(i, cams, renderer, seconds[0])
                if anchor is not None and anchor[0] < i - 1:          # the frames skipped since the last render
                    for job, stream, secs in zip(self.jobs, streams, seconds):
                        job._blend_skipped(anchor, (i, frames), stream[2], secs)
                for job, stream, secs in zip(self.jobs, streams, seconds):
                    job._consume(i, frames, *stream, secs)
                anchor = (i, frames)
                progress.report(i + 1, cfg.n_timestamps, "timestamps")   # the driver's view under Ray
                if self.progress and i % 10 == 0:
                    bar.set_postfix_str(" ".join(f"c{k}:{s.n_events / 1e3:.0f}k" for k, s in enumerate(spools)))
                if i + 1 - last_ckpt >= self.checkpoint_every and i + 1 < cfg.n_timestamps:
                    self._checkpoint(ckpt, i + 1, streams, seconds, t_start)
                    last_ckpt = i + 1
        finally:
            bar.close()
            renderer.close()
        for job, (job_sims, job_spools, _), secs in zip(self.jobs, streams, seconds):
            for sim, spool in zip(job_sims, job_spools):
                tail = sim.flush()              # what the readout still holds (latency, bandwidth)
                spool.append(tail)
                spool.finish(t_end_us=max(int(job.t_us[-1]), int(tail["t"][-1]) if tail.size else 0))
        if cfg.ground_truth:                        # after the loop: the frames it checks the flow against exist
            from datagen.ground_truth_files import write_ground_truth

            self.ground_truth = write_ground_truth(self, cfg.ground_truth)
            seconds[0]["ground_truth"] = self.ground_truth["seconds"]
        seconds[0]["total"] += time.perf_counter() - t_start
        for variant, secs in zip(self.variants, seconds[1:]):   # before the scene's manifest, which marks completion
            t0 = time.perf_counter()
            for part in ("frames", "rgb", "gray"):        # the same sharp frames: hard links where possible
                link_tree(self.dir / part, variant.dir / part)
            if self.ground_truth:
                from datagen.ground_truth_files import share_with_variant

                variant.ground_truth = share_with_variant(self, variant, self.ground_truth)
            secs["write"] += time.perf_counter() - t0
            secs["total"] = secs["simulate"] + secs["write"]      # its own work; the render is the scene's
            variant._write_metadata(secs)
        self._write_metadata(seconds[0])
        ckpt.remove()
        geometry_cache.remove(self.dir)
        self._exports()
        return self.dir

    @property
    def jobs(self) -> list["SceneJob"]:
        """This scene and its speed variants, which share its render loop."""
        return [self] + self.variants

    def _prefix(self) -> str:
        """Checkpoint key prefix of this job's state: '' for the scene, '<folder>__' for a variant."""
        return f"{self.dir.name}__" if self._is_variant else ""

    def _resumable_state(self, ckpt: JobCheckpoint) -> dict:
        """The checkpoint's state if its event spools hold what it records, else {} (start over, saying why)."""
        state = ckpt.load() or {}
        if state and not all(can_resume(job._event_path(k), int(state[f"{job._prefix()}n_events_{k}"]))
                             for job in self.jobs for k in range(self.cfg.camera.n_cameras)):
            print(f"warning: {ckpt.path}: its event spools are missing or shorter than it records; starting "
                  f"{self.cfg.name} over from the first timestamp", flush=True)
            ckpt.remove()
            state = {}
        if state:
            problem = self._sensor_state_problem(state)
            if problem:
                print(f"warning: {ckpt.path}: {problem}; starting {self.cfg.name} over from the first timestamp",
                      flush=True)
                ckpt.remove()
                state = {}
        return state

    def _sensor_state_problem(self, state: dict) -> str | None:
        """Why the checkpoint's event sensors cannot continue here (another sensor config or seed,
        e.g. a checkpoint of an older release), or None."""
        cfg = self.cfg
        W, H = cfg.render.width, cfg.render.height
        for job in self.jobs:
            key0 = f"{job._prefix()}sim"
            for k in range(cfg.camera.n_cameras):
                prefix = f"{key0}{k}__"
                try:
                    EventSimulator(job.cfg.sensor, W, H, seed=job.cfg.event_seed * 1000 + k).load_state_dict(
                        {key[len(prefix):]: v for key, v in state.items() if key.startswith(prefix)})
                except (ValueError, KeyError) as exc:
                    return f"camera {k} of {job.dir.name}: {exc}"
        return None

    def _event_path(self, camera: int) -> Path:
        return self.dir / "events" / f"cam{camera}.h5"

    def _open_streams(self, state: dict, prefix: str = ""):
        """Per camera: the simulator, the event spool and the blur accumulators, restored from `state`
        (this job's keys carry `prefix`)."""
        cfg = self.cfg
        C, W, H = cfg.camera.n_cameras, cfg.render.width, cfg.render.height
        sims = [EventSimulator(cfg.sensor, W, H, seed=cfg.event_seed * 1000 + k) for k in range(C)]
        attrs = {**simulator_attrs(cfg.sensor), "scene": cfg.name}
        if cfg.speed != 1:
            attrs["speed"] = cfg.speed
        spools = []
        for k in range(C):
            spools.append(EventSpool(self._event_path(k), W, H, attrs={**attrs, "camera": k, "seed": cfg.event_seed * 1000 + k},
                                     resume_count=int(state[f"{prefix}n_events_{k}"]) if state else None))
            if state:
                key0 = f"{prefix}sim{k}__"
                sims[k].load_state_dict({key[len(key0):]: v for key, v in state.items() if key.startswith(key0)})
        stacks = {(level, k): BlurStack(self.windows[level]) for level in self.windows for k in range(C)}
        for (level, k), stack in stacks.items():
            stack.load_state(state, f"{prefix}blur__{level}__{k}__")
        return sims, spools, stacks

    def _render(self, i: int, cams, renderer, seconds: dict) -> list[np.ndarray]:
        """Every camera's linear frame [H, W, 3] at rendered timestamp i."""
        cfg = self.cfg
        t0 = time.perf_counter()
        R.set_time(float(self.tau[i]))
        R.set_noise_seed(cfg.seed * 100_003 + i)
        frames = []
        for k, cam in enumerate(cams):
            R.set_pose(cam, self.poses[k, i])
            frames.append(renderer.render(cam) * np.float32(cfg.lighting.exposure))
        seconds["render"] += time.perf_counter() - t0
        return frames

    def _consume(self, i: int, frames: list[np.ndarray], sims, spools, stacks, seconds: dict) -> None:
        """Feed frame i of every camera to its simulator (at this job's timestamp of i), write it if kept
        (the scene only: variants link the scene's), and add it to the blur sums."""
        t1 = time.perf_counter()
        for k, frame in enumerate(frames):
            spools[k].append(sims[k].push(rec709_luma(frame), int(self.t_us[i])))
        t2 = time.perf_counter()
        kept_index = self._kept_index.get(i) if not self._is_variant else None
        for k, frame in enumerate(frames):
            if kept_index is not None:
                self._write_kept(k, kept_index, frame)
            for level in self.windows:
                for j, mean in stacks[(level, k)].add(i, frame):
                    write_png_srgb(self.dir / "blur" / level / f"cam{k}" / f"{j:05d}.png", mean)
        seconds["simulate"] += t2 - t1
        seconds["write"] += time.perf_counter() - t2

    def _blend_skipped(self, a: tuple[int, list], b: tuple[int, list], stacks, seconds: dict) -> None:
        """The frames between rendered frames a and b ((index, frames per camera)) into the blur sums, as
        linear-light blends of the two (datagen.temporal_sampling); the simulator sees only rendered frames."""
        if not self.windows:
            return
        t0 = time.perf_counter()
        (ia, fa), (ib, fb) = a, b
        for m in range(ia + 1, ib):
            levels = [lv for lv, wins in self.windows.items() if any(first <= m <= last for first, last in wins.values())]
            if not levels:                       # in no exposure: nothing to blend
                continue
            w = np.float32(blend_weights(ia, ib, m))
            for k in range(len(fa)):
                frame = fa[k] * (1 - w) + fb[k] * w
                for level in levels:
                    for j, mean in stacks[(level, k)].add(m, frame):
                        write_png_srgb(self.dir / "blur" / level / f"cam{k}" / f"{j:05d}.png", mean)
        seconds["write"] += time.perf_counter() - t0

    def _plan_renders(self) -> None:
        """self.rendered: the rendered-frame indices (every one, or render.adaptive_px's schedule from
        the scene geometry: datagen.temporal_sampling) and self.render_plan for the manifest."""
        cfg, T = self.cfg, self.cfg.n_timestamps
        if cfg.render.adaptive_px:
            from datagen.temporal_sampling import frame_steps_px, plan_renders

            mats, samples = self._motion()
            steps = frame_steps_px(samples, mats, self.poses, self.intr.K, self.kept, T)
            rendered, plan = plan_renders(steps, self.kept, cfg.render.adaptive_px, cfg.render.max_stride)
        else:
            rendered, plan = np.arange(T), {"adaptive_px": 0.0, "rendered_frames": T, "timestamps": T}
        for job in self.jobs:                       # the variants show the scene's frames
            job.rendered, job.render_plan = rendered, plan
        if not cfg.render.adaptive_px:
            return
        print(f"{cfg.name}: adaptive render: {len(self.rendered)} of {T} frames (<= {cfg.render.adaptive_px:g} px "
              f"between rendered frames, <= {cfg.render.max_stride} apart)", flush=True)

    def _motion(self):
        """(part motion, surface samples) of the scene's geometry at the kept frames (render_geometry),
        measured once for the blur levels and the render schedule."""
        if getattr(self, "_motion_cache", None) is None:
            from datagen.render_geometry import RigidMotionError, sample_scene_motion

            cfg = self.cfg
            try:
                self._motion_cache = sample_scene_motion(self.tau, self.kept, self.poses, self.intr.K, cfg.render.width,
                                                         cfg.render.height, cfg.blur.sample_stride_px)
            except RigidMotionError as exc:
                raise RigidMotionError(f"scene {cfg.name}: {exc}") from None
        return self._motion_cache

    @property
    def _is_variant(self) -> bool:
        return self.dir.name != self.cfg.name

    def _measure_blur(self) -> None:
        """Pick every blur level's exposure from the scene geometry (datagen.blur_geometry), the
        scene's and its speed variants'; refuse variants the render moves too fast for."""
        cfg = self.cfg
        if not any(job.cfg.blur.target_px or job.cfg.blur.exposure_ms for job in self.jobs):
            return
        mats, samples = self._motion()
        jobs = [job for job in self.jobs if job.cfg.blur.target_px or job.cfg.blur.exposure_ms]
        reports = measure_blur_many(samples, mats, self.poses, self.intr.K, self.kept,
                                    [(job.cfg.blur, job.cfg.real_fps) for job in jobs], cfg.name)
        for job, report in zip(jobs, reports):      # variants show the scene's frames: same poses and kept frames
            job.blur, job.windows = report, report.windows
        if self.variants:
            check_interpolation(cfg.name, cfg.speeds.factors, self.variants[0].blur.manifest["px_per_frame"].get("p90", 0.0),
                                cfg.speeds.max_px_per_frame)
        if self.progress:
            for job in self.jobs:
                levels = job.blur.manifest["levels"] if job.blur else {}
                print(f"{job.dir.name}: blur exposures " + ", ".join(
                    f"{name} {lv['n_frames']} frames ({lv['exposure_ms']:.2f} ms): {lv['median_px']:.1f} px"
                    for name, lv in levels.items()), flush=True)
                fitted = {name: lv for name, lv in levels.items() if lv.get("fitted")}
                if fitted:
                    print(f"{job.dir.name}: blur targets fitted to this scene and size (target -> got): "
                          + ", ".join(f"{name} {lv['declared_target_px']:g} -> {lv['median_px']:.2f} px"
                                      for name, lv in fitted.items()), flush=True)

    def dynamic_views(self) -> list[tuple[int, int]]:
        """(camera, kept index) of the views with a dynamic mask: the test views, and the contact sheet's."""
        test = [j for j in range(len(self.kept)) if j % self.cfg.frames.test_every == 0]
        return [(k, j) for k in range(self.cfg.camera.n_cameras) for j in sorted(set(test) | {len(self.kept) // 2})]

    def measure_dynamic(self) -> None:
        """The dynamic masks (datagen.dynamic) of the scene currently built, for it and its speed
        variants (the same views of the same frames)."""
        from datagen.dynamic import THRESHOLD_PX
        from datagen.render_geometry import RigidMotionError, dynamic_masks

        views = self.dynamic_views()
        try:
            by_time = dynamic_masks(self.tau, [(k, int(self.kept[j])) for k, j in views], self.poses, self.intr.K,
                                    self.cfg.render.width, self.cfg.render.height, THRESHOLD_PX)
        except RigidMotionError as exc:
            raise RigidMotionError(f"scene {self.cfg.name}: {exc}") from None
        for job in self.jobs:
            job.dynamic = {(k, j): by_time[(k, int(self.kept[j]))] for k, j in views}

    def _checkpoint(self, ckpt, next_index, streams, seconds, t_start) -> None:
        state = {"next_index": next_index}
        elapsed = time.perf_counter() - t_start
        for job, (sims, spools, stacks), secs in zip(self.jobs, streams, seconds):
            p = job._prefix()
            for k, (sim, spool) in enumerate(zip(sims, spools)):
                state[f"{p}n_events_{k}"] = spool.sync()
                state.update({f"{p}sim{k}__{key}": v for key, v in sim.state_dict().items()})
            for (level, k), stack in stacks.items():
                state.update(stack.state(f"{p}blur__{level}__{k}__"))
            state.update({f"{p}seconds_{name}": v + (elapsed if name == "total" and job is self else 0.0)
                          for name, v in secs.items()})
        ckpt.save(state)

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default=None, help="scene name (blender_scenes/<name>.yaml)")
    ap.add_argument("--scene-file", type=Path, default=None,
                    help="a scene made elsewhere (.blend, .glb/.gltf, .fbx, .obj, .usd*, .abc); its stem names it")
    ap.add_argument("--kind", choices=("object", "room"), default="object",
                    help="with --scene-file: cameras around the content (object) or inside it (room)")
    ap.add_argument("--preset", default="quick", help="dataset preset (configs/dataset_<preset>.yaml) or a YAML path")
    ap.add_argument("--scene-config", type=Path, help="use this scene YAML instead of the scene's own")
    ap.add_argument("--out", type=Path, required=True, help="dataset root; the scene goes to OUT/<scene>")
    ap.add_argument("--checkpoint-every", type=positive_int, default=100, metavar="N", help="timestamps between checkpoints")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--position", type=int, default=0, help="progress-bar line (when several scenes run side by side)")
    args = ap.parse_args(argv)
    if bool(args.scene) == bool(args.scene_file):
        ap.error("give --scene NAME or --scene-file FILE")
    try:
        preset = load_preset(args.preset)
        cfg = resolve_scene(args.scene, preset.scene(args.scene), args.scene_config) if args.scene else None
        if args.scene_file or cfg.source.file:
            from datagen.scene_file import file_scene_config

            cfg = file_scene_config(args, preset, cfg)
        poses = None
        if cfg.source.cameras:                 # the file (loaded by file_scene_config) films with its own cameras
            from datagen.scene_file import file_camera_poses

            t_us = timestamps_us(cfg)
            poses = file_camera_poses(cfg, t_us / t_us[-1])
        job = SceneJob(cfg, args.out, str(args.preset), args.checkpoint_every, not args.no_progress, args.position,
                       poses=poses)
        with output_lock(job.dir):       # two generators of one scene folder would corrupt each other
            job.run()
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as exc:
        if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
            print(f"error: {exc.filename}: {exc.strerror}", file=sys.stderr)      # a full disk: the file it met
        else:
            print(f"error: {' '.join(str(exc).split())}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
