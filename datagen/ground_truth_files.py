"""Write a scene's per-pixel ground truth (datagen.ground_truth) beside its frames, after the render
loop, for every kept frame of every camera:

    ground_truth/objects.json              {"1": part name, ...}; id 0 = no surface; the parts each joined
                                           object holds; units and conventions
    ground_truth/depth/cam<k>/<j>.exr      float32 z-depth, metres, camera frame; 0 = no surface
    ground_truth/normals/cam<k>/<j>.exr    float32 R,G,B = unit normal (x, y, z) in the camera frame; 0 = none
    ground_truth/ids/cam<k>/<j>.png        uint16 object id
    ground_truth/flow/cam<k>/<j>.png       DSEC-Flow 16-bit PNG: forward flow to kept frame j + 1 (not for the last)
    ground_truth/flow/cam<k>/<j>.npz       float32 forward_px [H, W, 2], bool valid, occluded (j + 1 exists)
    ground_truth/velocity/cam<k>/<j>.npz   float32 px_per_ms [H, W, 2]: image velocity at kept frame j (with flow)
    ground_truth/event_ids/cam<k>.npy      uint8 / uint16 [N]: the object id at each event's pixel (in the event
                                           file's order), from the kept frame nearest its time (with ids)

and returns the manifest's `ground_truth` entry (kinds, rate, conventions, the brightness-constancy
check: PSNR of frame j against frame j + 1 warped back by the flow, over valid pixels) with the object
id maps it wrote (the speed variants label their own events with them).
"""
from __future__ import annotations

import json
import time

import numpy as np

from common.fileio import write_text_atomic
from common.flow import encode_dsec_flow
from common.imageio import read_exr, write_exr, write_png
from datagen import ground_truth as G

CONVENTIONS = {
    "pixels": "pixel (x, y) is the ray through (x + 0.5, y + 0.5); OpenCV camera axes (x right, y down, z forward)",
    "depth": "z-depth in metres along the camera's z axis (not the ray length); 0 where no surface is seen",
    "normals": "unit shading normals in the camera frame (the triangle's corner normals interpolated at the point, "
               "as the renderer shades it: smooth faces vary, flat faces give the face normal), turned to face the "
               "camera; 0 where no surface is seen",
    "ids": "1 + the index of the scene part seen (objects.json names them); 0 where no surface is seen; static parts "
           "that share a parent are one object, named after its first part (objects.json's joined lists them)",
    "flow": "forward: where the surface point seen at a pixel of kept frame j is at kept frame j + 1, minus the "
            "pixel (camera and object motion); valid where it is in front of the camera, inside the image and "
            "visible: the ray from frame j + 1's camera centre to the tracked point meets no surface before it "
            "(occluded: in front and inside but hidden); DSEC-Flow PNG: channels (x, y, valid), "
            "value = flow * 128 + 2**15",
    "velocity": "px_per_ms: image velocity of the point seen at each pixel, by a central difference over the "
                "neighbouring rendered timestamps, pixels per millisecond of the scene's time (a speed variant's: "
                "times its speed factor; it keeps no velocity files of its own)",
}


