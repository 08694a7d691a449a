"""A scene from a file (bpy): load a .blend or import glTF / FBX / OBJ / USD / Alembic, read its
animation range, and place the six-camera rig from its animated bounding box.

    cfg = resolve_file_scene({"name": "walker", "kind": "object", "source": {"file": "walker.blend"}})
    cams = render.build_scene(cfg, intr)          # loads it again, then the usual path

Everything after loading (the 3000 FPS render, blur levels, simulator, writer, manifest, masks,
resume) is the built-in scenes' path: only `render.build_scene` branches on `source.file`.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import bpy
import numpy as np

from common.config import ConfigError, from_dict
from scene_format.cameras import intrinsics_from_fov, project
from scene_format.config import RenderConfig, SceneConfig, deep_merge, read_scene_yaml
from datagen.config import file_scene_name

IMPORTERS = {".glb": ("import_scene", "gltf"), ".gltf": ("import_scene", "gltf"), ".fbx": ("import_scene", "fbx"),
             ".obj": ("wm", "obj_import"), ".usd": ("wm", "usd_import"), ".usda": ("wm", "usd_import"),
             ".usdc": ("wm", "usd_import"), ".usdz": ("wm", "usd_import"), ".abc": ("wm", "alembic_import")}
BLEND_MAGIC = (b"BLENDER", b"\x28\xb5\x2f\xfd", b"\x1f\x8b")     # plain, zstd- and gzip-compressed .blend
N_PROBES = 9                  # times at which the animated bounds are sampled
OBJECT_MARGIN = 1.25          # rig distance over the distance at which the bounding sphere just fits
ROOM_FILL = 0.35              # rig radius inside a room, as a fraction of its smaller half extent
ELEVATION_DEG = 20.0          # object rigs look down at the content from this elevation
MIN_IN_VIEW = 0.5             # every camera of an automatic rig must see this share of the moving surface
MIN_IN_VIEW_OWN_RIG = 0.01    # and of a rig set in the scene YAML (source.rig: config), at least this


class SceneFileError(ConfigError):
    """A scene file that cannot be used: the message names the file and what was expected."""


def _call(path: Path, op, **kwargs) -> None:
    try:
        result = op(**kwargs)
    except (RuntimeError, TypeError, ValueError) as exc:
        raise SceneFileError(f"{path}: Blender cannot read it ({' '.join(str(exc).split())[:300]})") from None
    if "FINISHED" not in result:
        raise SceneFileError(f"{path}: Blender's importer did not finish ({', '.join(result)})")


def load_file(path: str | Path) -> None:
    """Replace Blender's scene with the file's (SceneFileError naming the file for anything unusable)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix != ".blend" and suffix not in IMPORTERS:
        raise SceneFileError(f"{path}: unsupported format {suffix or '(none)'!r}; expected .blend or one Blender "
                             f"imports headless ({', '.join(sorted(IMPORTERS))})")
    if not path.is_file():
        raise SceneFileError(f"{path}: no such file")
    if suffix == ".blend":
        with path.open("rb") as f:
            head = f.read(8)
        if not head.startswith(BLEND_MAGIC):
            raise SceneFileError(f"{path}: not a Blender file (it does not start with a .blend header)")
        _call(path, bpy.ops.wm.open_mainfile, filepath=str(path), load_ui=False)
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        module, name = IMPORTERS[suffix]
        _call(path, getattr(getattr(bpy.ops, module), name), filepath=str(path))
    if not mesh_objects():
        raise SceneFileError(f"{path}: no mesh to render (expected at least one mesh object with faces)")


def mesh_objects() -> list:
    return [o for o in bpy.context.scene.objects if o.type == "MESH" and len(o.data.polygons) and not o.hide_render]


def file_animation(path: Path) -> tuple[float, float, float]:
    """(first frame, last frame, frames per second) of the file's animation: the scene's frame range,
    widened to its actions' keys when an importer left the default range."""
    sc = bpy.context.scene
    fps = sc.render.fps / (sc.render.fps_base or 1.0)
    start, end = float(sc.frame_start), float(sc.frame_end)
    if path.suffix.lower() != ".blend":
        ranges = [a.frame_range for a in bpy.data.actions]
        if ranges:
            start, end = min(r[0] for r in ranges), max(r[1] for r in ranges)
    if not end > start:
        raise SceneFileError(f"{path}: empty frame range ({start:g} .. {end:g}); expected an animation of at least "
                             "two frames")
    return start, end, fps


