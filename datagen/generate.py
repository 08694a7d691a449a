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
metadata, manifests, exports) are datagen.scene_folder, what it will write is its plan
(datagen.scene_plan); this module is the loop.
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
from datagen.scene_plan import ScenePlan, make_plan, measure, timestamps_us
from scene_format.config import SceneConfig
from datagen.config import load_preset, resolve_scene
from datagen.temporal_sampling import blend_weights
from common.checkpoint import JobCheckpoint
from common.config import ConfigError
from common.argtypes import positive_int
from common.fileio import link_tree, output_lock
from common.imageio import write_png_srgb
from eventio.h5io import simulator_attrs
from common.color import rec709_luma
from simulator.resumable import EventSpool, can_resume
from simulator.simulator import EventSimulator

class SceneJob:
    """Runs one scene's generation loop over its plan (datagen.scene_plan); `run()` does the work
    (resuming if a checkpoint matches)."""

    def __init__(self, cfg: SceneConfig, out_root: Path, preset: str = "custom", checkpoint_every: int = 100,
                 progress: bool = True, position: int = 0, folder: str | None = None, poses: np.ndarray | None = None):
        if int(checkpoint_every) < 1:
            raise ValueError(f"checkpoint_every: expected an integer >= 1, got {checkpoint_every!r}")
        self.checkpoint_every, self.progress, self.position = int(checkpoint_every), progress, position
        # [C, T, 4, 4] OpenCV c2w: the rig's, or given (a file's own cameras, read from it by the caller)
        self.plan = make_plan(cfg, out_root, preset, folder, poses=poses)
        self.cfg, self.dir = cfg, self.plan.dir

    def _log(self, line: str) -> None:
        if self.progress:
            print(line, flush=True)

    def is_complete(self) -> bool:
        """Whether the scene (and so its variants, written before it) is complete with this config."""
        manifest = self.dir / "manifest.json"
        if not manifest.exists():
            return False
        if not scene_folder.same_config(json.loads(manifest.read_text()), self.cfg):
            raise ValueError(f"{self.dir} holds a complete scene generated with another config; "
                             "remove it or choose another --out")
        return True

    # -- the loop ----------------------------------------------------------------------------
    def run(self) -> Path:
        """Generate the scene: measure the blur, then render, simulate and write every timestamp
        (resuming a checkpoint), then finish the event files and the metadata."""
        cfg, plan = self.cfg, self.plan
        if self.is_complete():
            print(f"{self.dir}: complete, skipped")
            scene_folder.write_exports(plan)
            return self.dir
        t_start = time.perf_counter()
        cams = R.build_scene(cfg, plan.intr)
        t_blur = time.perf_counter()
        cached = geometry_cache.load(self.dir, plan.fingerprint, plan.plans)     # False without a folder or file
        if cached:      # an earlier start measured it (15-27 min in a paper-preset room)
            print(f"{cfg.name}: blur exposures, dynamic masks and render schedule from an earlier start "
                  f"({geometry_cache.FILE_NAME})", flush=True)
        else:       # before anything is written: a blur level out of reach leaves no output behind
            measure(plan, self._log)
        t_blur = time.perf_counter() - t_blur
        self.dir.mkdir(parents=True, exist_ok=True)
        if not cached:
            geometry_cache.save(self.dir, plan.fingerprint, plan.plans)
        renderer = R.ViewRenderer()
        ckpt = JobCheckpoint(self.dir / ".generate.ckpt.npz", plan.fingerprint)
        state = self._resumable_state(ckpt)
        streams = [self._open_streams(p, state) for p in plan.plans]
        sims, spools, stacks = streams[0]
        start = int(state.get("next_index", 0))
        if start:
            print(f"{cfg.name}: resuming at timestamp {start} of {cfg.n_timestamps}", flush=True)
        seconds = [{name: float(state.get(f"{_prefix(p)}seconds_{name}", 0.0))
                    for name in ("blur_geometry", "render", "simulate", "write", "total")} for p in plan.plans]
        seconds[0]["blur_geometry"] += t_blur
        bar = tqdm(range(start, cfg.n_timestamps), desc=cfg.name, unit="ts", initial=start, total=cfg.n_timestamps,
                   disable=not self.progress, dynamic_ncols=True, position=self.position)
        rendered = set(plan.rendered.tolist())
        # the rendered frame before `start` (resuming an adaptive run): the blend anchor of the frames it skips
        anchor = (start - 1, self._render(start - 1, cams, renderer, seconds[0])) if start and len(rendered) < cfg.n_timestamps else None
        last_ckpt = start
        try:
            for i in bar:
                if i not in rendered:
                    continue
                frames = self._render(i, cams, renderer, seconds[0])
                if anchor is not None and anchor[0] < i - 1:          # the frames skipped since the last render
                    for p, stream, secs in zip(plan.plans, streams, seconds):
                        self._blend_skipped(p, anchor, (i, frames), stream[2], secs)
                for p, stream, secs in zip(plan.plans, streams, seconds):
                    self._consume(p, i, frames, *stream, secs)
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
        for p, (p_sims, p_spools, _), secs in zip(plan.plans, streams, seconds):
            for sim, spool in zip(p_sims, p_spools):
                tail = sim.flush()              # what the readout still holds (latency, bandwidth)
                spool.append(tail)
                spool.finish(t_end_us=max(int(p.t_us[-1]), int(tail["t"][-1]) if tail.size else 0))
        ground_truth, ids = None, {}
        if cfg.ground_truth:                        # after the loop: the frames it checks the flow against exist
            from datagen.ground_truth_files import write_ground_truth

            ground_truth, ids = write_ground_truth(plan, cfg.ground_truth)
            seconds[0]["ground_truth"] = ground_truth["seconds"]
        seconds[0]["total"] += time.perf_counter() - t_start
        for variant, secs in zip(plan.variants, seconds[1:]):   # before the scene's manifest, which marks completion
            t0 = time.perf_counter()
            for part in ("frames", "rgb", "gray"):        # the same sharp frames: hard links where possible
                link_tree(self.dir / part, variant.dir / part)
            shared = None
            if ground_truth:
                from datagen.ground_truth_files import share_with_variant

                shared = share_with_variant(plan, variant, ground_truth, ids)
            secs["write"] += time.perf_counter() - t0
            secs["total"] = secs["simulate"] + secs["write"]      # its own work; the render is the scene's
            scene_folder.write_metadata(variant, secs, shared)
        scene_folder.write_metadata(plan, seconds[0], ground_truth)
        ckpt.remove()
        geometry_cache.remove(self.dir)
        scene_folder.write_exports(plan)
        return self.dir

    def _resumable_state(self, ckpt: JobCheckpoint) -> dict:
        """The checkpoint's state if its event spools hold what it records, else {} (start over, saying why)."""
        state = ckpt.load() or {}
        if state and not all(can_resume(_event_path(p, k), int(state[f"{_prefix(p)}n_events_{k}"]))
                             for p in self.plan.plans for k in range(self.cfg.camera.n_cameras)):
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
        for p in self.plan.plans:
            key0 = f"{_prefix(p)}sim"
            for k in range(cfg.camera.n_cameras):
                prefix = f"{key0}{k}__"
                try:
                    EventSimulator(p.cfg.sensor, W, H, seed=p.cfg.event_seed * 1000 + k).load_state_dict(
                        {key[len(prefix):]: v for key, v in state.items() if key.startswith(prefix)})
                except (ValueError, KeyError) as exc:
                    return f"camera {k} of {p.dir.name}: {exc}"
        return None

    @staticmethod
    def _open_streams(p: ScenePlan, state: dict):
        """Per camera of plan p: the simulator, the event spool and the blur accumulators, restored
        from `state` (p's keys carry its prefix)."""
        cfg, prefix = p.cfg, _prefix(p)
        C, W, H = cfg.camera.n_cameras, cfg.render.width, cfg.render.height
        sims = [EventSimulator(cfg.sensor, W, H, seed=cfg.event_seed * 1000 + k) for k in range(C)]
        attrs = {**simulator_attrs(cfg.sensor), "scene": cfg.name}
        if cfg.speed != 1:
            attrs["speed"] = cfg.speed
        spools = []
        for k in range(C):
            spools.append(EventSpool(_event_path(p, k), W, H, attrs={**attrs, "camera": k, "seed": cfg.event_seed * 1000 + k},
                                     resume_count=int(state[f"{prefix}n_events_{k}"]) if state else None))
            if state:
                key0 = f"{prefix}sim{k}__"
                sims[k].load_state_dict({key[len(key0):]: v for key, v in state.items() if key.startswith(key0)})
        stacks = {(level, k): BlurStack(p.windows[level]) for level in p.windows for k in range(C)}
        for (level, k), stack in stacks.items():
            stack.load_state(state, f"{prefix}blur__{level}__{k}__")
        return sims, spools, stacks

    def _render(self, i: int, cams, renderer, seconds: dict) -> list[np.ndarray]:
        """Every camera's linear frame [H, W, 3] at rendered timestamp i."""
        cfg, plan = self.cfg, self.plan
        t0 = time.perf_counter()
        R.set_time(float(plan.tau[i]))
        R.set_noise_seed(cfg.seed * 100_003 + i)
        frames = []
        for k, cam in enumerate(cams):
            R.set_pose(cam, plan.poses[k, i])
            frames.append(renderer.render(cam) * np.float32(cfg.lighting.exposure))
        seconds["render"] += time.perf_counter() - t0
        return frames

    def _consume(self, p: ScenePlan, i: int, frames: list[np.ndarray], sims, spools, stacks, seconds: dict) -> None:
        """Feed frame i of every camera to plan p's simulators (at p's timestamp of i), write it if kept
        (the scene only: variants link the scene's), and add it to p's blur sums."""
        t1 = time.perf_counter()
        for k, frame in enumerate(frames):
            spools[k].append(sims[k].push(rec709_luma(frame), int(p.t_us[i])))
        t2 = time.perf_counter()
        kept_index = p.kept_index.get(i) if not p.is_variant else None
        for k, frame in enumerate(frames):
            if kept_index is not None:
                scene_folder.write_kept(p.dir, k, kept_index, frame)
            for level in p.windows:
                for j, mean in stacks[(level, k)].add(i, frame):
                    write_png_srgb(p.dir / "blur" / level / f"cam{k}" / f"{j:05d}.png", mean)
        seconds["simulate"] += t2 - t1
        seconds["write"] += time.perf_counter() - t2

    @staticmethod
    def _blend_skipped(p: ScenePlan, a: tuple[int, list], b: tuple[int, list], stacks, seconds: dict) -> None:
        """The frames between rendered frames a and b ((index, frames per camera)) into plan p's blur sums,
        as linear-light blends of the two (datagen.temporal_sampling); the simulator sees only rendered frames."""
        if not p.windows:
            return
        t0 = time.perf_counter()
        (ia, fa), (ib, fb) = a, b
        for m in range(ia + 1, ib):
            levels = [lv for lv, wins in p.windows.items() if any(first <= m <= last for first, last in wins.values())]
            if not levels:                       # in no exposure: nothing to blend
                continue
            w = np.float32(blend_weights(ia, ib, m))
            for k in range(len(fa)):
                frame = fa[k] * (1 - w) + fb[k] * w
                for level in levels:
                    for j, mean in stacks[(level, k)].add(m, frame):
                        write_png_srgb(p.dir / "blur" / level / f"cam{k}" / f"{j:05d}.png", mean)
        seconds["write"] += time.perf_counter() - t0

    def _checkpoint(self, ckpt, next_index, streams, seconds, t_start) -> None:
        state = {"next_index": next_index}
        elapsed = time.perf_counter() - t_start
        for p, (sims, spools, stacks), secs in zip(self.plan.plans, streams, seconds):
            pre = _prefix(p)
            for k, (sim, spool) in enumerate(zip(sims, spools)):
                state[f"{pre}n_events_{k}"] = spool.sync()
                state.update({f"{pre}sim{k}__{key}": v for key, v in sim.state_dict().items()})
            for (level, k), stack in stacks.items():
                state.update(stack.state(f"{pre}blur__{level}__{k}__"))
            state.update({f"{pre}seconds_{name}": v + (elapsed if name == "total" and p is self.plan else 0.0)
                          for name, v in secs.items()})
        ckpt.save(state)


def _prefix(p: ScenePlan) -> str:
    """Checkpoint key prefix of a plan's state: '' for the scene, '<folder>__' for a variant."""
    return f"{p.dir.name}__" if p.is_variant else ""


def _event_path(p: ScenePlan, camera: int) -> Path:
    return p.dir / "events" / f"cam{camera}.h5"


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
