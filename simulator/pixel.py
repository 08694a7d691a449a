"""Pure per-pixel functions of the DVS model: colour to luminance, log responses, low-pass, rates.

Arrays in, arrays out, no state. Intensities are scene-linear luminance (1.0 = diffuse white);
log intensities are natural-log units; times are seconds where named `_s`, microseconds `_us`.
"""
from __future__ import annotations

import math

import numpy as np

from common.color import REC709_LUMA, linear_to_srgb, rec709_luma, srgb_to_linear  # noqa: F401 (re-exported)

# v2e maps 8-bit DN to the photoreceptor bandwidth scale as (DN + 20) / 275.
_INTEN_OFFSET_DN, _INTEN_SCALE_DN = 20.0, 275.0
# v2e: shot-noise rate at full white is this fraction of the rate in the dark.
SHOT_NOISE_WHITE_FACTOR = 0.25


def log_response(intensity: np.ndarray, eps: float, out: np.ndarray | None = None) -> np.ndarray:
    """log(I + eps) [same shape], in the precision of `out` (float64 when out is None); finite for I = 0."""
    out = np.add(intensity, eps, out=out, dtype=np.float64 if out is None else out.dtype)
    return np.log(out, out=out)


def linlog_response_ref(intensity: np.ndarray, threshold_dn: float, dn_per_unit: float,
                        out: np.ndarray | None = None) -> np.ndarray:
    """v2e's lin-log in float64: with DN = dn_per_unit * I, DN * log(thr)/thr for DN <= thr, else log(DN).

    Continuous at DN = thr (both sides equal log(thr)); zero at DN = 0. Readable reference of
    `linlog_response`.
    """
    dn = np.multiply(intensity, dn_per_unit, dtype=np.float64)
    res = np.log(np.maximum(dn, threshold_dn))
    low = dn <= threshold_dn
    res[low] = dn[low] * (math.log(threshold_dn) / threshold_dn)
    if out is not None:
        out[...] = res
        return out
    return res


def linlog_response(intensity: np.ndarray, threshold_dn: float, dn_per_unit: float,
                    out: np.ndarray | None = None, scratch: np.ndarray | None = None) -> np.ndarray:
    """`linlog_response_ref` in the precision of `out` (float64 when out is None), like
    `log_response`, in whole-array passes over kept buffers (boolean indexing and fresh arrays
    cost ~20x a log per frame here). `scratch` [2, *shape] of out's dtype is reused when given.

    For thr > e the two branches meet as a minimum: DN k (k = log(thr)/thr) is the chord through the
    origin and (thr, log thr), below log(max(DN, thr)) = log(thr) when DN < thr, and above log(DN) when
    DN > thr because log(x)/x decreases for x > e. So the response is min(log(max(DN, thr)), DN k):
    in float64 equal to the reference except within an ulp at DN == thr, where the two branches agree
    to an ulp. For thr <= e the branches are blended with 0/1 weights (x * 1 + y * 0 == x).
    """
    shape = np.shape(intensity)
    dtype = np.dtype(np.float64 if out is None else out.dtype)
    private = scratch is None or scratch.shape != (2,) + shape or scratch.dtype != dtype
    if private:
        scratch = np.empty((2,) + shape, dtype)
    dn, res = scratch[0], scratch[1]
    k = math.log(threshold_dn) / threshold_dn
    np.multiply(intensity, dtype.type(dn_per_unit), out=dn, dtype=dtype)
    np.maximum(dn, dtype.type(threshold_dn), out=res)
    np.log(res, out=res)
    if threshold_dn > math.e:
        dn *= dtype.type(k)
        if out is None:
            out = np.empty(shape, dtype)
        return np.minimum(res, dn, out=out)
    high = np.greater(dn, dtype.type(threshold_dn)).astype(dtype)
    res *= high
    np.subtract(1.0, high, out=high)
    dn *= dtype.type(k)
    dn *= high
    res += dn
    if out is None:
        return res if private else res.copy()   # never hand out the caller's scratch
    out[...] = res
    return out


def intensity01(intensity: np.ndarray) -> np.ndarray:
    """v2e's normalised intensity (DN + 20) / 275 with DN = 255 I: sets photoreceptor bandwidth."""
    return (np.asarray(intensity, dtype=np.float64) * 255.0 + _INTEN_OFFSET_DN) / _INTEN_SCALE_DN


def lowpass_step(lp_prev: np.ndarray, log_new: np.ndarray, intensity: np.ndarray, dt_s: float,
                 cutoff_hz: float, out: np.ndarray | None = None,
                 scratch: np.ndarray | None = None) -> np.ndarray:
    """One step of v2e's intensity-dependent first-order photoreceptor filter [P].

    tau = 1 / (2 pi cutoff_hz); the update weight eps = intensity01(I) * dt / tau is clamped to 1,
    so bright pixels follow the input faster than dark ones. `out` may be `lp_prev` (in place);
    `scratch` [P] float64 avoids temporaries.
    """
    k = dt_s * 2.0 * math.pi * cutoff_hz  # dt / tau
    keep = np.multiply(intensity, 255.0 * k / _INTEN_SCALE_DN, out=scratch, dtype=np.float64)
    keep += _INTEN_OFFSET_DN * k / _INTEN_SCALE_DN
    np.minimum(keep, 1.0, out=keep)          # eps
    np.subtract(1.0, keep, out=keep)         # 1 - eps
    res = out if out is not None else np.empty(np.shape(lp_prev), np.float64)
    # lp + eps (new - lp) == new + (1 - eps)(lp - new): no temporaries, and `out` may be `lp_prev`
    np.subtract(lp_prev, log_new, out=res)
    res *= keep
    res += log_new
    return res


