"""Job checkpoints: one atomic .npz of arrays and scalars, tied to a fingerprint of the job's inputs."""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from common.fileio import atomic_output

_FINGERPRINT = "checkpoint__fingerprint"


class JobCheckpoint:
    """`save(state)` replaces the checkpoint atomically; `load()` returns the saved state if it was
    made by a job with the same fingerprint, else None (and drops the stale file)."""

    def __init__(self, path: str | os.PathLike, fingerprint: str):
        self.path = Path(path)
        self.fingerprint = str(fingerprint)

    def load(self) -> dict[str, Any] | None:
        if not self.path.exists():
            return None
        try:
            with np.load(self.path, allow_pickle=False) as z:
                if _FINGERPRINT in z.files and str(z[_FINGERPRINT]) == self.fingerprint:
                    return {k: z[k] for k in z.files if k != _FINGERPRINT}
        except (OSError, ValueError):
            pass  # unreadable: start over
        self.remove()
        return None

    def save(self, state: Mapping[str, Any]) -> None:
        if _FINGERPRINT in state:
            raise ValueError(f"checkpoint state may not use the key {_FINGERPRINT}")
        arrays = {k: np.asarray(v) for k, v in state.items()}
        arrays[_FINGERPRINT] = np.asarray(self.fingerprint)
        with atomic_output(self.path) as tmp:
            with open(tmp, "wb") as fh:
                np.savez(fh, **arrays)

    def remove(self) -> None:
        self.path.unlink(missing_ok=True)


def torch_load(path: str | os.PathLike, what: str):
    """`torch.load(path, weights_only=True)` on the CPU; a file torch cannot read is a ValueError of one
    line naming the file, `what` it should have been, and the clause of torch's message that says
    what failed (torch wraps it in a page of advice about weights_only)."""
    import re

    import torch

    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises several types for foreign or damaged files
        m = re.search(r"Unpickler error:\s*([^\n]+)", str(exc))
        why = m.group(1).strip() if m else (str(exc).strip().split(".")[0] or type(exc).__name__)
        raise ValueError(f"{path}: cannot read it as {what} ({why[:120]})") from None
