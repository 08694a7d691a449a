"""On-the-fly training sequences for E2VID / FireNet, made by the project's own simulator.

A sequence is a procedural texture (gratings, multi-scale noise, random shapes, or a blend) on a
canvas larger than the crop, moved by a random 2D similarity motion (translation, rotation, zoom at
constant rates, with a random overall speed), rendered at `fps` by warping the canvas, and fed as
linear intensity to `simulator.EventSimulator` with a randomised sensor (contrast thresholds, their
per-pixel mismatch, shot noise, refractory period). Each training step covers `substeps` rendered
frames; its events become a normalised 5-bin voxel grid, its target is the sharp frame at the step's
end (sRGB-encoded, as the dataset stores frames), and `flow_grid` maps every pixel to where the same
texture point was one step earlier (for the temporal-consistency loss).

Nothing here reads the benchmark's scenes; the texture generators are seeded NumPy/OpenCV code.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

from e2vid.voxel import normalize_voxel, voxel_grid_events
from simulator import EventSimulator, SimulatorConfig
from common.color import srgb_to_linear

VAL_SEED_BASE = 1 << 40            # held-out sequences use seeds >= this; training seeds stay below


@dataclass(frozen=True)
class SynthConfig:
    height: int = 64
    width: int = 64
    n_steps: int = 32                  # voxel grids (network calls) per sequence
    substeps: int = 10                 # rendered frames per step
    fps: float = 3000.0                # as the dataset renders
    num_bins: int = 5
    max_shift_px: float = 3.0          # per step, before the random speed factor
    max_rotation_deg: float = 3.0      # per step
    max_zoom: float = 0.03             # log-scale change per step
    threshold_range: tuple[float, float] = (0.1, 0.45)
    threshold_sigma_max: float = 0.04
    shot_noise_max_hz: float = 5.0


@dataclass
class Sequence:
    voxels: torch.Tensor      # [T, B, H, W] normalised voxel grids
    targets: torch.Tensor     # [T, 1, H, W] sharp frames (sRGB-encoded, [0, 1]) at each step's end
    flow: torch.Tensor        # [T, H, W, 2] grid_sample grid: pixel -> its position one step earlier (row 0 unused)
    n_events: np.ndarray      # [T] events per step
    events: list | None = None         # [T] EVENT_DTYPE arrays (single sequences only)
    t_end_us: np.ndarray | None = None  # [T] end time of each step


# ---------------------------------------------------------------- textures (canvas [S, S] in [0, 1])

def _normalise(a: np.ndarray) -> np.ndarray:
    lo, hi = np.percentile(a, 1), np.percentile(a, 99)
    return np.clip((a - lo) / max(hi - lo, 1e-6), 0, 1)


def texture_grating(rng: np.random.Generator, size: int) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    out = np.zeros((size, size), np.float32)
    for _ in range(rng.integers(1, 4)):
        theta, period = rng.uniform(0, np.pi), rng.uniform(6, size / 3)
        phase = (xx * np.cos(theta) + yy * np.sin(theta)) * 2 * np.pi / period + rng.uniform(0, 2 * np.pi)
        wave = np.sin(phase)
        if rng.random() < 0.5:
            wave = np.sign(wave)               # square wave: sharp edges
        out += rng.uniform(0.3, 1.0) * wave
    return _normalise(out)


def texture_noise(rng: np.random.Generator, size: int) -> np.ndarray:
    out = np.zeros((size, size), np.float32)
    for octave in range(rng.integers(2, 5)):
        sigma = float(rng.uniform(1.0, 12.0)) * (1.6 ** octave)
        layer = cv2.GaussianBlur(rng.standard_normal((size, size)).astype(np.float32), (0, 0), sigma)
        out += layer / (layer.std() + 1e-6) * rng.uniform(0.3, 1.0)
    return _normalise(out)


def texture_shapes(rng: np.random.Generator, size: int) -> np.ndarray:
    img = np.full((size, size), rng.uniform(0, 1), np.float32)
    for _ in range(rng.integers(8, 30)):
        val = float(rng.uniform(0, 1))
        kind = rng.integers(0, 3)
        c = tuple(int(v) for v in rng.integers(0, size, 2))
        r = int(rng.integers(4, size // 5))
        if kind == 0:
            cv2.circle(img, c, r, val, -1, lineType=cv2.LINE_AA)
        elif kind == 1:
            box = cv2.boxPoints((c, (float(r * rng.uniform(0.5, 2)), float(r * rng.uniform(0.5, 2))),
                                 float(rng.uniform(0, 180))))
            cv2.fillPoly(img, [box.astype(np.int32)], val, lineType=cv2.LINE_AA)
        else:
            pts = (np.asarray(c) + rng.uniform(-r, r, (int(rng.integers(3, 7)), 2))).astype(np.int32)
            cv2.fillPoly(img, [pts], val, lineType=cv2.LINE_AA)
    return img


TEXTURES = (texture_grating, texture_noise, texture_shapes)


def random_texture(rng: np.random.Generator, size: int) -> np.ndarray:
    """A display-referred texture [size, size] in [0, 1] with a random black level and contrast."""
    choice = rng.integers(0, len(TEXTURES) + 1)
    if choice < len(TEXTURES):
        tex = TEXTURES[choice](rng, size)
    else:                                   # blend of two kinds
        a, b = rng.choice(len(TEXTURES), 2, replace=False)
        w = rng.uniform(0.3, 0.7)
        tex = w * TEXTURES[a](rng, size) + (1 - w) * TEXTURES[b](rng, size)
    lo = rng.uniform(0.0, 0.35)
    hi = rng.uniform(lo + 0.25, 1.0)
    return (lo + (hi - lo) * tex).astype(np.float32)


# ---------------------------------------------------------------- motion

def similarity(centre_canvas: np.ndarray, angle_rad: float, scale: float, centre_img: np.ndarray) -> np.ndarray:
    """2x3 affine mapping canvas points q to image points p = s R (q - centre_canvas) + centre_img."""
    c, s = np.cos(angle_rad) * scale, np.sin(angle_rad) * scale
    A = np.array([[c, -s], [s, c]])
    return np.hstack([A, (centre_img - A @ centre_canvas)[:, None]])


def _inv(M: np.ndarray) -> np.ndarray:
    A_inv = np.linalg.inv(M[:, :2])
    return np.hstack([A_inv, (-A_inv @ M[:, 2])[:, None]])


def flow_grid(M_prev: np.ndarray, M_now: np.ndarray, height: int, width: int) -> np.ndarray:
    """[H, W, 2] grid_sample coordinates (x, y in [-1, 1], align_corners=False) of each pixel's
    texture point in the previous frame: p' = M_prev M_now^-1 p."""
    inv = _inv(M_now)
    both = M_prev[:, :2] @ inv[:, :2], M_prev[:, :2] @ inv[:, 2] + M_prev[:, 2]
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float64)
    px = both[0][0, 0] * xx + both[0][0, 1] * yy + both[1][0]
    py = both[0][1, 0] * xx + both[0][1, 1] * yy + both[1][1]
    return np.stack([(2 * px + 1) / width - 1, (2 * py + 1) / height - 1], -1).astype(np.float32)


