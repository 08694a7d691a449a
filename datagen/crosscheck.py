"""A generated scene's ground truth against Blender itself, by a second implementation of each map.

    python -m datagen.crosscheck data/tiny/cubes [--cameras 0,1] [--frames 0,2] [--json OUT]

Rebuilds the scene from its scene.yaml and, at kept frames of chosen cameras:
- renders Cycles' own passes at 1 sample (Depth, Normal, Object Index) and compares them with the
  stored depth, normals and ids. Cycles' Depth pass is planar z-depth like ours; its Normal pass is
  the world shading normal. Cycles samples a random point inside each pixel, ours is the pixel
  centre: pixels within one pixel of an edge (of depth or id) are left out of the depth and normal
  figures, and reported as a count;
- renders Cycles' Vector pass at the integer Blender frame nearest each kept frame, the camera
  keyframed either side, and compares it with the toolkit's tracking over the same step (the
  machinery of the stored velocity and flow: surface points by ray cast, carried by their parts'
  motion, projected). Cycles takes the pass over one Blender frame either side (the built-in scenes
  span 1000 over the clip) where the stored velocity spans the neighbouring rendered timestamps, so
  the stored map itself is not what is compared;
- checks every flow label against exact visibility computed without the toolkit's tracer: each
  pixel's surface point found by Blender's scene ray cast, carried to frame j + 1 by its object's
  world matrix (rigid parts; a part whose mesh deforms is skipped and counted), and seen from frame
  j + 1's camera centre by another scene ray cast. Reported: the share of labelled-occluded pixels
  that are visible and of labelled-valid pixels that are hidden, for the stored labels and for the
  depth-test rule the toolkit used before (the later depth map at the landing pixel nearer by 2 %).

Prints one table per scene; `--json` writes the figures.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

EDGE_PX = 1                # pixels this close to a depth or id edge are left out (sub-pixel sampling)
OLD_OCCLUSION_REL = 0.02   # the depth-test rule the flow labels used before the ray cast


def _edges(depth: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """bool [H, W]: pixels within EDGE_PX of a change of id or a depth jump of more than 5 %."""
    import cv2

    jump = np.zeros(depth.shape, bool)
    for axis in (0, 1):
        a = np.diff(depth, axis=axis)
        rel = np.abs(a) > 0.05 * np.maximum(np.minimum(np.delete(depth, -1, axis), np.delete(depth, 0, axis)), 1e-6)
        diff_id = np.diff(ids.astype(np.int64), axis=axis) != 0
        e = rel | diff_id
        pad = [(0, 1) if i == axis else (0, 0) for i in range(2)]
        jump |= np.pad(e, pad) | np.pad(e, [(1, 0) if i == axis else (0, 0) for i in range(2)])
    k = 2 * EDGE_PX - 1
    return cv2.dilate(jump.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool) if k > 1 else jump


def passes_of(path: Path) -> dict[str, np.ndarray]:
    """{pass name: [H, W, C] float32} of a Cycles multilayer EXR (one part per pass)."""
    import OpenEXR

    out = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for part in f.parts:
            chans = part.channels
            names = sorted(chans)
            order = [n for c in "XYZWRGBA" for n in names if n.endswith("." + c)] or names
            out[part.name().split(".", 1)[-1]] = np.stack([np.asarray(chans[n].pixels) for n in order], -1)
    return out


class Scene:
    """A generated scene rebuilt in Blender with its cameras, its time mapping and its parts' ids."""

    def __init__(self, scene_dir: Path):
        import bpy

        from datagen import render as R
        from datagen.generate import timestamps_us
        from datagen.rig import scene_poses
        from scene_format.cameras import intrinsics_from_fov
        from scene_format.config import read_scene_config

        self.dir = Path(scene_dir)
        self.cfg = read_scene_config(self.dir / "scene.yaml")
        c = self.cfg
        self.intr = intrinsics_from_fov(c.render.width, c.render.height, c.camera.fov_x_deg)
        t_us = timestamps_us(c)
        self.tau = t_us / t_us[-1] if t_us[-1] > 0 else np.zeros(len(t_us))
        self.t_us = t_us
        self.poses = scene_poses(c, self.tau)                # [C, T, 4, 4] OpenCV c2w
        self.kept = np.arange(0, c.n_timestamps, c.frames.keep_every)
        self.cams = R.build_scene(c, self.intr)
        self.R, self.bpy = R, bpy
        objects = json.loads((self.dir / "ground_truth" / "objects.json").read_text())["objects"]
        by_name = {o.name: o for o in bpy.context.scene.objects}
        self.parts = {int(i): by_name[name] for i, name in objects.items() if name in by_name}
        for i, o in self.parts.items():
            o.pass_index = i

    def at(self, camera: int, i: int) -> None:
        self.R.set_time(float(self.tau[i]))
        self.R.set_pose(self.cams[camera], self.poses[camera, i])
        self.bpy.context.scene.camera = self.cams[camera]

    def render_passes(self, camera: int, i: int, folder: Path, frame: int | None = None) -> dict[str, np.ndarray]:
        """Cycles' Depth, Normal and Object Index passes at rendered index i, 1 sample; with `frame`
        (an integer Blender frame), the Vector pass there instead, the camera keyframed at the frames
        either side so that the pass sees its motion."""
        import addon_utils

        bpy, R = self.bpy, self.R
        sc = bpy.context.scene
        addon_utils.enable("cycles", default_set=True)
        sc.render.engine = "CYCLES"
        sc.cycles.samples = 1
        sc.cycles.use_denoising = False
        sc.render.use_motion_blur = False
        vl = bpy.context.view_layer
        vl.use_pass_z = vl.use_pass_normal = vl.use_pass_object_index = True
        vl.use_pass_vector = frame is not None
        sc.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
        sc.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
        sc.render.image_settings.color_depth = "32"
        cam = self.cams[camera]
        if frame is None:
            self.at(camera, i)
        else:
            for f, pose in zip((frame - 1, frame, frame + 1), self.poses_at_frames(camera, frame)):
                R.set_pose(cam, pose)
                cam.keyframe_insert("location", frame=f)
                cam.keyframe_insert("rotation_euler", frame=f)
            sc.frame_set(frame)
            sc.camera = cam
        sc.render.filepath = str(folder / "passes.exr")
        try:
            with R._quiet_stdout():
                bpy.ops.render.render(write_still=True)
        finally:
            cam.animation_data_clear()
        return passes_of(folder / "passes.exr")

    def taus_at_frames(self, frame: int) -> np.ndarray:
        """Normalised times [3] of Blender frames frame - 1, frame, frame + 1."""
        return (np.array([frame - 1, frame, frame + 1], np.float64) - self.R._TIME_MAP[0]) / self.R._TIME_MAP[1]

    def poses_at_frames(self, camera: int, frame: int) -> np.ndarray:
        """The camera's OpenCV c2w [3, 4, 4] at Blender frames frame - 1, frame, frame + 1."""
        from datagen.rig import scene_poses

        return scene_poses(self.cfg, self.taus_at_frames(frame))[camera]

    def ray(self, origin: np.ndarray, direction: np.ndarray, distance: float = 1.0e9):
        """Blender's own scene ray cast (the evaluated scene at the current time): (hit, location,
        object) of the first surface along the ray."""
        bpy = self.bpy
        from mathutils import Vector

        dg = bpy.context.evaluated_depsgraph_get()
        hit, loc, _n, _face, obj, _m = bpy.context.scene.ray_cast(dg, Vector(origin.tolist()),
                                                                   Vector(direction.tolist()), distance=distance)
        return hit, np.array(loc), obj


