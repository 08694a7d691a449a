"""Progress of a job that runs somewhere else (a Ray task, its child process, another node), told
to the driver through a small file beside the job's log: the driver shows each running job's
position inside its unit of work (timestamps of a scene being rendered, iterations of a cell) with
an estimate of the time left.

    report(done, total, "ts")          # in the worker's loop; a no-op unless E4DGS_PROGRESS_FILE is set
    describe(read(path))               # on the driver: '812/1501 ts, ~3 min left'

The file is written at most once a second (atomically: a reader never sees half of it); the
variable is inherited by child processes, so a scene rendered by `python -m datagen.generate`
under a Ray task reports like the task itself. Data and output folders are shared by every node
(the harness requires it), so the driver reads the file wherever the job runs.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

ENV = "E4DGS_PROGRESS_FILE"
EVERY_S = 1.0

_state: dict = {"path": None, "unit": None, "total": None, "t0": 0.0, "done0": 0, "last": 0.0}


def report(done: int, total: int, unit: str) -> None:
    """This process's position in its current unit of work (cheap when nobody listens)."""
    path = os.environ.get(ENV)
    if not path:
        return
    now = time.time()
    s = _state
    if (s["path"], s["unit"], s["total"]) != (path, unit, total) or done < s["done0"]:
        s.update(path=path, unit=unit, total=total, t0=now, done0=done, last=0.0)   # a new stage: a new rate
    if now - s["last"] < EVERY_S and done < total:
        return
    s["last"] = now
    info = {"done": int(done), "total": int(total), "unit": unit, "t0": s["t0"], "done0": s["done0"], "t": now}
    tmp = f"{path}.{os.getpid()}.tmp"
    try:
        Path(tmp).write_text(json.dumps(info))
        os.replace(tmp, path)
    except OSError:           # progress is a display: a full disk or a gone folder costs only the display
        try:
            os.unlink(tmp)
        except OSError:
            pass


def read(path: str | os.PathLike) -> dict | None:
    """The last report in `path`, or None (none yet, or unreadable)."""
    try:
        info = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return info if isinstance(info, dict) and {"done", "total", "unit", "t0", "done0", "t"} <= set(info) else None


def seconds_left(info: dict) -> float | None:
    """Seconds to the end of the unit at the rate since the unit started; None before any rate."""
    done, total = info["done"] - info["done0"], info["total"] - info["done"]
    elapsed = info["t"] - info["t0"]
    if done <= 0 or elapsed <= 0:
        return None
    return total * elapsed / done


def describe(info: dict | None) -> str:
    """'812/1501 ts, ~3 min left' ('' for None)."""
    if info is None:
        return ""
    text = f"{info['done']}/{info['total']} {info['unit']}"
    left = seconds_left(info)
    if left is not None and info["done"] < info["total"]:
        text += f", ~{_duration(left)} left"
    return text


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    if seconds < 90 * 60:
        return f"{round(seconds / 60)} min"
    return f"{seconds / 3600:.1f} h"
