"""What produced a result: the toolkit's version, library versions and the git commit."""
from __future__ import annotations

import functools
import hashlib
import importlib
import platform
import subprocess
from pathlib import Path

from common import __version__

REPO = Path(__file__).resolve().parent.parent


def git_commit() -> str | None:
    """HEAD of the repository this package runs from (None outside a git checkout)."""
    try:
        r = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, timeout=5)
        return r.stdout.strip() or None
    except OSError:
        return None


def versions(*modules: str, **extra: str) -> dict[str, str]:
    """{toolkit, python, numpy, each named module's __version__, **extra}."""
    import numpy as np

    out = {"toolkit": __version__, "python": platform.python_version(), "numpy": np.__version__}
    for name in modules:
        out[name] = importlib.import_module(name).__version__
    return {**out, **extra}


# The packages whose code computes a benchmark row's numbers (training, rendering, scoring, reading
# the scene); a change to any of their sources makes every row another code version. Presentation
# (tables, plots), the command line, the presets and the grid's bookkeeping (benchmark/config.py, grid.py: what they compose is
# the resolved config, its own part of the identity) and the dataset generator are left out: the
# generator's output is covered by the dataset's own digest (scene_format.manifest.content_digest).
CODE_PACKAGES = ("common", "e2vid", "recon", "scene_format")
CODE_MODULES = ("benchmark/job_run.py", "benchmark/testviews.py")


def _source_files(root: Path) -> list[Path]:
    files = [p for pkg in CODE_PACKAGES for p in (root / pkg).rglob("*.py")]
    return sorted(files + [root / m for m in CODE_MODULES if (root / m).exists()])


@functools.lru_cache(maxsize=None)
def code_version(root: Path = REPO) -> str:
    """SHA-256 (16 hex digits) of the sources in CODE_PACKAGES / CODE_MODULES under `root`, by path
    and content: changes with any edit to them, committed or not, and is the same for a git checkout
    and an installed copy of the same code (which has no commit)."""
    h = hashlib.sha256()
    for path in _source_files(Path(root)):
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]

