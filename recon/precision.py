"""The deformation field's arithmetic precision (`train.precision: auto | float32 | bfloat16`).

The 8 x 256 deformation MLP is about half of a training step on the CPU, and whether bfloat16 helps
depends on the core: with native bf16 (AVX-512 BF16, AMX) a bf16 matrix product ran 2.9x faster
than float32; on a core without it (AMD Zen 3, AVX2 only) 45x slower, and a whole D3DGS step 10.9x
slower (docs/design/recon.md, "Precision"). So `auto` measures instead of assuming:

    choice = resolve_precision("auto", torch.device("cpu"))   # PrecisionChoice(dtype="float32", ...)
    with autocast(choice.dtype, device):
        dx, dq, ds = field(x, t)

`auto` on the CPU times the field's own forward + backward at MEASURE_POINTS points in both dtypes
(warm-up first, then alternating repetitions, medians), picks the faster and caches the answer per
machine (CPU model, torch version, thread count) in common.machine.cache_dir() / precision.json, so
the measurement (a few seconds) runs once per machine. On CUDA `auto` is float32, what gsplat
rasterizes in and what the public D3DGS code trains in; `bfloat16` there is torch's CUDA autocast.
Parameters and optimizer state stay float32 whatever the choice: only the field's matrix products
change dtype, so a checkpoint resumes under either precision.
"""
from __future__ import annotations

import contextlib
import json
import statistics
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Mapping

import torch

from common.fileio import write_text_atomic
from common.machine import cache_dir, cpu_features, cpu_model
from recon.config import PRECISIONS
from recon.deform import PAPER_SIZE, DeformationField

DTYPES = ("float32", "bfloat16")
MEASURE_POINTS = 4096      # Gaussians of the timing (quick runs train 2k-20k; the ratio is what matters)
MEASURE_REPEATS = 3        # timed forward + backward passes per dtype, after one warm-up each
STOP_RATIO = 3.0           # a dtype whose warm-up takes this many times the other's median is not timed further
CACHE_FILE = "precision.json"
CACHE_FORMAT = "e4dgs-precision-cache/1"


@dataclass(frozen=True)
class PrecisionChoice:
    """What a run computes its deformation in, and why."""
    dtype: str                                   # float32 | bfloat16
    source: str          # config (asked for) | measured | cached | cuda (auto on CUDA) | trajectory (auto, no MLP)
    machine: str = ""                            # the cache key: CPU model, torch version, threads
    timings_ms: dict[str, float] = field(default_factory=dict)   # median ms of one fwd + bwd per dtype

    def to_dict(self) -> dict:
        return asdict(self)

    def describe(self) -> str:
        """One line for the run's log: 'float32 (measured on AMD EPYC ...: float32 260 ms, bfloat16 3700 ms ...)'."""
        if not self.timings_ms:
            why = {"config": "train.precision", "cuda": "auto on CUDA: float32",
                   "trajectory": "auto with per-Gaussian trajectories: float32"}.get(self.source, self.source)
            return f"{self.dtype} ({why})"
        times = ", ".join(f"{k} {v:.0f} ms" for k, v in self.timings_ms.items())
        return (f"{self.dtype} ({self.source}: {times} per deformation forward + backward of {MEASURE_POINTS} "
                f"points on {self.machine})")


def check_precision(value: str, where: str = "train.precision") -> str:
    if value not in PRECISIONS:
        raise ValueError(f"{where}: expected one of {', '.join(PRECISIONS)}, got {value!r}")
    return value


def faster_dtype(timings_ms: Mapping[str, float]) -> str:
    """The dtype with the smallest time; float32 on a tie or when bfloat16 was not timed (it is exact)."""
    best = "float32"
    for dtype in DTYPES:
        if dtype in timings_ms and timings_ms[dtype] < timings_ms.get(best, float("inf")):
            best = dtype
    return best


def autocast(dtype: str, device: torch.device | str):
    """The context the deformation field runs in: bfloat16 autocast on `device`, or nothing for float32."""
    if dtype == "bfloat16":
        return torch.autocast(torch.device(device).type, dtype=torch.bfloat16)
    return contextlib.nullcontext()


def timing_field(device: torch.device, size: tuple[int, int] = PAPER_SIZE) -> DeformationField:
    """A field of `size` (depth, width) whose heads are not zero (an untrained field's backward would
    skip nothing, but keep it real)."""
    gen = torch.Generator().manual_seed(0)
    f = DeformationField(*size)
    with torch.no_grad():
        for head in (f.warp, f.rotation, f.scaling):
            head.weight.copy_(torch.randn(head.weight.shape, generator=gen) * 0.01)
    return f.to(device)


