"""Blur length from geometry (pure NumPy): how far each visible surface point travels across the
image during an exposure.

A blurred frame is the mean of the sharp frames rendered at the timestamps of its exposure window,
so the smear a surface point leaves is the polyline through its projections at those timestamps.
Its length in pixels is the blur length of that point. The renderer side
(`datagen.render_geometry`) casts a ray through every n-th pixel at the window's centre frame, keeps
the first surface hit in its object's local frame, and records every object's world matrix at every
rendered timestamp; the functions here turn that into image paths. A rigid part's local point and
its matrix give its world position at any time. A deforming part (armature, shape keys, modifiers,
cloth) keeps its hits as (triangle, barycentric coordinates) on its evaluated mesh, whose world
vertices are recorded at every timestamp (`PartMotion`), so a surface point is tracked exactly
however the mesh bends; only a mesh whose topology changes cannot be tracked.

Statistics over many views are accumulated in log-spaced histograms (relative bin width 0.4 %), so
choosing an exposure among hundreds of candidates does not keep every path in memory.
"""
from __future__ import annotations

import dataclasses

from dataclasses import dataclass

import numpy as np

from datagen.blur import exposure_window
from common.config import ConfigError

NEAR_M = 0.01  # points nearer than this to the camera plane are not projected (no finite path)


