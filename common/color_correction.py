"""Colour correction of event-trained renders at inference (paper eq. 11): per channel, a gain and
an offset on log intensity fitted by ordinary least squares to the ground truth.

Events fix log intensity only up to an offset (and, with an unknown threshold, a scale), so before
scoring, each channel's log-linear prediction L = log(linear(pred) + eps) is mapped to
g * L + b with (g, b) minimising sum (g L + b - L_gt)^2 over the image's pixels subject to g >= 0,
and re-encoded. A channel whose prediction is constant has no defined gain: then g = 1 and
b = mean(L_gt - L) (the offset alone), so the correction is always defined.

Why g >= 0: the gain stands for the unknown scale of the contrast thresholds, which is positive.
Event polarity fixes the sign of every contrast, so a prediction whose log intensity is
anti-correlated with the truth has its contrast inverted; an unconstrained fit (g < 0) would flip it
back and score it as if it were right. The constrained optimum is then g = 0 (the prediction
carries no usable contrast: the image becomes the ground truth's mean log intensity).
"""
from __future__ import annotations

import numpy as np

from common.color import linear_to_srgb, srgb_to_linear

LOG_EPS = 1e-3
_MIN_VAR = 1e-12


def fit_gain_offset(l_pred: np.ndarray, l_gt: np.ndarray) -> tuple[float, float]:
    """Least squares of l_gt ~ g l_pred + b over all elements with g >= 0: the OLS fit, or (0, mean
    l_gt) when the OLS gain is negative; (1, mean difference) when l_pred is constant."""
    x = np.asarray(l_pred, np.float64).ravel()
    y = np.asarray(l_gt, np.float64).ravel()
    if x.size == 0:
        raise ValueError("fit_gain_offset: empty input")
    xm, ym = x.mean(), y.mean()
    var = np.mean((x - xm) ** 2)
    if var < _MIN_VAR:
        return 1.0, float(ym - xm)
    g = float(np.mean((x - xm) * (y - ym)) / var)
    if g < 0.0:   # the quadratic in g is convex, so the best g >= 0 is the boundary
        return 0.0, float(ym)
    return g, float(ym - g * xm)


def correct_colors(pred_srgb: np.ndarray, gt_srgb: np.ndarray, eps: float = LOG_EPS) -> tuple[np.ndarray, list]:
    """Corrected prediction [H, W, C] (sRGB-encoded, clipped to [0, 1]) and the per-channel (g, b).

    pred_srgb and gt_srgb are [H, W, C] in [0, 1] (sRGB-encoded, as the dataset stores images).
    """
    if pred_srgb.shape != gt_srgb.shape:
        raise ValueError(f"correct_colors: shapes differ: {pred_srgb.shape} vs {gt_srgb.shape}")
    lp = np.log(srgb_to_linear(pred_srgb) + eps)
    lg = np.log(srgb_to_linear(gt_srgb) + eps)
    out = np.empty(pred_srgb.shape, np.float32)
    params = []
    for c in range(pred_srgb.shape[-1]):
        g, b = fit_gain_offset(lp[..., c], lg[..., c])
        params.append((g, b))
        out[..., c] = linear_to_srgb(np.exp(g * lp[..., c] + b) - eps)
    return out, params
