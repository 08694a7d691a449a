"""Per-pixel ground truth from the exact surface tracking (pure NumPy): depth, normals, object ids
and optical flow of a view, and the DSEC-Flow file convention.

The renderer side (`datagen.render_geometry.surface_views`) casts the ray through every pixel centre
of a view at its rendered time and keeps, per pixel that meets a surface, the hit's world point,
its shading normal (corner normals interpolated, as the renderer shades it), its part and its coordinates on that part (a point in the part's frame, or a
triangle and barycentric coordinates on a deforming mesh, `blur_geometry.track_world`). From those:

- depth: z-depth in the camera frame, metres (OpenCV axes: z forward); 0 where no surface is seen;
- normals: unit shading normals in the camera frame, turned to face the camera; 0 where no surface;
- ids: the part's id (1 + its index in the scene's `objects` table), 0 where no surface;
- forward flow to a later time: where the surface point seen at each pixel is at that time, minus
  the pixel (camera and object motion both), valid where the point is in front of the camera, inside
  the image and visible there: the renderer casts a ray from that time's camera centre to the
  tracked point through that time's geometry, and the point is occluded where the ray meets a
  surface before it (not by a depth test at the pixel it lands in, which is wrong within a pixel of
  every edge and calls a point landing on background occluded);
- instantaneous flow: the image velocity of the point, pixels per millisecond of real time, by a
  central difference over the neighbouring rendered timestamps.

Pixel (x, y) is the ray through (x + 0.5, y + 0.5), as the renders and `scene_format.cameras.project`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datagen.blur_geometry import NEAR_M, project_tracks, track_world
from scene_format.config import GROUND_TRUTH_KINDS as KINDS  # noqa: F401  (re-exported)

# A ray cast to a tracked point stops short of it by this fraction of its length (plus VISIBLE_ABS_M) so
# that the point's own surface does not hide it: the BVH runs in single precision (depth to a few ulp,
# 1e-6 at 4 m), and 1e-4 is 0.4 mm at 4 m, far below any gap between two surfaces of a scene.
VISIBLE_REL = 1e-4
VISIBLE_ABS_M = 1e-5


@dataclass
class ViewSurface:
    """What the ray through every pixel of one view (H * W rays, row-major) met at its time."""
    hit: np.ndarray          # bool [H * W]
    local: np.ndarray        # [M, 3] the M hits in their part's frame (or triangle, b1, b2 on a deforming part)
    obj: np.ndarray          # int [M] part index
    world: np.ndarray        # [M, 3] world points
    normal: np.ndarray       # [M, 3] world shading normals (unit)


def _image(hit: np.ndarray, values: np.ndarray, width: int, height: int, dtype, fill=0) -> np.ndarray:
    """Scatter per-hit values [M, ...] into an image [H, W, ...] (fill where nothing was hit)."""
    out = np.full((height * width,) + values.shape[1:], fill, dtype)
    out[np.flatnonzero(hit)] = values
    return out.reshape((height, width) + values.shape[1:])


def camera_points(world: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World points [M, 3] in an OpenCV camera's frame (x right, y down, z forward)."""
    w2c = np.linalg.inv(c2w)
    return world @ w2c[:3, :3].T + w2c[:3, 3]


def depth_image(s: ViewSurface, c2w: np.ndarray, width: int, height: int) -> np.ndarray:
    """float32 [H, W] z-depth in metres; 0 where the ray meets no surface."""
    return _image(s.hit, camera_points(s.world, c2w)[:, 2], width, height, np.float32)


def normal_image(s: ViewSurface, c2w: np.ndarray, width: int, height: int) -> np.ndarray:
    """float32 [H, W, 3] unit shading normals in the camera frame, facing the camera; 0 where no surface."""
    n = s.normal @ c2w[:3, :3]                       # world -> camera: R^T n, as row vectors
    view = camera_points(s.world, c2w)               # from the camera centre to the point
    n = np.where((np.sum(n * view, 1) > 0)[:, None], -n, n)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return _image(s.hit, n, width, height, np.float32)


def id_image(s: ViewSurface, width: int, height: int) -> np.ndarray:
    """uint16 [H, W]: 1 + the part index of the surface seen, 0 where none."""
    return _image(s.hit, s.obj.astype(np.int64) + 1, width, height, np.uint16)


def pixel_centres(width: int, height: int) -> np.ndarray:
    """[H * W, 2] (x + 0.5, y + 0.5), row-major."""
    x, y = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    return np.stack([x.ravel(), y.ravel()], -1)


def track_points(s: ViewSurface, motion, times: np.ndarray) -> np.ndarray:
    """World positions [T', M, 3] of the view's surface points at the rendered time indices `times` [T']
    (motion: blur_geometry.PartMotion or [T, O, 4, 4] part matrices)."""
    times = np.asarray(times, np.int64)
    mats = motion[int(times.min()):int(times.max()) + 1]
    return track_world(s.local, s.obj, mats)[times - times.min()]


