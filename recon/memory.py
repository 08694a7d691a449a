"""What a training run's Gaussians will take in memory, estimated from its config before anything is
allocated, so that a size typed wrong (init.n_points_object: 1e9) is refused naming the field instead
of ending in the kernel's OOM killer.

Per Gaussian the trainer holds each parameter four times (value, gradient, Adam's two moments) as
float32: mean 3, scale 3, rotation 4, opacity 1, SH colour 3 (sh_degree + 1)^2, and for a trajectory
field 3 (degree + 1 + 2 fourier) coefficients; plus ~512 bytes of the rasterizer's per-Gaussian
temporaries. The count is the most the run can reach: the initial points, or densify.max_gaussians
when densification is on.
"""
from __future__ import annotations

RASTER_BYTES_PER_GAUSSIAN = 512


def floats_per_gaussian(train) -> tuple[int, int]:
    """(floats of the Gaussian itself, floats of its trajectory) of a TrainConfig."""
    own = 3 + 3 + 4 + 1 + 3 * (train.sh_degree + 1) ** 2
    field = train.deform_field
    traj = 3 * (field.degree + 1 + 2 * field.fourier) if train.deform and field.kind == "trajectory" else 0
    return own, traj


def peak_gaussians(train, kind: str) -> tuple[int, str]:
    """(the most Gaussians the run can hold, the field that sets it)."""
    init = train.init
    start, name = ((init.n_points_room, "train.init.n_points_room") if kind == "room"
                   else (init.n_points_object, "train.init.n_points_object"))
    if init.kind == "events":
        start, name = max(start, init.carve_candidates), "train.init.carve_candidates" if init.carve_candidates > start else name
    if train.densify.enabled and train.densify.max_gaussians > start:
        return train.densify.max_gaussians, "train.densify.max_gaussians"
    return start, name


def training_bytes(train, kind: str) -> tuple[int, str]:
    """(estimated peak bytes of the Gaussians and their optimiser state, the field to lower first)."""
    n, count_field = peak_gaussians(train, kind)
    own, traj = floats_per_gaussian(train)
    per = 16 * (own + traj) + RASTER_BYTES_PER_GAUSSIAN
    field = "train.deform_field.fourier / degree" if traj > own else count_field
    return n * per, field


def check_fits(train, kind: str, available: int | None) -> None:
    """ValueError naming the field when the estimate exceeds the memory available (None: unknown, no check)."""
    need, field = training_bytes(train, kind)
    if available is not None and need > available:
        n, _ = peak_gaussians(train, kind)
        raise ValueError(f"{field}: the run would hold up to {n:,} Gaussians, ~{need / 2**30:.1f} GiB with their "
                         f"optimiser state, and this machine has {available / 2**30:.1f} GiB available; lower {field}")