def _world_meshes() -> list[tuple[np.ndarray, np.ndarray]]:
    """(world vertices [V, 3], triangles [F, 3]) of every mesh at the current frame."""
    dg = bpy.context.evaluated_depsgraph_get()
    out = []
    for o in mesh_objects():
        ev = o.evaluated_get(dg)
        me = ev.to_mesh()
        me.calc_loop_triangles()
        co = np.empty(len(me.vertices) * 3)
        me.vertices.foreach_get("co", co)
        tri = np.empty(len(me.loop_triangles) * 3, np.int64)
        me.loop_triangles.foreach_get("vertices", tri)
        m = np.array(ev.matrix_world)
        out.append((co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3], tri.reshape(-1, 3)))
        ev.to_mesh_clear()
    return out


def surface_points(verts: np.ndarray, tris: np.ndarray, n: int = 2000, seed: int = 0) -> np.ndarray:
    """n points spread over a mesh's surface by area (the same triangles and barycentric coordinates
    for the same seed and topology, so a point is followed from probe to probe)."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1) + 1e-12
    rng = np.random.default_rng(seed)
    f = rng.choice(len(tris), n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])


def animated_bounds(path: Path, start: float, end: float) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """(lower corner [3], upper corner [3]) of every mesh over the clip, and points spread over the
    moving meshes' surfaces at each probe time (SceneFileError if nothing moves)."""
    probes = []
    for f in np.linspace(start, end, N_PROBES):
        bpy.context.scene.frame_set(int(math.floor(f)), subframe=float(f - math.floor(f)))
        probes.append(_world_meshes())
    allv = np.concatenate([v for p in probes for v, _ in p])
    ref = probes[0]
    moving = [o for o in range(len(ref))
              if any(p[o][0].shape != ref[o][0].shape or not np.allclose(p[o][0], ref[o][0], atol=1e-6) for p in probes)]
    if not moving:
        raise SceneFileError(f"{path}: nothing moves in frames {start:g} .. {end:g} (expected an animated scene: "
                             "keyframes, an armature, shape keys or a simulation)")
    return allv.min(0), allv.max(0), [np.concatenate([surface_points(*p[o], seed=o) for o in moving if len(p[o][1])])
                                      for p in probes]


def place_rig(kind: str, lo: np.ndarray, hi: np.ndarray, camera: dict, width: int, height: int) -> dict:
    """The camera rig's target, radius and height from the animated bounds (kind object: around them,
    far enough that the bounding sphere fits the narrower field of view with a margin; room: inside,
    at mid height). The rig's radius_change scales with it."""
    centre = (lo + hi) / 2
    fov_x = math.radians(camera.get("fov_x_deg", 50.0))
    fov_y = 2 * math.atan(math.tan(fov_x / 2) * height / width)
    old_radius = camera.get("radius", 4.0)
    if kind == "room":
        radius = ROOM_FILL * float(min(hi[0] - lo[0], hi[1] - lo[1])) / 2
        cam_z = float(centre[2])
    else:
        r = float(np.linalg.norm(hi - lo)) / 2
        dist = OBJECT_MARGIN * r / math.sin(min(fov_x, fov_y) / 2)
        radius, cam_z = dist * math.cos(math.radians(ELEVATION_DEG)), float(centre[2]) + dist * math.sin(math.radians(ELEVATION_DEG))
    return {**camera, "target": [float(c) for c in centre], "radius": radius, "height": cam_z,
            "radius_change": camera.get("radius_change", 0.0) * radius / old_radius}