def track_uv(s: ViewSurface, motion, poses: np.ndarray, K: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel positions [T', M, 2] and depths [T', M] of the view's surface points at the rendered
    time indices `times` [T'], seen by the same camera (poses [T, 4, 4] its OpenCV c2w at every
    rendered time; motion: blur_geometry.PartMotion or [T, O, 4, 4] part matrices)."""
    times = np.asarray(times, np.int64)
    return project_tracks(K, poses[times], track_points(s, motion, times))


def lands_inside(uv1: np.ndarray, z1: np.ndarray, width: int, height: int) -> np.ndarray:
    """bool [M]: the tracked point is in front of the camera (z1 > NEAR_M) and inside the image at
    the later time (uv1 [M, 2] px, z1 [M] m)."""
    return (z1 > NEAR_M) & np.all(np.isfinite(uv1), 1) & (uv1[:, 0] >= 0) & (uv1[:, 0] < width) \
        & (uv1[:, 1] >= 0) & (uv1[:, 1] < height)


def ray_stops(origin: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit directions [M, 3], distances [M]) of the rays a visibility test casts from a camera
    centre `origin` [3] towards world points [M, 3]: each stops VISIBLE_REL of its length (plus
    VISIBLE_ABS_M) short of its point, so only a surface strictly in front of the point hides it."""
    d = points - origin
    length = np.linalg.norm(d, axis=1)
    return d / np.maximum(length, 1e-12)[:, None], np.maximum(length * (1 - VISIBLE_REL) - VISIBLE_ABS_M, 0.0)


def forward_flow(s: ViewSurface, uv1: np.ndarray, z1: np.ndarray, visible1: np.ndarray, width: int,
                 height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flow float32 [H, W, 2] px, valid bool [H, W], occluded bool [H, W]) from the view's pixels to
    where their surface points are at a later time: uv1 [M, 2] and depth z1 [M] there, visible1 bool
    [M] whether the ray from that time's camera to the point meets nothing before it (the renderer's
    ray cast, datagen.render_geometry.SurfaceTracer.visible). Valid: in front of the camera, inside
    the image and visible; occluded: in front and inside but hidden (a point that lands on background
    with nothing in front of it is visible)."""
    uv0 = pixel_centres(width, height)[np.flatnonzero(s.hit)]
    flow = (uv1 - uv0).astype(np.float32)
    inside = lands_inside(uv1, z1, width, height)
    occluded = inside & ~np.asarray(visible1, bool)
    valid = inside & ~occluded
    return (_image(s.hit, np.where(valid[:, None], flow, 0), width, height, np.float32),
            _image(s.hit, valid, width, height, bool), _image(s.hit, occluded, width, height, bool))


def instant_flow(uv_prev: np.ndarray, uv_next: np.ndarray, dt_ms: float, hit: np.ndarray, width: int,
                 height: int) -> np.ndarray:
    """float32 [H, W, 2] image velocity, px per ms: (uv_next - uv_prev) / dt_ms per hit (uv [M, 2] at
    the two times dt_ms apart); 0 where no surface or the point is behind the camera at either time."""
    v = (uv_next - uv_prev) / dt_ms
    v = np.where(np.all(np.isfinite(v), 1)[:, None], v, 0.0)
    return _image(hit, v, width, height, np.float32)


def event_labels(t_us: np.ndarray, x: np.ndarray, y: np.ndarray, frame_times_us: np.ndarray,
                 ids: np.ndarray) -> np.ndarray:
    """uint16 [N]: the object id at each event's pixel in the kept frame nearest its time (events
    t_us, x, y [N]; frame_times_us [J] increasing; ids [J, H, W]). Between kept frames a moving edge
    may hand a pixel to another object: the label is the nearest frame's."""
    last = len(frame_times_us) - 1
    after = np.clip(np.searchsorted(frame_times_us, t_us), 0, last)         # the first frame at or after t
    before = np.clip(after - 1, 0, last)
    j = np.where(np.abs(t_us - frame_times_us[before]) <= np.abs(frame_times_us[after] - t_us), before, after)
    return ids[j, y.astype(np.int64), x.astype(np.int64)]


def warp_backward(image1: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """image1 sampled at each pixel + its flow (bilinear, edges clamped): the later frame warped back
    onto the earlier one (the brightness-constancy check). image1 [H, W] or [H, W, C]."""
    h, w = flow.shape[:2]
    x = np.arange(w)[None, :] + flow[..., 0]
    y = np.arange(h)[:, None] + flow[..., 1]
    x0 = np.clip(np.floor(x).astype(np.int64), 0, w - 1)
    y0 = np.clip(np.floor(y).astype(np.int64), 0, h - 1)
    x1, y1 = np.clip(x0 + 1, 0, w - 1), np.clip(y0 + 1, 0, h - 1)
    fx, fy = np.clip(x - x0, 0, 1), np.clip(y - y0, 0, 1)
    if image1.ndim == 3:
        fx, fy = fx[..., None], fy[..., None]
    top = image1[y0, x0] * (1 - fx) + image1[y0, x1] * fx
    bottom = image1[y1, x0] * (1 - fx) + image1[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def masked_psnr(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    """PSNR (dB, images in [0, 1]) over the pixels of mask."""
    err = (a - b)[mask]
    mse = float(np.mean(err ** 2)) if err.size else float("nan")
    return float("inf") if mse == 0 else -10.0 * np.log10(mse)