def _affine(A: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """A[t, :3, :3] @ p + A[t, :3, 3] for every time and point: [T, N, 3] from A [T, >=3, 4], pts [N, 3]
    (written out per component: numpy's batched matmul is slow for 3x3 blocks)."""
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    return np.stack([A[:, r, 0, None] * x + A[:, r, 1, None] * y + A[:, r, 2, None] * z + A[:, r, 3, None]
                     for r in range(3)], -1)


@dataclass
class PartMotion:
    """How every part moves over the rendered times: `mats` [T, O, 4, 4] part-to-world (identity for a
    deforming part) and, for each deforming part o, `deform[o]` = (triangles [F, 3], world vertices
    [T, V, 3]). Sliced over time like the matrix array it generalises (motion[a:b])."""
    mats: np.ndarray
    deform: dict

    @property
    def shape(self) -> tuple:
        return self.mats.shape

    def __getitem__(self, t) -> "PartMotion":
        if not isinstance(t, slice):
            raise TypeError("PartMotion is sliced over time only (motion[a:b])")
        return PartMotion(self.mats[t], {o: (tri, v[t]) for o, (tri, v) in self.deform.items()})


def barycentric_world(tris: np.ndarray, verts: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """World positions [T, N, 3] of points (triangle index, b1, b2) [N, 3] on a mesh whose world
    vertices are verts [T, V, 3]: (1 - b1 - b2) v0 + b1 v1 + b2 v2 of the triangle tris[f]."""
    f = coords[:, 0].astype(np.int64)
    b1, b2 = coords[None, :, 1, None], coords[None, :, 2, None]
    v0, v1, v2 = (verts[:, tris[f, c]] for c in range(3))
    return (1.0 - b1 - b2) * v0 + b1 * v1 + b2 * v2


def track_world(local_pts: np.ndarray, obj_index: np.ndarray, obj_mats) -> np.ndarray:
    """World positions [T, N, 3] of points given in their object's frame.

    local_pts [N, 3]; obj_index [N] into obj_mats' objects; obj_mats [T, O, 4, 4] object-to-world, or
    a PartMotion, whose deforming parts' points are (triangle, b1, b2) on their evaluated mesh.
    """
    deform = getattr(obj_mats, "deform", {})
    mats = getattr(obj_mats, "mats", obj_mats)
    out = np.empty((mats.shape[0], len(local_pts), 3))
    for o in np.unique(obj_index):
        sel = obj_index == o
        if int(o) in deform:
            out[:, sel] = barycentric_world(*deform[int(o)], local_pts[sel])
        else:
            out[:, sel] = _affine(mats[:, o], local_pts[sel])
    return out


def project_tracks(K: np.ndarray, c2w: np.ndarray, world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates [T, N, 2] and depths [T, N] of world points [T, N, 3] seen by a camera whose
    OpenCV pose is c2w [T, 4, 4] (pixel centres at +0.5, as scene_format.cameras.project)."""
    w2c = np.linalg.inv(c2w)
    r, t = w2c[:, None, :3, :3], w2c[:, None, :3, 3]                 # [T, 1, 3, 3], [T, 1, 3]
    pc = [r[..., i, 0] * world[..., 0] + r[..., i, 1] * world[..., 1] + r[..., i, 2] * world[..., 2] + t[..., i]
          for i in range(3)]
    depth = pc[2]
    z = np.where(depth > NEAR_M, depth, np.nan)
    uv = np.stack([K[0, 0] * pc[0] / z + K[0, 2], K[1, 1] * pc[1] / z + K[1, 2]], -1)
    return uv, depth


def cumulative_path_px(uv: np.ndarray) -> np.ndarray:
    """cum [T, N]: image path length (px) from timestamp 0 to t along the polyline uv [T, N, 2];
    NaN from the first step at which the point was behind the near plane onwards."""
    d = np.diff(uv, axis=0)
    step = np.hypot(d[..., 0], d[..., 1])                         # [T-1, N], NaN next to a culled point
    cum = np.zeros(uv.shape[:2])
    cum[1:] = np.cumsum(step, axis=0)
    return cum


def window_path_px(cum: np.ndarray, first: np.ndarray, last: np.ndarray) -> np.ndarray:
    """Path lengths [W, N] over windows [first_w, last_w] (inclusive frame indices) from cum [T, N]."""
    return cum[np.asarray(last)] - cum[np.asarray(first)]


def candidate_windows(i_center: int, n_max: int, n_timestamps: int, offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """[first], [last] of the exposure windows of 1..n_max frames centred on i_center (shifted to stay
    in the clip, datagen.blur.exposure_window), minus `offset` (the first tracked timestamp)."""
    w = np.array([exposure_window(i_center, n, n_timestamps) for n in range(1, n_max + 1)])
    return w[:, 0] - offset, w[:, 1] - offset


class LogHistogram:
    """Counts of non-negative values in log-spaced bins over [lo, hi] px, one row per candidate;
    values below lo land in bin 0, above hi in the last bin, NaN is dropped."""

    def __init__(self, rows: int, lo: float = 1e-3, hi: float = 1e4, bins: int = 4000):
        self.edges = np.geomspace(lo, hi, bins + 1)
        self.counts = np.zeros((rows, bins), np.int64)

    def add(self, values: np.ndarray) -> None:
        """values [rows, N]."""
        rows, n = values.shape
        ok = np.isfinite(values)
        b = np.clip(np.searchsorted(self.edges, values, side="right") - 1, 0, self.counts.shape[1] - 1)
        flat = (np.arange(rows)[:, None] * self.counts.shape[1] + b)[ok]
        self.counts += np.bincount(flat, minlength=self.counts.size).reshape(self.counts.shape)

    def quantile(self, q: float) -> np.ndarray:
        """[rows] the q-quantile of each row (geometric interpolation inside the bin); NaN if empty."""
        total = self.counts.sum(1)
        cum = np.cumsum(self.counts, axis=1)
        out = np.full(len(total), np.nan)
        for r in np.nonzero(total)[0]:
            target = q * total[r]
            b = int(np.searchsorted(cum[r], target, side="left"))
            below = cum[r, b - 1] if b > 0 else 0
            frac = (target - below) / max(self.counts[r, b], 1)
            lo, hi = self.edges[b], self.edges[b + 1]
            out[r] = lo * (hi / lo) ** frac
        return out


@dataclass(frozen=True)
class LevelChoice:
    level: str
    target_px: float | None       # None: a level declared by its exposure
    n_frames: int
    fit_factor: float = 1.0       # the target is the declared one x this (BlurConfig.fit)


def fit_targets(medians_px: np.ndarray, target_px: dict[str, float], tolerance: float) -> tuple[dict[str, float], float]:
    """(targets, factor): the targets x one factor that puts the strongest at the longest exposure's
    median blur max(medians_px), when the strongest is beyond it by more than `tolerance`; else
    (target_px, 1.0). medians_px [n_max]: median blur (px) of exposures of 1..n_max frames."""
    finite = medians_px[np.isfinite(medians_px) & (medians_px > 0)]
    top = max(target_px.values())
    if not len(finite) or top <= float(finite.max()) * (1 + tolerance):
        return dict(target_px), 1.0
    factor = float(finite.max()) / top
    return {level: px * factor for level, px in target_px.items()}, factor


def fixed_exposures(exposure_ms: dict[str, float], fps: float, n_timestamps: int, scene: str) -> list[LevelChoice]:
    """Levels declared by a real-time exposure: n = round(ms * fps) rendered frames (at least 1; fps is
    rendered frames per real second). One longer than the clip is a ConfigError naming the scene and level."""
    out = []
    for level in sorted(exposure_ms, key=exposure_ms.get):
        n = max(1, int(round(exposure_ms[level] * 1e-3 * fps)))
        if n > n_timestamps:
            raise ConfigError(f"scene {scene}, blur level {level}: the {exposure_ms[level]:g} ms exposure spans {n} "
                              f"rendered frames, more than the clip's {n_timestamps}")
        out.append(LevelChoice(level, None, n))
    return out


def choose_exposures(medians_px: np.ndarray, target_px: dict[str, float], tolerance: float, fps: float,
                     scene: str, limit_reason: str, strict: bool = True) -> list[LevelChoice]:
    """Per level the exposure n (frames) whose median blur medians_px[n - 1] is closest to the target
    in ratio. A level missed by more than `tolerance` (relative), or two levels on one exposure, is a
    ConfigError naming the scene and the level; limit_reason says what bounds the longest exposure.
    strict=False (BlurConfig.fit): no miss is refused, and a level whose closest exposure a weaker level
    took takes the closest longer one (an error only when none is left)."""
    out = []
    logm = np.log(np.where(medians_px > 0, medians_px, np.nan))
    for level in sorted(target_px, key=target_px.get):
        target = target_px[level]
        if np.all(np.isnan(logm)):
            raise ConfigError(f"scene {scene}, blur level {level}: nothing in view moves, so no exposure blurs "
                              f"(target {target:g} px)")
        err = np.abs(logm - np.log(target))
        if not strict and out:
            err[:out[-1].n_frames] = np.nan                   # longer than the weaker level's exposure
        if np.all(np.isnan(err)):
            raise ConfigError(f"scene {scene}, blur level {level}: no exposure is left longer than level "
                              f"{out[-1].level}'s ({out[-1].n_frames} frames, {limit_reason})")
        n = int(np.nanargmin(err)) + 1
        got = float(medians_px[n - 1])
        if strict and abs(got / target - 1) > tolerance:
            longest = float(np.nanmax(medians_px))
            if target > got:
                why = (f"the longest exposure ({len(medians_px)} frames, {1e3 * len(medians_px) / fps:.2f} ms, "
                       f"bounded by {limit_reason}) gives {longest:.2f} px")
            else:
                why = (f"the shortest blurring exposure (2 frames, {2e3 / fps:.2f} ms) already gives "
                       f"{float(medians_px[1]) if len(medians_px) > 1 else float('nan'):.2f} px; raise render.fps")
            raise ConfigError(f"scene {scene}, blur level {level}: target {target:g} px cannot be reached within "
                              f"{100 * tolerance:g} %: the closest exposure ({n} frames, {1e3 * n / fps:.2f} ms) gives "
                              f"{got:.2f} px, and {why}")
        if out and out[-1].n_frames == n:
            raise ConfigError(f"scene {scene}, blur levels {out[-1].level} and {level}: targets {out[-1].target_px:g} "
                              f"and {target:g} px fall on the same exposure ({n} frames): the levels would be identical")
        out.append(LevelChoice(level, float(target), n))
    return out


def summarize(values: np.ndarray) -> dict:
    """median and 90th percentile (px) of finite values, with their count."""
    v = values[np.isfinite(values)]
    if not len(v):
        return {"median_px": None, "p90_px": None, "samples": 0}
    return {"median_px": round(float(np.median(v)), 3), "p90_px": round(float(np.percentile(v, 90)), 3),
            "samples": int(len(v))}


@dataclass
class BlurReport:
    """What the generator needs (windows) and records (statistics) for a scene's blur levels."""
    choices: list[LevelChoice]
    windows: dict[str, dict[int, tuple[int, int]]]       # level -> blurred frame j -> (first, last) frame
    manifest: dict                                        # per level and camera statistics, px per frame
    view_median_px: dict[str, np.ndarray]                 # level -> [C, J] median blur of each blurred frame


def view_paths(local, obj, mats, c2w, K, i_center, n_max, T):
    """Tracked range [lo, hi] around i_center and the cumulative paths [hi - lo + 1, N] of one view."""
    lo, hi = max(0, i_center - n_max), min(T - 1, i_center + n_max)
    uv, _ = project_tracks(K, c2w[lo:hi + 1], track_world(local, obj, mats[lo:hi + 1]))
    return lo, cumulative_path_px(uv)


def choose_levels(samples: dict, mats: np.ndarray, poses: np.ndarray, K: np.ndarray, centers: np.ndarray,
                  blur_cfg, fps: float, scene: str) -> list[LevelChoice]:
    """Each pixel-declared level's exposure (the one whose median blur is closest to its target) and
    each exposure-declared level's. fps: rendered frames per real second (render.fps * speed)."""
    T = mats.shape[0]
    choices = []
    if blur_cfg.target_px:
        n_cap = int(np.floor(blur_cfg.max_exposure_ms * 1e-3 * fps + 1e-9))
        n_max = max(1, min(T, n_cap))
        limit = (f"the clip's {T} rendered frames" if T <= n_cap else f"max_exposure_ms = {blur_cfg.max_exposure_ms:g}")
        hist = LogHistogram(n_max)
        for (k, j), (local, obj) in samples.items():
            if not len(local):
                continue
            lo, cum = view_paths(local, obj, mats, poses[k], K, int(centers[j]), n_max, T)
            first, last = candidate_windows(int(centers[j]), n_max, T, offset=lo)
            hist.add(window_path_px(cum, first, last))
        medians = hist.quantile(0.5)
        targets, factor = (fit_targets(medians, blur_cfg.target_px, blur_cfg.tolerance) if blur_cfg.fit
                           else (blur_cfg.target_px, 1.0))
        choices = [dataclasses.replace(c, fit_factor=factor) for c in
                   choose_exposures(medians, targets, blur_cfg.tolerance, fps, scene, limit, strict=not blur_cfg.fit)]
    return choices + fixed_exposures(blur_cfg.exposure_ms, fps, T, scene)


def measure_blur(samples: dict, mats: np.ndarray, poses: np.ndarray, K: np.ndarray, centers: np.ndarray,
                 blur_cfg, fps: float, scene: str) -> BlurReport:
    """Choose every level's exposure and measure what it does.

    samples {(camera, j): (local points [N, 3], part index [N])} from the renderer at blurred frame
    j's centre frame centers[j]; mats [T, O, 4, 4] part matrices; poses [C, T, 4, 4] OpenCV c2w;
    fps: rendered frames per real second (render.fps times the scene's speed).
    """
    return measure_blur_many(samples, mats, poses, K, centers, [(blur_cfg, fps)], scene)[0]


def measure_blur_many(samples: dict, mats: np.ndarray, poses: np.ndarray, K: np.ndarray, centers: np.ndarray,
                      configs: list, scene: str) -> list[BlurReport]:
    """measure_blur for several (blur config, fps) pairs over the same frames and poses (a scene and
    its speed variants), tracking every view once for all of them."""
    choices = [choose_levels(samples, mats, poses, K, centers, b, fps, scene) for b, fps in configs]
    stats = _path_statistics(samples, mats, poses, K, centers, sorted({c.n_frames for cs in choices for c in cs}))
    return [_report(cs, stats, b, fps, centers, mats.shape[0]) for cs, (b, fps) in zip(choices, configs)]


def _path_statistics(samples, mats, poses, K, centers, exposures: list[int]) -> dict:
    """Per exposure n (rendered frames): every camera's blur paths and every view's median, and the
    image motion per rendered frame. Each view's paths are computed once here rather than kept from
    the choice's pass, which would hold every view's [2 n_max + 1, N] array (~2 GB for a quick room)."""
    T, C, J = mats.shape[0], poses.shape[0], len(centers)
    n_track = max(exposures + [2])
    per_cam = {(n, k): [] for n in exposures for k in range(C)}
    view_median = {n: np.full((C, J), np.nan) for n in exposures}
    step = []
    for (k, j), (local, obj) in samples.items():
        if not len(local):
            continue
        lo, cum = view_paths(local, obj, mats, poses[k], K, int(centers[j]), n_track, T)
        c = int(centers[j]) - lo
        a, b = (c, c + 1) if c + 1 < len(cum) else (c - 1, c)
        step.append(cum[b] - cum[a])
        for n in exposures:
            first, last = exposure_window(int(centers[j]), n, T)
            path = cum[last - lo] - cum[first - lo]
            per_cam[(n, k)].append(path)
            if np.isfinite(path).any():
                view_median[n][k, j] = float(np.nanmedian(path))
    steps = np.concatenate(step) if step else np.zeros(0)
    return {"per_cam": per_cam, "view_median": view_median, "steps": steps[np.isfinite(steps)], "C": C}


def _report(choices: list[LevelChoice], stats: dict, blur_cfg, fps: float, centers: np.ndarray, T: int) -> BlurReport:
    per_cam, C, steps = stats["per_cam"], stats["C"], stats["steps"]
    levels = {}
    for c in choices:
        cams = [np.concatenate(per_cam[(c.n_frames, k)] or [np.zeros(0)]) for k in range(C)]
        fitted = ({"fitted": True, "declared_target_px": round(c.target_px / c.fit_factor, 6)}
                  if blur_cfg.fit and c.target_px is not None else {})
        levels[c.level] = {"target_px": c.target_px, **fitted, "n_frames": c.n_frames,
                           "exposure_ms": round(1e3 * c.n_frames / fps, 4), **summarize(np.concatenate(cams)),
                           "per_camera": [summarize(v) for v in cams]}
    px_per_frame = ({"median": round(float(np.median(steps)), 3), "p90": round(float(np.percentile(steps, 90)), 3),
                     "p99": round(float(np.percentile(steps, 99)), 3), "max": round(float(steps.max()), 3)}
                    if len(steps) else {})
    windows = {c.level: {j: exposure_window(int(i), c.n_frames, T) for j, i in enumerate(centers)} for c in choices}
    manifest = {"method": "geometry: first surface hit through every sample_stride_px-th pixel at the blurred "
                          "frame's centre frame, tracked rigidly through every rendered frame of its exposure and "
                          "projected; blur length = length of that image path; median and p90 over hits",
                "sample_stride_px": blur_cfg.sample_stride_px, "tolerance": blur_cfg.tolerance,
                "max_exposure_ms": blur_cfg.max_exposure_ms, "levels": levels, "px_per_frame": px_per_frame}
    view_median = {c.level: stats["view_median"][c.n_frames] for c in choices}
    return BlurReport(choices, windows, manifest, view_median)
