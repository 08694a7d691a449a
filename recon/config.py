"""The typed training config every reconstruction method shares (strict YAML through `common.config`):
initialisation, learning rates, densification, schedules. Each method's own config sits beside it
in recon/methods/ (D3DGSConfig in d3dgs.py, E4DGSConfig in e4dgs_config.py, ...).

Schedules are written for the public D3DGS budget (40,000 iterations) and, with
`scale_schedule: true`, scaled to the run's `iterations` (see `Schedule`), so a short CPU run keeps
the public code's proportions: warm-up 7.5 %, densification from 1.25 % to 37.5 %, etc. Two
intervals have floors, because what they wait for does not shrink with the budget: densification
accumulates gradients over at least MIN_DENSIFY_INTERVAL views, and after an opacity reset the
opacities need several hundred Adam steps (lr 0.05 on logits) to recover, so resets come at least
MIN_OPACITY_RESET_INTERVAL iterations apart (short budgets get none). The warm-up (static
Gaussians first) lasts at least MIN_WARM_UP iterations: a deformation field switched on before the
static fit has settled follows coherent gradients and its offsets grow exponentially (measured on
the tiny test scene: a 45-iteration warm-up gave log-scale offsets of -180 within 250 iterations).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Literal

from common.config import MAX_ITERATIONS, SEED_RANGE, ConfigError, check_positive

PRECISIONS = ("auto", "float32", "bfloat16")      # train.precision's values (recon.precision chooses for auto)
PAPER_SIZE = (8, 256)    # depth, width of the paper's (D3DGS's) deformation MLP
PAPER_POSITION_FREQS = 10  # D3DGS's position encoding: sin / cos at 2^0 .. 2^9


def mlp_spec(depth: int = PAPER_SIZE[0], width: int = PAPER_SIZE[1], position_freqs: int = PAPER_POSITION_FREQS) -> dict:
    """recon.deform.make_field's spec of an MLP: {"kind": "mlp"} for the paper's field (what runs
    recorded before the size was a choice), with depth and width for another size, and
    position_freqs where the position encoding is not the paper's."""
    spec = {"kind": "mlp"} if (depth, width) == PAPER_SIZE else {"kind": "mlp", "depth": depth, "width": width}
    if position_freqs != PAPER_POSITION_FREQS:
        spec["position_freqs"] = position_freqs
    return spec

REFERENCE_ITERATIONS = 40_000
MIN_DENSIFY_INTERVAL = 10
MIN_OPACITY_RESET_INTERVAL = 1000
MIN_WARM_UP = 200