def write_ground_truth(plan, kinds: tuple[str, ...], log=print) -> tuple[dict, dict[int, np.ndarray]]:
    """Every kept frame's ground truth of `kinds` for the scene currently built (plan: its
    datagen.scene_plan.ScenePlan): (the manifest's entry, {camera: [K, H, W] object ids} when ids
    were written, else {})."""
    from datagen.render_geometry import SurfaceTracer

    t0 = time.perf_counter()
    cfg, d = plan.cfg, plan.dir / "ground_truth"
    W, H, C, K = cfg.render.width, cfg.render.height, cfg.camera.n_cameras, plan.intr.K
    dt_ms = 1000.0 / cfg.real_fps                        # real time between rendered frames
    T = len(plan.tau)
    tracer = SurfaceTracer(plan.tau)
    objects = {str(n + 1): name for n, name in enumerate(tracer.names)}
    joined = {str(n + 1): parts for n, parts in sorted(tracer.joined.items())}
    write_text_atomic(d / "objects.json", json.dumps({"objects": objects, "joined": joined, "conventions": CONVENTIONS},
                                                     indent=1))
    flow = "flow" in kinds
    warp, identity = [], []
    ids_by_camera = {k: [] for k in range(C)}          # the event labels' look-up (with ids)
    prev = None                                         # (j, {k: ViewSurface})
    frames: dict = {}                                   # linear kept frames read for the warp check, each once
    for j, i in enumerate(plan.kept.tolist()):
        surf = tracer.views_at(i, {k: plan.poses[k, i] for k in range(C)}, K, W, H)
        for k, s in surf.items():
            name = f"cam{k}/{j:05d}"
            if "depth" in kinds:
                write_exr(d / "depth" / f"{name}.exr", G.depth_image(s, plan.poses[k, i], W, H))
            if "normals" in kinds:
                write_exr(d / "normals" / f"{name}.exr", G.normal_image(s, plan.poses[k, i], W, H))
            if "ids" in kinds:
                ids_by_camera[k].append(G.id_image(s, W, H))
                write_png(d / "ids" / f"{name}.png", ids_by_camera[k][-1])
        if flow:
            a, b = max(i - 1, 0), min(i + 1, T - 1)
            for k, s in surf.items():
                uv, _z = G.track_uv(s, tracer.motion, plan.poses[k], K, np.array([a, b]))
                _save_npz(d / "velocity" / f"cam{k}" / f"{j:05d}.npz",
                          px_per_ms=G.instant_flow(uv[0], uv[1], (b - a) * dt_ms, s.hit, W, H))
            if prev is not None:
                _write_forward(plan, d, prev, i, tracer, frames, warp, identity)
        prev = (j, surf)
    events_by_object, ids = None, {}
    if "ids" in kinds:
        ids = {k: np.stack(v) for k, v in ids_by_camera.items()}   # the variants label with them too
        frame_times = plan.t_us[plan.kept]
        events_by_object = [label_events(plan.dir, d, k, frame_times, ids[k], objects) for k in range(C)]
    seconds = time.perf_counter() - t0
    out = {"kinds": list(kinds), "frames": "every kept frame of every camera",
           "rate_fps": round(cfg.real_fps / cfg.frames.keep_every, 6), "objects": objects, "joined": joined,
           "conventions": {k: CONVENTIONS[k] for k in ("pixels", *kinds, *(("velocity",) if flow else ()))},
           "seconds": round(seconds, 3)}
    if events_by_object is not None:
        out["events_by_object"] = events_by_object
    if warp:
        out["warp_check"] = {"psnr_db_warped": round(float(np.mean(warp)), 3),
                             "psnr_db_unwarped": round(float(np.mean(identity)), 3), "views": len(warp),
                             "what": "kept frame j against frame j + 1 warped back by the forward flow (linear "
                                     "light, clipped to [0, 1]), over the flow's valid pixels; unwarped: the same "
                                     "pixels without the flow"}
    log(f"{cfg.name}: ground truth ({', '.join(kinds)}) of {len(plan.kept)} kept frames x {C} cameras in {seconds:.0f} s")
    return out, ids


def _write_forward(plan, d, prev, i1: int, tracer, frames: dict, warp: list, identity: list) -> None:
    """The forward flow from the previous kept frame to this one (rendered index i1, the tracer's last
    views_at), per camera, with each tracked point's visibility by a ray cast in i1's geometry, and its
    warp check (frames: {(camera, j): linear frame}, each read once and dropped once used)."""
    j0, surf0 = prev
    cfg, K = plan.cfg, plan.intr.K
    W, H = cfg.render.width, cfg.render.height
    for k, s in surf0.items():
        world = G.track_points(s, tracer.motion, np.array([i1]))[0]
        uv, z = G.project_tracks(K, plan.poses[k, i1][None], world[None])
        inside = G.lands_inside(uv[0], z[0], W, H)
        visible = np.zeros(len(world), bool)
        visible[inside] = tracer.visible(world[inside], plan.poses[k, i1])
        fwd, valid, occluded = G.forward_flow(s, uv[0], z[0], visible, W, H)
        folder = d / "flow" / f"cam{k}"
        write_png(folder / f"{j0:05d}.png", encode_dsec_flow(fwd, valid))
        _save_npz(folder / f"{j0:05d}.npz", forward_px=fwd, valid=valid, occluded=occluded)
        f0 = frames.pop((k, j0), None)                 # read as the later frame of the step before
        if valid.any():
            f0 = _linear_frame(plan, k, j0) if f0 is None else f0
            f1 = frames[(k, j0 + 1)] = _linear_frame(plan, k, j0 + 1)
            warp.append(G.masked_psnr(f0, G.warp_backward(f1, fwd), valid))
            identity.append(G.masked_psnr(f0, f1, valid))