def check_passes(scene: Scene, camera: int, j: int, folder: Path) -> dict:
    """Depth, normal and id figures of kept frame j of `camera` against Cycles' passes."""
    from scene_format.reader import SceneDataset

    i = int(scene.kept[j])
    p = scene.render_passes(camera, i, folder)
    gt = SceneDataset(scene.dir).ground_truth(camera, j)
    ids_c = np.rint(p["Object Index"][..., 0]).astype(np.int64)
    depth_c = p["Depth"][..., 0]
    seen = gt.depth_m > 0
    edges = _edges(gt.depth_m, gt.ids)
    interior = seen & ~edges & (ids_c == gt.ids)
    out = {"camera": camera, "frame": j, "pixels_seen": int(seen.sum()), "near_edges": int((seen & edges).sum()),
           "ids_agree_off_edges": float(np.mean((ids_c == gt.ids)[~edges])) if (~edges).any() else 1.0}
    dd = np.abs(depth_c[interior] - gt.depth_m[interior])
    out["depth_median_m"], out["depth_p95_m"] = (float(np.median(dd)), float(np.percentile(dd, 95))) if dd.size else (0.0, 0.0)
    # Cycles' Normal pass: world shading normals; ours: camera frame (OpenCV) turned to face the camera
    c2w = scene.poses[camera, i]
    n_world = p["Normal"][..., :3] @ c2w[:3, :3]                 # world -> camera: R^T n (row vectors)
    n_ours = gt.normals
    cosang = np.abs(np.sum(n_world * n_ours, -1))[interior]
    ang = np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    out["normal_median_deg"], out["normal_p95_deg"] = (float(np.median(ang)), float(np.percentile(ang, 95))) if ang.size else (0.0, 0.0)
    return out