def time_deformation(device: torch.device, n_points: int = MEASURE_POINTS, repeats: int = MEASURE_REPEATS,
                     stop_ratio: float = STOP_RATIO, clock: Callable[[], float] = time.perf_counter,
                     size: tuple[int, int] = PAPER_SIZE) -> dict[str, float]:
    """Median milliseconds of one forward + backward of a deformation field of `size` (depth, width)
    on n_points points, per dtype (the ratio depends on the size: a small field may be faster in float32).

    Both dtypes run one warm-up pass, then the timed passes alternate between them, so a stall of the
    machine hits both. A dtype whose warm-up took stop_ratio x the other's is reported by that one pass
    (it cannot win: on a core without bf16 this saves ~10 s of a 45x slower product)."""
    f = timing_field(device, size)
    gen = torch.Generator().manual_seed(1)
    x = torch.rand(n_points, 3, generator=gen).to(device)

    def one(dtype: str) -> float:
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        t0 = clock()
        with autocast(dtype, device):
            dx, dq, ds = f(x, 0.5)
        (dx.float().square().sum() + dq.float().square().sum() + ds.float().square().sum()).backward()
        if device.type == "cuda":
            torch.cuda.synchronize(device)
        f.zero_grad(set_to_none=True)
        return (clock() - t0) * 1e3

    warm = {d: one(d) for d in DTYPES}
    timed = {d: [] for d in DTYPES}
    slow = {d for d in DTYPES if warm[d] > stop_ratio * min(warm.values())}
    for _ in range(repeats):
        for d in DTYPES:
            if d not in slow:
                timed[d].append(one(d))
    return {d: round(statistics.median(timed[d]) if timed[d] else warm[d], 3) for d in DTYPES}


def machine_key(device: torch.device, size: tuple[int, int] = PAPER_SIZE) -> str:
    """What a measurement holds for: the processor, torch's version, its thread count (and the
    field's size where it is not the paper's)."""
    if device.type == "cuda":
        proc = torch.cuda.get_device_name(device)
    else:
        proc = f"{cpu_model()} [{' '.join(cpu_features())}]"
    key = f"{proc} | torch {torch.__version__} | {torch.get_num_threads()} threads"
    return key if tuple(size) == PAPER_SIZE else f"{key} | mlp {size[0]}x{size[1]}"


def _read_cache(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict) or data.get("format") != CACHE_FORMAT or not isinstance(data.get("machines"), dict):
        return {}
    return data["machines"]


def _cached_timings(entry) -> dict[str, float] | None:
    if not isinstance(entry, dict) or not isinstance(entry.get("timings_ms"), dict):
        return None
    t = entry["timings_ms"]
    if not all(isinstance(t.get(d), (int, float)) and t[d] > 0 for d in DTYPES):
        return None
    return {d: float(t[d]) for d in DTYPES}


def resolve_precision(requested: str, device: torch.device | str, cache: Path | None = None,
                      timer: Callable[[torch.device], Mapping[str, float]] = time_deformation,
                      field_kind: str = "mlp", size: tuple[int, int] = PAPER_SIZE) -> PrecisionChoice:
    """The dtype a run computes its deformation in: `requested` as it is, or for `auto` the faster one
    on this machine (cached in `cache`, default cache_dir() / precision.json; a cache that cannot be
    read is measured again, one that cannot be written is warned about and skipped), for an MLP of
    `size` (depth, width). A trajectory
    field (a few products per Gaussian) has nothing to gain: `auto` is float32 for it."""
    check_precision(requested)
    device = torch.device(device)
    if requested != "auto":
        return PrecisionChoice(requested, "config")
    if field_kind == "trajectory":
        return PrecisionChoice("float32", "trajectory")
    if device.type == "cuda":
        return PrecisionChoice("float32", "cuda", machine_key(device, size))
    key = machine_key(device, size)
    path = Path(cache) if cache is not None else cache_dir() / CACHE_FILE
    machines = _read_cache(path)
    timings = _cached_timings(machines.get(key))
    if timings is not None:
        return PrecisionChoice(faster_dtype(timings), "cached", key, timings)
    timings = {d: float(v) for d, v in timer(device, size=tuple(size)).items()}
    machines[key] = {"timings_ms": timings, "n_points": MEASURE_POINTS, "measured": time.strftime("%Y-%m-%d %H:%M:%S")}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(path, json.dumps({"format": CACHE_FORMAT, "machines": machines}, indent=1))
    except OSError as exc:
        warnings.warn(f"train.precision auto: could not cache the measurement in {path} ({exc.strerror or exc}); "
                      "it runs again next time (set E4DGS_CACHE_DIR to a writable folder)", stacklevel=2)
    return PrecisionChoice(faster_dtype(timings), "measured", key, timings)