def _linear_frame(plan, camera: int, j: int) -> np.ndarray:
    return np.clip(read_exr(plan.dir / "frames" / f"cam{camera}" / f"{j:05d}.exr"), 0, 1)


LABEL_CHUNK = 1 << 22                               # events labelled per read (4 M)


def label_events(scene_dir, d, camera: int, frame_times_us: np.ndarray, ids: np.ndarray, objects: dict) -> dict:
    """Write ground_truth/event_ids/cam<k>.npy (each event's object id, datagen.ground_truth.event_labels)
    and return the camera's event count per object name ("none": pixels that see no surface)."""
    from eventio.event_file import EventFile

    with EventFile(scene_dir / "events" / f"cam{camera}.h5") as ev:
        labels = np.empty(ev.n, np.uint8 if len(objects) < 256 else np.uint16)
        for i0 in range(0, ev.n, LABEL_CHUNK):          # memory bounded by the chunk, not the clip
            i1 = min(i0 + LABEL_CHUNK, ev.n)
            x, y, _p = ev.rows(i0, i1)
            labels[i0:i1] = G.event_labels(ev.times(i0, i1), x, y, frame_times_us, ids)
    _save(d / "event_ids" / f"cam{camera}.npy", lambda f: np.save(f, labels))
    counts = np.bincount(labels, minlength=len(objects) + 1)
    return {"none" if i == 0 else objects[str(i)]: int(n) for i, n in enumerate(counts)}


def _save(path, write) -> None:
    """write(file) into `path` atomically (common.fileio.atomic_output)."""
    from common.fileio import atomic_output

    with atomic_output(path) as tmp:
        with open(tmp, "wb") as f:
            write(f)


def _save_npz(path, **arrays) -> None:
    _save(path, lambda f: np.savez_compressed(f, **arrays))


def share_with_variant(scene, variant, summary: dict, ids: dict[int, np.ndarray]) -> dict:
    """A speed variant shows its scene's frames: the same depth, normals, ids and forward flow (hard
    links); its image velocity is the scene's times the speed factor (its time runs that much faster:
    no files of its own, the reader scales the scene's), and its own events are labelled at its own
    times (scene, variant: their plans; ids: the scene's {camera: [K, H, W] object ids}). Returns the
    variant's manifest entry."""
    from common.fileio import link_tree

    src, dst, speed = scene.dir / "ground_truth", variant.dir / "ground_truth", variant.cfg.speed
    for part in ("depth", "normals", "ids"):
        if (src / part).is_dir():
            link_tree(src / part, dst / part)
    if (src / "flow").is_dir():
        link_tree(src / "flow", dst / "flow")
    write_text_atomic(dst / "objects.json", (src / "objects.json").read_text())
    out = {**summary, "rate_fps": round(summary["rate_fps"] * speed, 6), "shared_with": scene.dir.name,
           "velocity_scale": speed, "seconds": 0.0}
    out.pop("warp_check", None)                    # measured on the scene's frames, which it shares
    if "events_by_object" in summary:                # the scene's id maps, kept from writing them
        frame_times = variant.t_us[variant.kept]
        out["events_by_object"] = [label_events(variant.dir, dst, k, frame_times, camera_ids, summary["objects"])
                                   for k, camera_ids in ids.items()]
    return out