def sample_thresholds(rng: np.random.Generator, nominal: float, sigma: float, minimum: float,
                      n_pixels: int) -> np.ndarray:
    """Per-pixel contrast thresholds [P]: Normal(nominal, sigma) clamped to >= minimum."""
    if sigma <= 0:
        return np.full(n_pixels, nominal, dtype=np.float64)
    return np.maximum(rng.normal(nominal, sigma, n_pixels), minimum)


def shot_noise_rates_hz(inten01: np.ndarray, total_rate_hz: float, c_nominal: float,
                        c_pixel: np.ndarray, share: float = 0.5,
                        white_factor: float = SHOT_NOISE_WHITE_FACTOR) -> np.ndarray:
    """Per-pixel, per-polarity shot-noise rate [P] as in v2e.

    `share` of the total rate for this polarity (v2e: half), scaled from 1 in the dark to
    `white_factor` at white (v2e: SHOT_NOISE_WHITE_FACTOR), and by nominal / actual threshold (pixels
    with smaller thresholds are noisier).
    """
    w = np.clip(inten01, 0.0, 1.0)
    return (share * total_rate_hz) * ((white_factor - 1.0) * w + 1.0) * (c_nominal / c_pixel)


def diffusion_walk(rate_hz, on_fraction: float, c_pos: float, c_neg: float):
    """The random walk (sigma in log units per sqrt(s), drift in log units per s; shapes of `rate_hz`)
    whose threshold crossings make `rate_hz` events per second on a still pixel, `on_fraction` of them ON.

    A walk with drift mu and variance sigma^2 per second, started at the reference, leaves (-C, C)
    upwards with probability 1 / (1 + exp(-k)), k = 2 mu C / sigma^2, after a mean time
    (C / mu) tanh(k / 2) (C^2 / sigma^2 without drift); an event moves the reference by C and the walk
    starts again. So k = logit(on_fraction), sigma^2 = rate C^2 2 tanh(k / 2) / k, mu = k sigma^2 / (2 C).
    C is the mean of c_pos and c_neg (exact when they are equal).
    """
    c = 0.5 * (c_pos + c_neg)
    k = drift_number(on_fraction)
    shape = 1.0 if abs(k) < 1e-9 else 2.0 * math.tanh(k / 2.0) / k
    var_per_s = np.asarray(rate_hz, dtype=np.float64) * (c * c * shape)
    return np.sqrt(var_per_s), var_per_s * (k / (2.0 * c))


def drift_number(on_fraction: float) -> float:
    """k = 2 mu C / sigma^2 of a walk that leaves (-C, C) upwards with probability on_fraction:
    logit(on_fraction)."""
    return math.log(on_fraction / (1.0 - on_fraction))


def diffusion_equilibrium_offsets(rng: np.random.Generator, k: np.ndarray, grid: int = 2001) -> np.ndarray:
    """Where a drifted walk stands against its reference at a random moment of a long still recording,
    in thresholds, per pixel [P] (in (-1, 1)), for each pixel's drift number k [P] (2 mu C / sigma^2).

    The walk restarts at the reference after each event, so its position is distributed as the time it
    spends at x before leaving (-1, 1) from 0: the Green's function of the drifted walk, with scale
    s(x) = (1 - exp(-k x)) / k and speed density exp(k x): (s(min(x, 0)) - s(-1)) (s(1) - s(max(x,
    0))) exp(k x); without drift the triangle 1 - |x|, with a strong upward drift uniform on (0, 1)
    (a leak's phase). Drawn by inverting its distribution function on `grid` points, for k rounded to
    0.05 and clipped to +-50 (beyond, the shape no longer changes to the grid's resolution).
    """
    k = np.clip(np.round(np.asarray(k, np.float64) / 0.05) * 0.05, -50.0, 50.0)
    x = np.linspace(-1.0, 1.0, grid)
    u = rng.random(k.shape)
    out = np.empty(k.shape)
    below = x < 0
    for kv in np.unique(k):
        if abs(kv) < 1e-9:
            density = 1.0 - np.abs(x)
        else:   # the products written with expm1: no cancellation near the barriers (times k^2, same shape)
            density = np.where(below, np.expm1(kv * (1.0 + x)) * -np.expm1(-kv),
                               np.expm1(kv) * -np.expm1(-kv * (1.0 - x)))
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(x))])
        sel = k == kv
        out[sel] = np.interp(u[sel], cdf / cdf[-1], x)
    return out
