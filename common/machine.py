"""What machine a figure came from, and where per-machine measurements are kept.

    cpu_model()        'AMD EPYC' (lscpu's "Model name", from /proc/cpuinfo)
    cpu_features()     the instruction sets that decide a dtype's speed: ['avx2', 'avx512_bf16', 'amx_bf16', ...]
    cache_dir()        $E4DGS_CACHE_DIR, else $XDG_CACHE_HOME/e4dgs, else ~/.cache/e4dgs

The Makefile points E4DGS_CACHE_DIR at .venv/e4dgs-cache, beside numba's compiled kernels.
"""
from __future__ import annotations

import functools
import os
import platform
from pathlib import Path

# flags of /proc/cpuinfo that change which dtype is fast (reported beside every timing)
SPEED_FLAGS = ("avx2", "fma", "avx512f", "avx512_bf16", "avx512_vnni", "amx_bf16", "amx_tile")


@functools.lru_cache(maxsize=None)     # the processor does not change while a process runs
def _cpuinfo(path: str = "/proc/cpuinfo") -> dict[str, str]:
    """The first processor's fields of /proc/cpuinfo ({} where there is none: not Linux)."""
    fields: dict[str, str] = {}
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return fields
    for line in text.splitlines():
        if not line.strip():
            if fields:
                break
            continue
        key, _, value = line.partition(":")
        fields.setdefault(key.strip(), value.strip())
    return fields


def cpu_model(path: str = "/proc/cpuinfo") -> str:
    """The CPU's model name ('AMD EPYC', 'Intel(R) Xeon(R) Platinum 8488C'), or what platform knows."""
    info = _cpuinfo(path)
    return info.get("model name") or info.get("Model") or platform.processor() or platform.machine() or "unknown CPU"


def cpu_features(path: str = "/proc/cpuinfo") -> list[str]:
    """Which of SPEED_FLAGS this CPU has, in SPEED_FLAGS' order."""
    flags = set(_cpuinfo(path).get("flags", "").split())
    return [f for f in SPEED_FLAGS if f in flags]


def cpu_summary() -> str:
    """'AMD EPYC (avx2 fma)': the model and its speed-relevant flags, for tables and logs."""
    return f"{cpu_model()} ({' '.join(cpu_features()) or 'no AVX2'})"


def cache_dir() -> Path:
    """The folder for per-machine measurements (not created here)."""
    if os.environ.get("E4DGS_CACHE_DIR"):
        return Path(os.environ["E4DGS_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "e4dgs"


def available_memory_bytes(path: str = "/proc/meminfo") -> int | None:
    """Memory the kernel says a new process can take without swapping (MemAvailable), or None where
    it does not say (not Linux)."""
    try:
        for line in Path(path).read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None