def check_vector(scene: Scene, camera: int, j: int, folder: Path) -> dict:
    """Cycles' Vector pass against the toolkit's tracking (the machinery of the stored velocity and
    flow: surface points by ray cast, carried by their parts' motion, projected) over the same step:
    one Blender frame either side of the integer frame nearest kept frame j. Cycles' vectors in our
    pixels per Blender frame: ((-X - Z) / 2, (Y + W) / 2) (previous - current in X, Y, current - next
    in Z, W, y up)."""
    from datagen import ground_truth as G
    from datagen.render_geometry import SurfaceTracer

    i = int(scene.kept[j])
    frame = int(round(scene.R._TIME_MAP[0] + scene.R._TIME_MAP[1] * float(scene.tau[i])))
    frame = min(max(frame, int(scene.R._TIME_MAP[0]) + 1), int(scene.R._TIME_MAP[0] + scene.R._TIME_MAP[1]) - 1)
    p = scene.render_passes(camera, i, folder, frame=frame)
    v = p["Vector"]
    cycles = np.stack([(-v[..., 0] - v[..., 2]) / 2, (v[..., 1] + v[..., 3]) / 2], -1)
    K, W, H = scene.intr.K, scene.cfg.render.width, scene.cfg.render.height
    poses = scene.poses_at_frames(camera, frame)
    tracer = SurfaceTracer(scene.taus_at_frames(frame))
    s = tracer.views_at(1, {camera: poses[1]}, K, W, H)[camera]
    uv, _z = G.track_uv(s, tracer.motion, poses, K, np.array([0, 2]))
    ours = G.instant_flow(uv[0], uv[1], 2.0, s.hit, W, H)          # px per Blender frame
    depth = G.depth_image(s, poses[1], W, H)
    ids = G.id_image(s, W, H)
    interior = (depth > 0) & ~_edges(depth, ids)
    diff = np.linalg.norm(cycles - ours, axis=-1)[interior]
    speed = np.linalg.norm(ours, axis=-1)[interior]
    return {"camera": camera, "frame": j, "blender_frame": frame, "pixels": int(interior.sum()),
            "vector_median_px": float(np.median(diff)) if diff.size else 0.0,
            "vector_p95_px": float(np.percentile(diff, 95)) if diff.size else 0.0,
            "speed_median_px": float(np.median(speed)) if speed.size else 0.0}


