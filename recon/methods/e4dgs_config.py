"""E-4DGS's config: its event supervision (ESS, AES, TV, IIP, inherited deformation switches) and the
RGB term of `e4dgs_rgb` (strict YAML through `common.config`); the method is recon/methods/e4dgs.py."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from common.config import MAX_ITERATIONS, ConfigError, check_positive
from recon.config import DensifyConfig, InitConfig, TrainConfig


@dataclass(frozen=True)
class EventConfig:
    """E-4DGS's event supervision. Every component has a switch for the paper's ablations."""
    # ESS: N uniform in a range. window_scale "rate": the range is window_fraction of each camera's
    # events over the clip, so windows follow the dataset's event rate (docs/design/e4dgs.md says why);
    # "pixels": the paper's counts (n_events_object / n_events_room, for its 346x260 sensor) scaled
    # by the pixel count. Either way capped at max_window_fraction of the smallest stream.
    ess: bool = True
    window_scale: Literal["rate", "pixels"] = "rate"  # how the ESS window's event count is chosen (the note above)
    window_fraction: tuple[float, float] = (0.05, 0.2)  # rate: the range as fractions of each camera's events
    n_events_object: tuple[int, int] = (5_000, 10_000)  # pixels: the paper's range for objects (346x260)
    n_events_room: tuple[int, int] = (100_000, 1_000_000)  # pixels: the paper's range for rooms (346x260)
    noise_sigma: float = 0.02          # log units, on event-free pixels (0: no jitter)
    max_window_fraction: float = 0.5  # a window holds at most this fraction of the smallest event stream
    # cameras supervised per step: the ESS window of one camera, then the same time window on
    # views_per_step - 1 others; the deformation runs once per timestamp for all of them. The paper does
    # not say how many views a step uses; 1 is one camera per step.
    views_per_step: int = 1
    # AES: learnable contrast threshold C_hat = exp(log_c), initialised at c_init; fixed when off
    aes: bool = True
    c_init: float = 0.15  # AES: the learnable threshold's initial value
    c_lr: float = 1e-3                 # Adam rate on log C_hat
    recon_eps: float = 1e-3  # the event loss's Charbonnier epsilon
    # the event loss averaged over count maps pooled in s x s blocks (recon.event_supervision.multiscale_recon_loss);
    # (1,) is the paper's per-pixel loss
    loss_scales: tuple[int, ...] = (1,)
    lambda_recon: float = 1.0  # weight of the event loss
    lambda_tv: float = 0.005           # 0 switches TV off
    # IIP: prune Gaussians whose largest alpha x transmittance over the training cameras at iip_times
    # timestamps is below iip_threshold, every iip_interval iterations from iip_start (reference
    # iterations, scaled like the schedule)
    iip: bool = True
    iip_threshold: float = 0.015  # IIP: prune below this max alpha x transmittance
    iip_start: int = 3000              # after the warm-up: on the initial fog (opacity 0.1) most
    iip_interval: int = 1000           # Gaussians score below 0.015 (lego: 10k of 20k at iteration 100)
    iip_times: int = 5  # IIP: timestamps each Gaussian's importance is taken over
    inherit_deformation: bool = True   # clone / split children read their parent's deformation input

    def __post_init__(self):
        for name in ("n_events_object", "n_events_room"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ConfigError(f"{name}: expected 0 < min <= max, got {[lo, hi]}")
        lo, hi = self.window_fraction
        if not 0 < lo <= hi <= 1:
            raise ConfigError(f"window_fraction: expected 0 < min <= max <= 1, got {[lo, hi]}")
        check_positive(self, "c_init", "recon_eps", "iip_interval", "iip_times", "max_window_fraction",
                       "views_per_step")
        if not self.loss_scales or any(not isinstance(s, int) or s < 1 for s in self.loss_scales):
            raise ConfigError(f"loss_scales: expected block sizes >= 1 (pixels), got {list(self.loss_scales)!r}")
        if self.noise_sigma < 0 or self.lambda_tv < 0 or self.lambda_recon < 0:
            raise ConfigError("noise_sigma, lambda_tv, lambda_recon: expected values >= 0")


def _e4dgs_train() -> TrainConfig:
    # no opacity reset (paper); gradient threshold 3e-3: the event loss is in counts (1 / C_hat ~ 7x)
    # of log intensity (d log(linear) / d sRGB ~ 2-8x), so its view-space gradients are 15-40x the
    # photometric ones; at 1e-3 the tiny test scene grew 2k -> 24k Gaussians in 340 iterations
    # initial points in the background's colour: events fix every contrast's sign, so a start with
    # contrast of its own (mid-grey on a darker background) must first be unlearned (docs/design/e4dgs.md)
    return TrainConfig(densify=DensifyConfig(opacity_reset=False, grad_threshold=3e-3),
                       init=InitConfig(color="background"))


@dataclass(frozen=True)
class E4DGSConfig:
    """E-4DGS. `e4dgs`: events only (grayscale model). `e4dgs_rgb`: events + the blurred RGB frames of
    `rgb_frames` (colour model), L = L_event + lambda_rgb L_RGB. A blurred frame is predicted as the
    mean, in linear light, of `rgb_samples` renders spread over its exposure (`rgb_render: mean`), or
    as one render at the exposure centre (`rgb_render: centre`). With `rgb_every` N > 1 the RGB term
    joins every N-th step only (iterations N, 2N, ...), so the other steps cost what an events-only
    step costs; its weight stays lambda_rgb."""
    events: EventConfig = field(default_factory=EventConfig)  # the event supervision (ESS, AES, IIP, TV)
    rgb_frames: str = "medium"  # the blur level whose frames supervise the RGB term
    lambda_rgb: float = 1.0  # weight of the blurred-RGB loss (events + RGB)
    rgb_every: int = 1  # an RGB term every this many iterations
    lambda_dssim: float = 0.2  # D-SSIM's share of the RGB loss
    rgb_render: Literal["mean", "centre"] = "mean"  # a blurred frame as the mean of renders over its exposure, or one at its centre
    rgb_samples: int = 3  # renders averaged over each blurred frame's exposure
    train: TrainConfig = field(default_factory=_e4dgs_train)

    def __post_init__(self):
        check_positive(self, "rgb_samples", "rgb_every")


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
EventConfig.BOUNDS = {
    "noise_sigma": (0.0, 10.0, "log intensity"), "max_window_fraction": (0.0, 1.0, "a fraction of the clip"),
    "views_per_step": (1, 64, "cameras per step"), "c_init": (1e-6, 10.0, "a contrast threshold (log intensity)"),
    "c_lr": (0.0, 10.0, "a learning rate"), "recon_eps": (0.0, 1.0, "the Charbonnier epsilon"),
    "lambda_recon": (0.0, 1e6, "a loss weight"), "lambda_tv": (0.0, 1e6, "a loss weight"),
    "iip_threshold": (0.0, 1.0, "a compositing weight"), "iip_start": (0, MAX_ITERATIONS, "iterations"),
    "iip_interval": (1, MAX_ITERATIONS, "iterations"), "iip_times": (0, 1000, "timestamps"),
}
E4DGSConfig.BOUNDS = {
    "lambda_rgb": (0.0, 1e6, "a loss weight"), "rgb_every": (1, MAX_ITERATIONS, "iterations"),
    "lambda_dssim": (0.0, 1.0, "D-SSIM's share of the RGB loss"), "rgb_samples": (1, 1000, "sharp renders per blurred frame"),
}