@dataclass(frozen=True)
class InitConfig:
    """Initial points. `auto`: a cube for object scenes, a dense-to-sparse sphere for rooms (the scene
    kind comes from the dataset's scene.yaml). Sizes `null` mean: cube half size 0.35 x the camera
    rig's radius, sphere radius 10 (the paper's), both centred on the rig's target. `events`: the
    auto volume carved by the cameras' event activity (recon.event_init): `carve_candidates` points
    of it are tested at `carve_times` instants, each against every camera's events within
    `carve_window` (a fraction of the clip), pixels active with >= `carve_min_events` events in
    their 3x3 neighbourhood, grown by `carve_dilate_px`. `color`: every point starts mid-grey (0.5,
    as 3DGS without SfM colours), or the scene's empty-background colour, so that the initial model
    renders no contrast at all and every contrast it ends with was learned (docs/design/e4dgs.md).
    `carve_fallback`: where the carving keeps no point (too few events agree between the cameras),
    `auto` starts from the auto volume instead, recorded in run.json's `init_fallback`; `error` stops."""
    kind: Literal["auto", "cube", "sphere", "points", "events"] = "auto"  # where the initial points lie (the class note)
    color: Literal["mid", "background"] = "mid"  # the initial points' colour: mid-grey or the empty background's
    n_points_object: int = 100_000  # initial points in an object scene
    n_points_room: int = 200_000  # initial points in a room scene
    cube_half_size: float | None = None  # half size of the initial cube (None: 0.35 x the rig's radius)
    sphere_radius: float | None = None  # radius of a room's initial sphere (None: 10, the paper's)
    points_file: str | None = None   # .npy or .ply-free [N, 3] float array, for kind: points
    init_opacity: float = 0.1  # every initial point's opacity
    seed: int = 0  # the initial points' random draws
    carve_candidates: int = 200_000  # events: candidate points tested against the cameras' events
    carve_times: int = 9  # events: instants of the clip the candidates are tested at
    carve_window: float = 0.01      # quick hinge, untrained model: 0.1 / 3 px 27.99 dB, 0.03 / 2 px 28.37,
    carve_min_events: int = 2       # 0.01 / 1 px 28.72 (the shorter the window, the less the motion
    carve_dilate_px: int = 1        # smears the silhouettes; docs/design/e4dgs.md)
    carve_fallback: Literal["auto", "error"] = "auto"  # where carving keeps no point: start from the auto volume, or stop

    def __post_init__(self):
        check_positive(self, "n_points_object", "n_points_room", "carve_candidates", "carve_times",
                       "carve_min_events")
        if not 0 < self.carve_window <= 1:
            raise ConfigError(f"carve_window: expected a fraction of the clip in (0, 1], got {self.carve_window!r}")
        if self.carve_dilate_px < 0:
            raise ConfigError(f"carve_dilate_px: expected a value >= 0, got {self.carve_dilate_px!r}")
        if not 0 < self.init_opacity < 1:
            raise ConfigError(f"init_opacity: expected a value in (0, 1), got {self.init_opacity!r}")
        if self.kind == "points" and not self.points_file:
            raise ConfigError("points_file: required when kind is 'points'")


@dataclass(frozen=True)
class LearningRates:
    """Adam learning rates of the public D3DGS code. position_* are multiplied by the scene extent
    (3DGS's spatial_lr_scale); the deformation field's rate starts at position_init x deform_scale."""
    position_init: float = 1.6e-4  # means' rate at the start (x scene extent)
    position_final: float = 1.6e-6  # means' rate at the end of position_lr_steps (x scene extent)
    position_delay_mult: float = 0.01  # 3DGS's delay multiplier of the position rate
    feature: float = 0.0025          # SH degree 0; higher degrees use feature / 20
    opacity: float = 0.05  # opacity logits' rate
    opacity_final: float | None = None   # None: constant; else log-linear decay to it over the run
    scaling: float = 0.001  # log-scales' rate
    rotation: float = 0.001  # quaternions' rate
    deform_scale: float = 5.0  # the deformation's rate over position_init

    def __post_init__(self):
        for name in ("position_init", "position_final", "position_delay_mult", "feature", "opacity", "scaling",
                     "rotation", "deform_scale"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"{name}: expected a learning rate >= 0, got {getattr(self, name)!r}")
        if self.opacity_final is not None and not self.opacity_final > 0:
            raise ConfigError(f"opacity_final: expected a value > 0 (or null), got {self.opacity_final!r}")


@dataclass(frozen=True)
class DensifyConfig:
    """3DGS adaptive density control. Iteration numbers are for the 40k reference budget."""
    enabled: bool = True  # clone, split and prune Gaussians during training
    start: int = 500  # first densification iteration (reference iterations)
    stop: int = 15_000  # last densification iteration (reference iterations)
    interval: int = 100  # iterations between densifications (reference iterations)
    grad_threshold: float = 2e-4     # on the NDC-space gradient norm of the projected means
    percent_dense: float = 0.01      # clone below / split above this fraction of the scene extent
    min_opacity: float = 0.005  # prune Gaussians below this opacity
    max_screen_size: float = 20.0    # pixels; applied after the first opacity reset
    max_world_size: float = 0.1      # fraction of the scene extent
    opacity_reset: bool = True  # reset every opacity every opacity_reset_interval iterations
    opacity_reset_interval: int = 3000  # iterations between opacity resets (reference iterations)
    max_gaussians: int = 1_000_000   # no densification beyond this count