def random_sensor(rng: np.random.Generator, cfg: SynthConfig) -> SimulatorConfig:
    c_pos = float(rng.uniform(*cfg.threshold_range))
    c_neg = float(np.clip(c_pos * rng.uniform(0.8, 1.25), 0.05, None))
    return SimulatorConfig(pos_threshold=c_pos, neg_threshold=c_neg,
                           threshold_sigma=float(rng.uniform(0, cfg.threshold_sigma_max)),
                           threshold_min=0.01,
                           shot_noise_rate_hz=float(rng.uniform(0, cfg.shot_noise_max_hz)),
                           refractory_us=int(rng.choice([0, 0, 100])))


def make_sequence(seed: int, cfg: SynthConfig = SynthConfig()) -> Sequence:
    """One training sequence, a pure function of (seed, cfg)."""
    rng = np.random.default_rng(seed)
    H, W = cfg.height, cfg.width
    speed = float(rng.choice([rng.uniform(0.1, 0.5), rng.uniform(0.5, 1.5)]))
    shift = rng.uniform(-1, 1, 2) * cfg.max_shift_px * speed
    rot = np.deg2rad(rng.uniform(-1, 1) * cfg.max_rotation_deg * speed)
    zoom = rng.uniform(-1, 1) * cfg.max_zoom * speed
    scale0 = float(np.exp(rng.uniform(-0.3, 0.3)))
    travel = np.abs(shift).max() * cfg.n_steps / scale0
    size = int(np.ceil((np.hypot(H, W) / scale0 / np.exp(-abs(zoom) * cfg.n_steps) + 2 * travel + 8)))
    canvas = random_texture(rng, size)
    centre_img = np.array([W / 2.0, H / 2.0])
    start = np.array([size / 2.0, size / 2.0]) - shift * cfg.n_steps / 2 / scale0
    angle0 = rng.uniform(0, 2 * np.pi)

    def transform(step_f: float) -> np.ndarray:
        return similarity(start + shift * step_f / scale0, angle0 + rot * step_f, scale0 * np.exp(zoom * step_f),
                          centre_img)

    def render(step_f: float) -> np.ndarray:
        return cv2.warpAffine(canvas, transform(step_f), (W, H), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT101)

    sim = EventSimulator(random_sensor(rng, cfg), W, H, seed=int(rng.integers(1 << 31)), threads=1)
    dt_us = 1e6 / cfg.fps
    sim.push(srgb_to_linear(render(0.0)), 0)
    voxels, targets, flows, counts, steps, ends = [], [], [], [], [], []
    for step in range(cfg.n_steps):
        chunks = []
        for sub in range(1, cfg.substeps + 1):
            k = step * cfg.substeps + sub
            frame = render(k / cfg.substeps)
            chunks.append(sim.push(srgb_to_linear(frame), int(round(k * dt_us))))
        ev = np.concatenate(chunks)
        steps.append(ev)
        ends.append(int(round((step + 1) * cfg.substeps * dt_us)))
        counts.append(len(ev))
        voxels.append(voxel_grid_events(ev, cfg.num_bins, W, H))
        targets.append(frame)
        flows.append(flow_grid(transform(step), transform(step + 1), H, W))
    vox = normalize_voxel(torch.from_numpy(np.stack(voxels)))
    return Sequence(vox, torch.from_numpy(np.stack(targets))[:, None], torch.from_numpy(np.stack(flows)),
                    np.asarray(counts), steps, np.asarray(ends, np.int64))


def make_batch(seeds: list[int], cfg: SynthConfig) -> Sequence:
    seqs = [make_sequence(s, cfg) for s in seeds]
    # [T, N, ...]: time first, as the recurrent loop consumes it
    return Sequence(torch.stack([s.voxels for s in seqs], 1), torch.stack([s.targets for s in seqs], 1),
                    torch.stack([s.flow for s in seqs], 1), np.stack([s.n_events for s in seqs], 1))


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
SynthConfig.BOUNDS = {
    "height": (1, 4096, "pixels"), "width": (1, 4096, "pixels"), "n_steps": (1, 100_000, "frames a sequence"),
    "substeps": (1, 1000, "simulator steps a frame"), "fps": (1e-3, 1e6, "frames per second"), "num_bins": (1, 64, "voxel bins"),
    "max_shift_px": (0.0, 1e4, "pixels"), "max_rotation_deg": (0.0, 360.0, "degrees"), "max_zoom": (0.0, 10.0, "a relative zoom"),
    "threshold_sigma_max": (0.0, 10.0, "log intensity"), "shot_noise_max_hz": (0.0, 1e6, "events per second a pixel"),
}