def file_camera_fov(path: Path, names: tuple[str, ...]) -> float:
    """The horizontal field of view (degrees) the named cameras share; SceneFileError naming a camera
    that is missing, not a camera, off-centre, or has another lens."""
    sc = bpy.context.scene
    have = sorted(o.name for o in sc.objects if o.type == "CAMERA")
    fovs = []
    for n in names:
        o = sc.objects.get(n)
        if o is None or o.type != "CAMERA":
            raise SceneFileError(f"{path}: source.cameras: no camera object {n!r} (the file's cameras: "
                                 f"{', '.join(have) or 'none'})")
        d = o.data
        if d.type != "PERSP" or d.shift_x or d.shift_y or d.sensor_fit == "VERTICAL":
            raise SceneFileError(f"{path}: source.cameras: {n!r} must be a perspective camera without lens shift, "
                                 "fitting its sensor horizontally")
        fovs.append(math.degrees(2 * math.atan(d.sensor_width / (2 * d.lens))))
    if max(fovs) - min(fovs) > 1e-6:
        raise SceneFileError(f"{path}: source.cameras: the cameras' lenses differ ({', '.join(f'{f:.3f}' for f in fovs)} "
                             "degrees); the dataset has one intrinsic matrix")
    return fovs[0]


def file_camera_poses(cfg: SceneConfig, tau: np.ndarray) -> np.ndarray:
    """OpenCV c2w [C, T, 4, 4] of the file's cameras source.cameras at normalised times tau (the file
    is loaded; their scale is removed)."""
    from scene_format.cameras import FLIP_YZ

    sc = bpy.context.scene
    src = cfg.source
    out = np.empty((len(src.cameras), len(tau), 4, 4))
    for i, t in enumerate(tau):
        f = src.frame_start + float(t) * (src.frame_end - src.frame_start)
        sc.frame_set(int(math.floor(f)), subframe=float(f - math.floor(f)))
        for k, n in enumerate(src.cameras):
            m = np.array(sc.objects[n].matrix_world, np.float64)
            m[:3, :3] /= np.linalg.norm(m[:3, :3], axis=0)
            out[k, i] = m @ FLIP_YZ
    return out