@dataclass(frozen=True)
class DeformFieldConfig:
    """What deforms the canonical Gaussians over time: `mlp`, a network on the encoded position and
    time (D3DGS's field, recon.deform; the paper's is 8 layers of 256, `depth` x `width`), or `trajectory`, per-Gaussian
    coefficients of `degree` polynomial and `fourier` sine / cosine pairs of time (Gaussian-Flow's
    dual-domain deformation, recon.trajectory). Trajectory coefficients learn at lr_scale x the
    means' rate, decaying after the warm-up as the MLP's rate does. `smoothness` weighs a temporal
    smoothness term added to the loss while the trajectories are on: the mean acceleration energy of
    the position offsets over the clip, in units of the scene's extent (recon.trajectory); 0 is off."""
    kind: Literal["mlp", "trajectory"] = "mlp"  # the paper's deformation MLP, or per-Gaussian trajectories
    degree: int = 3  # trajectory: polynomial terms of time
    fourier: int = 2  # trajectory: sine / cosine pairs of time
    lr_scale: float = 1.0  # the field's rate over the means' rate
    smoothness: float = 0.0  # trajectory: weight of the acceleration energy (0: off)
    depth: int = 8  # mlp: linear layers (the encoded input joins again after depth // 2)
    width: int = 256  # mlp: hidden units per layer
    position_freqs: int = PAPER_POSITION_FREQS  # mlp: sin / cos pairs of the position encoding (2^0 .. 2^(n-1)); D3DGS's 10

    def __post_init__(self):
        if self.degree < 0 or self.fourier < 0 or self.degree + self.fourier == 0:
            raise ConfigError(f"degree, fourier: expected values >= 0, not both 0; got {self.degree!r}, {self.fourier!r}")
        if not self.lr_scale >= 0:
            raise ConfigError(f"lr_scale: expected a value >= 0, got {self.lr_scale!r}")
        if not (self.smoothness >= 0 and math.isfinite(self.smoothness)):
            raise ConfigError(f"smoothness: expected a finite value >= 0, got {self.smoothness!r}")
        if self.smoothness > 0 and self.kind != "trajectory":
            raise ConfigError(f"smoothness: regularises per-Gaussian trajectories; expected kind: trajectory "
                              f"with smoothness {self.smoothness!r}, got kind: {self.kind}")

    def spec(self) -> dict:
        """recon.deform.make_field's spec of this field."""
        if self.kind == "mlp":
            return mlp_spec(self.depth, self.width, self.position_freqs)
        return {"kind": "trajectory", "degree": self.degree, "fourier": self.fourier}


@dataclass(frozen=True)
class CoarseToFineConfig:
    """Render and supervise at reduced resolution first (recon.coarse): factors[k] (an integer >= 2,
    decreasing) until the fraction until[k] of the run (increasing, in (0, 1]), then full resolution.
    Empty (the default): full resolution throughout. Example: factors [4, 2], until [0.2, 0.5]."""
    factors: tuple[int, ...] = ()  # downscale factors, decreasing (e.g. [4, 2])
    until: tuple[float, ...] = ()  # the fraction of the run each factor lasts until, increasing

    def __post_init__(self):
        if len(self.factors) != len(self.until):
            raise ConfigError(f"factors, until: expected one end per factor, got {len(self.factors)} factors and "
                              f"{len(self.until)} ends")
        if any(not isinstance(f, int) or isinstance(f, bool) or f < 2 for f in self.factors) or \
                any(a <= b for a, b in zip(self.factors, self.factors[1:])):
            raise ConfigError(f"factors: expected integers >= 2, decreasing, got {list(self.factors)!r}")
        if any(not 0 < u <= 1 for u in self.until) or any(a >= b for a, b in zip(self.until, self.until[1:])):
            raise ConfigError(f"until: expected fractions of the run in (0, 1], increasing, got {list(self.until)!r}")

    def factor_at(self, iteration: int, iterations: int) -> int:
        """The render factor at `iteration` (1-based) of a run of `iterations`: factors[k] while
        iteration <= until[k] x iterations (the first stage not yet ended), then 1."""
        for f, end in zip(self.factors, self.until):
            if iteration <= end * iterations:
                return f
        return 1