def check_occlusion(scene: Scene, camera: int, j: int, stride: int = 1) -> dict:
    """The stored flow labels of kept frame j -> j + 1 (and the old depth-test rule's) against exact
    visibility by Blender's scene ray cast (module note)."""
    from datagen.ground_truth import VISIBLE_ABS_M, VISIBLE_REL
    from scene_format.reader import SceneDataset

    d = SceneDataset(scene.dir)
    gt, nxt = d.ground_truth(camera, j), d.ground_truth(camera, j + 1)
    i0, i1 = int(scene.kept[j]), int(scene.kept[j + 1])
    K = scene.intr.K
    H, W = gt.depth_m.shape
    ys, xs = np.nonzero(gt.depth_m > 0)
    keep = (ys % stride == 0) & (xs % stride == 0)
    ys, xs = ys[keep], xs[keep]
    scene.at(camera, i0)
    c0 = scene.poses[camera, i0]
    local, owner = [], []
    deforming = 0
    for x, y in zip(xs.tolist(), ys.tolist()):
        d_cam = np.linalg.inv(K) @ np.array([x + 0.5, y + 0.5, 1.0])
        hit, loc, obj = scene.ray(c0[:3, 3], c0[:3, :3] @ d_cam)
        if not hit or obj is None or getattr(obj.data, "shape_keys", None) is not None or any(
                m.type in ("ARMATURE", "CAST", "DISPLACE", "WAVE", "SIMPLE_DEFORM", "LATTICE") for m in obj.modifiers):
            deforming += int(hit)
            local.append(None)
            owner.append(None)
            continue
        m = np.array(obj.matrix_world)
        local.append(np.linalg.inv(m) @ np.append(loc, 1.0))
        owner.append(obj.name)
    scene.at(camera, i1)
    c1 = scene.poses[camera, i1]
    mats = {o.name: np.array(o.matrix_world) for o in scene.bpy.context.scene.objects if o.type == "MESH"}
    counts = {"checked": 0, "deforming_skipped": deforming, "labelled_occluded": 0, "occluded_but_visible": 0,
              "labelled_valid": 0, "valid_but_hidden": 0, "old_occluded": 0, "old_occluded_but_visible": 0,
              "old_valid": 0, "old_valid_but_hidden": 0}
    for x, y, loc, name in zip(xs.tolist(), ys.tolist(), local, owner):
        if loc is None:
            continue
        p1 = (mats[name] @ loc)[:3]
        pc = np.linalg.inv(c1) @ np.append(p1, 1.0)
        if pc[2] <= 1e-6:
            continue
        u, v = K[0, 0] * pc[0] / pc[2] + K[0, 2], K[1, 1] * pc[1] / pc[2] + K[1, 2]
        if not (0 <= u < W and 0 <= v < H):
            continue
        ray = p1 - c1[:3, 3]
        length = float(np.linalg.norm(ray))
        hit, _loc, _obj = scene.ray(c1[:3, 3], ray / length, max(length * (1 - VISIBLE_REL) - VISIBLE_ABS_M, 0.0))
        visible = not hit
        counts["checked"] += 1
        occluded, valid = bool(gt.flow_occluded[y, x]), bool(gt.flow_valid[y, x])
        counts["labelled_occluded"] += occluded
        counts["occluded_but_visible"] += occluded and visible
        counts["labelled_valid"] += valid
        counts["valid_but_hidden"] += valid and not visible
        dn = float(nxt.depth_m[int(v), int(u)])
        old_occ = dn <= 0 or dn < pc[2] * (1 - OLD_OCCLUSION_REL)
        counts["old_occluded"] += old_occ
        counts["old_occluded_but_visible"] += old_occ and visible
        counts["old_valid"] += not old_occ
        counts["old_valid_but_hidden"] += (not old_occ) and not visible
    counts["disagree"] = counts["occluded_but_visible"] + counts["valid_but_hidden"]
    counts["old_disagree"] = counts["old_occluded_but_visible"] + counts["old_valid_but_hidden"]
    return {"camera": camera, "frame": j, **counts}