def in_view(cfg: SceneConfig, moving: list[np.ndarray]) -> list[float]:
    """Per camera the mean share of the moving surface (points probed over the clip) in its image."""
    from datagen.rig import scene_poses

    intr = intrinsics_from_fov(cfg.render.width, cfg.render.height, cfg.camera.fov_x_deg)
    probe_tau = np.linspace(0, 1, len(moving))
    poses = file_camera_poses(cfg, probe_tau) if cfg.source.cameras else scene_poses(cfg, probe_tau)
    shares = []
    for k in range(cfg.camera.n_cameras):
        s = []
        for i, pts in enumerate(moving):
            pts = pts[:: max(1, len(pts) // 4000)]
            uv, z = project(intr.K, poses[k, i], pts)
            s.append(float(np.mean((z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < intr.width) & (uv[:, 1] >= 0)
                                   & (uv[:, 1] < intr.height))))
        shares.append(float(np.mean(s)))
    return shares


def resolve_file_scene(data: dict[str, Any], label: str = "") -> SceneConfig:
    """The SceneConfig of a scene file: `data` (name, kind, source.file, any overrides) completed with
    the file's frame range, frame rate, length (unless duration_s is given) and, with rig auto, the
    camera rig; refused (SceneFileError) when a camera would not keep the moving content in view."""
    cfg0 = from_dict(SceneConfig, data)
    path = Path(cfg0.source.file)
    load_file(path)
    start, end, fps = file_animation(path)
    src = cfg0.source
    start = src.frame_start if src.frame_start is not None else start
    end = src.frame_end if src.frame_end is not None else end
    fps = src.fps if src.fps is not None else fps
    lo, hi, moving = animated_bounds(path, start, end)
    extra: dict[str, Any] = {"source": {"frame_start": start, "frame_end": end, "fps": fps}}
    if "duration_s" not in data:
        extra["duration_s"] = (end - start) / fps
    if src.cameras:
        extra["camera"] = {**dict(data.get("camera", {})), "n_cameras": len(src.cameras),
                           "fov_x_deg": file_camera_fov(path, src.cameras), "shake": {"rms_deg": 0.0}}
    elif src.rig == "auto":
        extra["camera"] = place_rig(cfg0.kind, lo, hi, dict(data.get("camera", {})), cfg0.render.width,
                                    cfg0.render.height)
    cfg = from_dict(SceneConfig, deep_merge(data, extra))
    shares = in_view(cfg, moving)
    worst = int(np.argmin(shares))
    # an automatic rig must keep most of the moving content in view; cameras the user set, at least some
    own = src.rig == "config" or bool(src.cameras)
    if shares[worst] < (MIN_IN_VIEW_OWN_RIG if own else MIN_IN_VIEW):
        raise SceneFileError(f"{path}: camera {worst} keeps only {100 * shares[worst]:.0f} % of the moving content in "
                             f"view (expected >= {100 * (MIN_IN_VIEW_OWN_RIG if own else MIN_IN_VIEW):.0f} %): the scene is too large for the rig "
                             f"({'use kind: room' if cfg.kind == 'object' else 'set camera: radius, height, target'}"
                             " or source.rig: config with your own camera values)")
    rig = (f"the file's cameras {', '.join(src.cameras)}" if src.cameras else
           f"rig target {(np.round(cfg.camera.target, 3) + 0.0).tolist()}, radius {cfg.camera.radius:.3g}, height {cfg.camera.height:.3g}")
    print(f"{label or cfg.name}: frames {start:g}..{end:g} at {fps:g} fps -> {cfg.duration_s:g} s clip; {rig}; "
          f"moving content in view {', '.join(f'{100 * s:.0f} %' for s in shares)}", flush=True)
    return cfg


def own_scene_data(raw: dict[str, Any], preset_overrides: dict[str, Any]) -> dict[str, Any]:
    """A user's scene YAML with a preset's overrides: the preset sizes the clip (duration, resolution,
    cameras, ...), but blur targets the YAML names are the user's and stay, in pixels at the width the
    YAML renders at (its render.width, else the default): a preset rendering at another width scales
    them by the ratio of widths and fits them (BlurConfig.fit: closest exposures, never refused), as it
    fits targets the preset supplies, which were chosen for its built-in scenes (the tiny preset's 9 px
    is out of reach of most). Targets used at the width they were written for are exact or refused."""
    data = deep_merge(raw, preset_overrides)
    own = raw.get("blur", {}).get("target_px") if isinstance(raw.get("blur"), dict) else None
    if own is not None:
        own_width, width = _render_width(raw), _render_width(data)
        scale = width / own_width if _positive_number(width) and _positive_number(own_width) else 1.0
        fit = isinstance(own, dict) and scale != 1.0
        if fit:
            own = {level: px * scale if _positive_number(px) else px for level, px in own.items()}
        data["blur"] = {**data.get("blur", {}), "target_px": own, **({"fit": True} if fit else {})}
    elif isinstance(data.get("blur"), dict) and data["blur"].get("target_px"):
        data["blur"] = {**data["blur"], "fit": True}
    return data


def _render_width(data: dict[str, Any]):
    render = data.get("render")
    return render.get("width", RenderConfig.width) if isinstance(render, dict) else RenderConfig.width


def _positive_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and x > 0


def file_scene_config(args, preset, cfg: SceneConfig | None) -> SceneConfig:
    """The resolved config of a scene from a file: --scene-file with the preset's overrides, or a
    scene YAML with `source: {file: ...}` (its path relative to the YAML's folder)."""
    if args.scene_file:
        data = own_scene_data({"name": file_scene_name(args.scene_file), "kind": args.kind,
                               "source": {"file": str(args.scene_file.resolve())}}, preset.overrides)
    else:
        yaml_path = Path(args.scene_config) if args.scene_config else None
        raw = read_scene_yaml(yaml_path) if yaml_path else {}
        data = own_scene_data(raw, preset.scene(cfg.name))
        f = Path(cfg.source.file)
        data["source"] = {**data.get("source", {}), "file": str(f if f.is_absolute() or yaml_path is None
                                                                 else (yaml_path.parent / f).resolve())}
        if "duration_s" not in raw and "duration_s" not in preset.scene(cfg.name):
            data.pop("duration_s", None)
    return resolve_file_scene(data)