@dataclass(frozen=True)
class Schedule:
    """Iteration numbers after scaling to the run's budget."""
    warm_up: int
    densify_start: int
    densify_stop: int
    densify_interval: int
    opacity_reset_interval: int
    position_lr_steps: int
    deform_lr_steps: int
    sh_interval: int


@dataclass(frozen=True)
class TrainConfig:
    """What every method's trainer shares: budget, schedule, checkpoints, evaluation."""
    iterations: int = 40_000  # training iterations of this run
    scale_schedule: bool = True  # scale the schedule's iteration counts to this run's iterations
    # the budget the schedule's iteration counts below are written for; with scale_schedule they are
    # scaled by iterations / schedule_reference (a recipe written for 750 iterations, run for 420)
    schedule_reference: int = REFERENCE_ITERATIONS
    deform: bool = True               # false: a static 3DGS (no deformation field is ever applied)
    deform_field: DeformFieldConfig = field(default_factory=DeformFieldConfig)  # what deforms the Gaussians over time
    coarse_to_fine: CoarseToFineConfig = field(default_factory=CoarseToFineConfig)  # reduced resolution first
    warm_up: int = 3000               # deformation off before this (reference iterations)
    position_lr_steps: int = 30_000  # iterations over which the position rate decays (reference iterations)
    deform_lr_steps: int = 40_000  # iterations over which the deformation rate decays (reference iterations)
    sh_degree: int = 3  # highest spherical-harmonics degree of the colours (0-3)
    sh_interval: int = 1000           # one more SH degree every this many (reference) iterations
    lr: LearningRates = field(default_factory=LearningRates)  # learning rates
    densify: DensifyConfig = field(default_factory=DensifyConfig)  # adaptive density control
    init: InitConfig = field(default_factory=InitConfig)  # the initial points
    background: tuple[float, float, float] | None = None   # None: the scene's empty-background colour
    # the deformation MLP's arithmetic: auto measures this machine once and takes the faster of
    # float32 and bfloat16 autocast (recon.precision; bf16 is 2-3x faster on cores with native bf16,
    # 10x slower on cores without); parameters stay float32 either way
    precision: str = "auto"
    backend: str = "auto"             # auto: gsplat on CUDA, the numba cpu backend on the CPU (recon.raster)
    device: str = "auto"              # auto: CUDA when torch sees it and gsplat is installed, else the CPU
    seed: int = 0  # training's random draws (views, windows, noise)
    checkpoint_every: int = 500       # real iterations between resumable checkpoints
    eval_every: int = 0               # real iterations between test-PSNR log rows (0: at snapshots only)
    eval_max_views: int = 0           # test views used for the log's PSNR (0: all)
    snapshots: tuple[float, ...] = (0.1, 0.25, 0.5, 1.0)   # fractions of the budget saved as models

    def __post_init__(self):
        check_positive(self, "iterations", "checkpoint_every", "schedule_reference")
        if not 0 <= self.sh_degree <= 3:
            raise ConfigError(f"sh_degree: expected 0..3, got {self.sh_degree!r}")
        if self.eval_every < 0 or self.eval_max_views < 0:
            raise ConfigError("eval_every, eval_max_views: expected values >= 0")
        for f in self.snapshots:
            if not 0 < f <= 1:
                raise ConfigError(f"snapshots: expected fractions in (0, 1], got {f!r}")
        if self.background is not None and not all(0 <= c <= 1 for c in self.background):
            raise ConfigError(f"background: expected values in [0, 1], got {self.background!r}")
        if self.precision not in PRECISIONS:
            raise ConfigError(f"precision: expected {', '.join(PRECISIONS[:-1])} or {PRECISIONS[-1]}, got {self.precision!r}")
        if self.backend not in ("auto", "cpu", "gsplat", "torch", "dense"):
            raise ConfigError(f"backend: expected auto, cpu, gsplat, torch or dense, got {self.backend!r}")
        if not (self.device in ("auto", "cpu", "cuda") or re.fullmatch(r"cuda:\d+", self.device)):
            raise ConfigError(f"device: expected auto, cpu, cuda or cuda:N, got {self.device!r}")

    def scaled(self, v: int) -> int:
        """An iteration count of the reference schedule (schedule_reference iterations, 40k by default)
        at this run's budget (>= 1)."""
        s = self.iterations / self.schedule_reference if self.scale_schedule else 1.0
        return max(1, int(round(v * s)))

    def schedule(self) -> Schedule:
        sc = self.scaled

        d = self.densify
        return Schedule(warm_up=max(sc(self.warm_up), min(self.warm_up, MIN_WARM_UP)), densify_start=sc(d.start),
                        densify_stop=sc(d.stop), densify_interval=max(sc(d.interval), min(d.interval, MIN_DENSIFY_INTERVAL)),
                        opacity_reset_interval=max(sc(d.opacity_reset_interval),
                                                   min(d.opacity_reset_interval, MIN_OPACITY_RESET_INTERVAL)),
                        position_lr_steps=sc(self.position_lr_steps), deform_lr_steps=sc(self.deform_lr_steps),
                        sh_interval=sc(self.sh_interval))


