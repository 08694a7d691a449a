"""What produced a result: the toolkit's version, library versions and the git commit."""
from __future__ import annotations

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