def _ints(text: str) -> list[int]:
    try:
        return [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", type=Path, help="a generated scene folder with ground truth (depth, flow, normals, ids)")
    p.add_argument("--cameras", type=_ints, default=[0], help="comma-separated cameras (default 0)")
    p.add_argument("--frames", type=_ints, default=None, help="comma-separated kept frames (default: first and middle)")
    p.add_argument("--stride", type=int, default=1, help="check every n-th pixel's occlusion label (default 1)")
    p.add_argument("--no-passes", action="store_true", help="skip the Cycles passes (occlusion only)")
    p.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = p.parse_args(argv)
    man = args.scene / "manifest.json"
    if not man.is_file():
        raise SystemExit(f"error: {args.scene}: no manifest.json (a generated scene folder)")
    kinds = (json.loads(man.read_text()).get("ground_truth") or {}).get("kinds") or []
    if not {"depth", "flow", "normals", "ids"} <= set(kinds):
        raise SystemExit(f"error: {args.scene}: its ground truth holds {kinds or 'nothing'}; the cross-check needs "
                         "depth, flow, normals and ids")
    scene = Scene(args.scene)
    n_kept = len(scene.kept)
    frames = args.frames if args.frames is not None else sorted({0, n_kept // 2})
    bad = [j for j in frames if not 0 <= j < n_kept - 1] + [k for k in args.cameras if not 0 <= k < len(scene.cams)]
    if bad or args.stride < 1:
        raise SystemExit(f"error: --frames 0..{n_kept - 2} and --cameras 0..{len(scene.cams) - 1}, --stride >= 1 "
                         f"(got {bad or args.stride})")
    out = {"scene": str(args.scene), "passes": [], "vector": [], "occlusion": []}
    with tempfile.TemporaryDirectory(prefix="e4dgs-crosscheck-") as tmp:
        for k in args.cameras:
            for j in frames:
                if not args.no_passes:
                    out["passes"].append(check_passes(scene, k, j, Path(tmp)))
                    out["vector"].append(check_vector(scene, k, j, Path(tmp)))
                out["occlusion"].append(check_occlusion(scene, k, j, args.stride))
    print("| camera | frame | depth median / p95 (m) | normal median / p95 (deg) | ids agree off edges | "
          "pixels seen | near edges |")
    print("|---|---|---|---|---|---|---|")
    for r in out["passes"]:
        print(f"| {r['camera']} | {r['frame']} | {r['depth_median_m']:.1e} / {r['depth_p95_m']:.1e} | "
              f"{r['normal_median_deg']:.3f} / {r['normal_p95_deg']:.3f} | {r['ids_agree_off_edges']:.4f} | "
              f"{r['pixels_seen']} | {r['near_edges']} |")
    if out["vector"]:
        print("\nCycles' Vector pass against the tracking, one Blender frame either side (px per frame):")
        print("| camera | frame | Blender frame | pixels | difference median / p95 | speed median |")
        print("|---|---|---|---|---|---|")
        for r in out["vector"]:
            print(f"| {r['camera']} | {r['frame']} | {r['blender_frame']} | {r['pixels']} | {r['vector_median_px']:.2e} / "
                  f"{r['vector_p95_px']:.2e} | {r['speed_median_px']:.3g} |")
    tot = {k: sum(r[k] for r in out["occlusion"]) for k in out["occlusion"][0] if k not in ("camera", "frame")}
    out["occlusion_total"] = tot
    print(f"\nocclusion labels against exact visibility ({tot['checked']} tracked points; {tot['deforming_skipped']} on "
          "deforming parts skipped):")
    print("| labels | occluded but visible | valid but hidden | disagree |")
    print("|---|---|---|---|")
    for name, pre in (("stored (ray cast)", ""), ("depth test, 2 % (before)", "old_")):
        occ, valid = tot[f"{pre}occluded" if pre else "labelled_occluded"], tot[f"{pre}valid" if pre else "labelled_valid"]
        print(f"| {name} | {tot[pre + 'occluded_but_visible']} of {occ} | {tot[pre + 'valid_but_hidden']} of {valid} | "
              f"{tot[pre + 'disagree'] / max(tot['checked'], 1):.2%} |")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
