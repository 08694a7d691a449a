"""Simulating a frame sequence on disk into an event file, as a library call (what `e4dgs simulate` runs).

    result = simulate_files(files, t_us, Path("events.h5"), SimulatorConfig(), seed=0)
    result.n_events, result.width, result.height

Holds a lock on the output while it runs; resumes a killed run from its last checkpoint (or starts
over, saying why, when the checkpoint's spool cannot be resumed); a failure before the first
checkpoint leaves nothing behind. Raises ValueError (bad frames) or OSError, never SystemExit.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Callable, NamedTuple

from common.checkpoint import JobCheckpoint
from common.config import dump_config
from common.fileio import output_lock
from common import imageio
from simulator.config import SimulatorConfig
from eventio.h5io import simulator_attrs
from simulator.resumable import EventSpool, SpoolResumeError
from simulator.simulator import EventSimulator, FrameError


def job_fingerprint(config_yaml: str, seed: int, files: list[Path], t_us: list[int]) -> str:
    """Identity of a simulate job: config, seed, frame files (name, size, mtime) and timestamps."""
    h = hashlib.sha256()
    h.update(json.dumps([config_yaml, seed, t_us]).encode())
    for f in files:
        st = f.stat()
        h.update(f"{f.name}:{st.st_size}:{st.st_mtime_ns};".encode())
    return h.hexdigest()


class SimulateResult(NamedTuple):
    n_events: int
    width: int
    height: int


def _read(path: Path):
    try:
        return imageio.read_linear_image(path)   # through the module, so tests can interrupt a run here
    except imageio.ImageReadError as exc:
        raise ValueError(str(exc)) from None


def simulate_files(files: list[Path], t_us: list[int], out: Path, config: SimulatorConfig | None = None,
                   seed: int = 0, checkpoint_every: int = 500, progress: bool = True,
                   log: Callable[[str], None] = print) -> SimulateResult:
    """Events of the frames `files` (timestamps `t_us`, microseconds) written to `out`."""
    from tqdm import tqdm

    config = config or SimulatorConfig()
    if len(files) != len(t_us) or len(files) < 2:
        raise ValueError(f"simulate_files: need >= 2 frames with one timestamp each, got {len(files)} and {len(t_us)}")
    if checkpoint_every < 1:
        raise ValueError(f"checkpoint_every: expected an integer >= 1, got {checkpoint_every}")
    first = _read(files[0])
    height, width = first.shape[:2]
    config_yaml = dump_config(config)
    attrs = {**simulator_attrs(config), "seed": seed, "source_frames": str(files[0].parent), "n_frames": len(files)}
    with output_lock(out):
        ckpt = JobCheckpoint(out.with_name(f".{out.name}.ckpt.npz"), job_fingerprint(config_yaml, seed, files, t_us))
        state = ckpt.load()
        try:
            spool = EventSpool(out, width, height, t_offset_us=t_us[0], attrs=attrs,
                               resume_count=None if state is None else int(state["n_events"]))
        except SpoolResumeError as exc:
            log(f"warning: {exc}; starting {out} over from the first frame")
            ckpt.remove()
            state = None
            spool = EventSpool(out, width, height, t_offset_us=t_us[0], attrs=attrs)
        sim = EventSimulator(config, width, height, seed=seed)
        start = 0
        if state is not None:
            sim.load_state_dict(state)
            start = int(state["next_frame"])
            log(f"resuming {out} at frame {start} of {len(files)} ({spool.n_events} events kept)")
        checkpointed, done = state is not None, False
        try:
            for k in tqdm(range(start, len(files)), desc="simulate", unit="frame", initial=start, total=len(files),
                          disable=not progress):
                try:
                    spool.append(sim.push(first if k == 0 else _read(files[k]), t_us[k]))
                except FrameError as exc:
                    raise ValueError(f"{files[k]}: {exc}") from None
                if (k + 1) % checkpoint_every == 0 and k + 1 < len(files):
                    ckpt.save({**sim.state_dict(), "next_frame": k + 1, "n_events": spool.sync()})
                    checkpointed = True
            tail = sim.flush()                  # what the readout still holds (latency, bandwidth)
            spool.append(tail)
            spool.finish(t_end_us=max(int(t_us[-1]), int(tail["t"][-1]) if tail.size else 0))
            ckpt.remove()
            done = True
        finally:
            spool.close()
            if not done and not checkpointed:   # nothing a later run could resume from
                spool.spool_path.unlink(missing_ok=True)
    return SimulateResult(spool.n_events, width, height)
