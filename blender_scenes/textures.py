"""Procedural texture images as NumPy arrays (sRGB-encoded values in [0, 1], shape [H, W, 3]).

Pure NumPy (no bpy), seeded, so scenes are identical on every machine. Textures carry edges and
fine detail on purpose: an event camera sees nothing on a uniform surface.
"""
from __future__ import annotations

import numpy as np


def _rgb(c) -> np.ndarray:
    return np.asarray(c, np.float64).reshape(1, 1, 3)


def value_noise(rng: np.random.Generator, size: int, octaves: int = 4, base_cells: int = 4) -> np.ndarray:
    """Tileable fractal value noise in [0, 1], [size, size]."""
    out = np.zeros((size, size))
    amp, total = 1.0, 0.0
    for o in range(octaves):
        cells = base_cells * 2 ** o
        grid = rng.random((cells, cells))
        x = np.linspace(0, cells, size, endpoint=False)
        i0 = np.floor(x).astype(int)
        f = x - i0
        f = f * f * (3 - 2 * f)
        i1 = (i0 + 1) % cells
        g00, g01 = grid[i0][:, i0], grid[i0][:, i1]
        g10, g11 = grid[i1][:, i0], grid[i1][:, i1]
        fy, fx = f[:, None], f[None, :]
        layer = (g00 * (1 - fx) + g01 * fx) * (1 - fy) + (g10 * (1 - fx) + g11 * fx) * fy
        out += amp * layer
        total += amp
        amp *= 0.5
    return out / total


def mottled(rng, size, base, variation=0.15, octaves=4) -> np.ndarray:
    """A colour with low-frequency mottling (paint, plastic, concrete)."""
    n = value_noise(rng, size, octaves)[..., None]
    return np.clip(_rgb(base) * (1 - variation + 2 * variation * n), 0, 1)


def checker(size, n, c1, c2) -> np.ndarray:
    idx = (np.arange(size) * n // size)
    mask = ((idx[:, None] + idx[None, :]) % 2).astype(bool)[..., None]
    return np.where(mask, _rgb(c1), _rgb(c2)) * np.ones((size, size, 3))


def stripes(size, n, c1, c2, horizontal=False) -> np.ndarray:
    idx = (np.arange(size) * n // size) % 2
    mask = (idx[:, None] if horizontal else idx[None, :]).astype(bool)
    return np.where(mask[..., None], _rgb(c1), _rgb(c2)) * np.ones((size, size, 3))


def bricks(rng, size, rows=8, cols=4, brick=(0.55, 0.22, 0.15), mortar=(0.8, 0.78, 0.72), mortar_px=2) -> np.ndarray:
    img = mottled(rng, size, brick, 0.2)
    h = size // rows
    y = np.arange(size)
    img[(y % h) < mortar_px] = mortar
    w = size // cols
    for r in range(rows):
        off = (w // 2) * (r % 2)
        xs = (np.arange(size) + off) % w < mortar_px
        img[r * h:(r + 1) * h, xs] = mortar
        shade = 0.85 + 0.3 * rng.random(cols + 1)
        for c in range(cols + 1):
            x0, x1 = c * w - off, (c + 1) * w - off
            sl = slice(max(x0, 0), max(min(x1, size), 0))
            img[r * h + mortar_px:(r + 1) * h, sl] *= shade[c]
    return np.clip(img, 0, 1)


def tiles(rng, size, n=8, color=(0.85, 0.88, 0.9), grout=(0.35, 0.37, 0.4), grout_px=2, jitter=0.06) -> np.ndarray:
    img = np.ones((size, size, 3)) * _rgb(color)
    step = size // n
    for i in range(n):
        for j in range(n):
            img[i * step:(i + 1) * step, j * step:(j + 1) * step] *= 1 - jitter + 2 * jitter * rng.random()
    idx = np.arange(size) % step < grout_px
    img[idx] = grout
    img[:, idx] = grout
    return np.clip(img, 0, 1)


def wood(rng, size, base=(0.55, 0.36, 0.2), rings=14) -> np.ndarray:
    n = value_noise(rng, size, 3, base_cells=2)
    y = np.linspace(0, 1, size)[:, None]
    grain = 0.5 + 0.5 * np.sin(2 * np.pi * (rings * y + 3.0 * n))
    return np.clip(_rgb(base) * (0.7 + 0.45 * grain[..., None]), 0, 1)


def pixel_art(pattern: np.ndarray, palette: dict, size: int = 64) -> np.ndarray:
    """Upscale a small character grid (list of strings or 2-D array of keys) with a palette."""
    grid = np.array([list(row) for row in pattern]) if not isinstance(pattern, np.ndarray) else pattern
    small = np.stack([[palette[k] for k in row] for row in grid]).astype(np.float64)
    rep_y, rep_x = size // small.shape[0], size // small.shape[1]
    return np.repeat(np.repeat(small, rep_y, axis=0), rep_x, axis=1)


def random_pixels(rng, n, palette, size=64) -> np.ndarray:
    keys = list(palette)
    grid = np.array(keys, dtype=object)[rng.integers(0, len(keys), (n, n))]
    return pixel_art(grid, palette, size)


def labelled(rng, size, base, ink=(0.1, 0.1, 0.12), n_marks=40) -> np.ndarray:
    """A plain surface with random dark rectangles and lines (labels, signs, scuffs)."""
    img = mottled(rng, size, base, 0.08)
    for _ in range(n_marks):
        h, w = rng.integers(1, size // 10, 2)
        y, x = rng.integers(0, size - h), rng.integers(0, size - w)
        img[y:y + h, x:x + w] = _rgb(ink) * (0.7 + 0.6 * rng.random())
    return np.clip(img, 0, 1)