# Ranges of the numeric fields (common.config.check_bounds: refused when loaded, naming the key).
_STEPS = (0, MAX_ITERATIONS, "iterations")
InitConfig.BOUNDS = {
    "n_points_object": (1, 10_000_000, "initial Gaussians; 10x a dense 3DGS scene"),
    "n_points_room": (1, 10_000_000, "initial Gaussians; 10x a dense 3DGS scene"),
    "cube_half_size": (1e-6, 1e4, "scene units"), "sphere_radius": (1e-6, 1e4, "scene units"),
    "init_opacity": (0.0, 1.0, "an opacity"), "seed": SEED_RANGE,
    "carve_candidates": (1, 10_000_000, "points tested"), "carve_times": (1, 1000, "instants"),
    "carve_window": (0.0, 1.0, "a fraction of the clip"), "carve_min_events": (1, 1000, "events in a 3x3 neighbourhood"),
    "carve_dilate_px": (0, 64, "pixels"),
}
LearningRates.BOUNDS = {name: (0.0, 10.0, "a learning rate") for name in
                        ("position_init", "position_final", "position_delay_mult", "feature", "opacity", "opacity_final",
                         "scaling", "rotation")}
LearningRates.BOUNDS["deform_scale"] = (0.0, 1000.0, "a multiple of the position rate")
DensifyConfig.BOUNDS = {
    "start": _STEPS, "stop": _STEPS, "interval": (1, MAX_ITERATIONS, "iterations"), "opacity_reset_interval": (1, MAX_ITERATIONS, "iterations"),
    "grad_threshold": (0.0, 1e3, "an NDC gradient norm"), "percent_dense": (0.0, 1.0, "a fraction of the scene extent"),
    "min_opacity": (0.0, 1.0, "an opacity"), "max_screen_size": (0.0, 1e5, "pixels"),
    "max_world_size": (0.0, 1e3, "a multiple of the scene extent"),
    "max_gaussians": (1, 20_000_000, "Gaussians; ~6 GB of parameters and Adam state at 20 M"),
}
DeformFieldConfig.BOUNDS = {
    "degree": (0, 16, "polynomial degree of a trajectory"), "fourier": (0, 64, "sine / cosine pairs per trajectory"),
    "lr_scale": (0.0, 1e3, "a multiple of the means' rate"), "smoothness": (0.0, 1e6, "a loss weight"),
    "depth": (3, 16, "the MLP's linear layers"), "width": (8, 1024, "the MLP's hidden units"),
    "position_freqs": (0, 16, "sin / cos pairs of the position encoding"),
}
TrainConfig.BOUNDS = {
    "iterations": (1, MAX_ITERATIONS, "200x the paper's 50,000"), "schedule_reference": (1, MAX_ITERATIONS, "iterations"),
    "warm_up": _STEPS, "position_lr_steps": _STEPS, "deform_lr_steps": _STEPS, "sh_degree": (0, 3, "3DGS's SH degrees"),
    "sh_interval": (1, MAX_ITERATIONS, "iterations"), "seed": SEED_RANGE,
    "checkpoint_every": (0, MAX_ITERATIONS, "iterations"), "eval_every": _STEPS,
    "eval_max_views": (0, 100_000, "views"),
}
