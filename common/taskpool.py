"""Independent jobs as Ray tasks: the engine under `e4dgs bench --ray` and `e4dgs dataset --ray`.

Ray is imported only here and only when a caller asks for it, so the serial paths (no `--ray`) never
load it. Each job is a module-level function plus arguments (pickled by reference, so every node must
have this package installed) with stated resources. The driver submits them all, keeps one progress
bar (done / running / failed) and hands each outcome to a callback as it arrives, so a caller can
record results as they come in and nothing finished is lost when a later job fails.

    specs = [TaskSpec("lego", generate_scene, ("quick", "lego", out), num_cpus=2, log_path=out / "logs/lego.log")]
    run_tasks(specs, RayOptions(), on_outcome=print)

Failures: a task that raises, or whose worker process dies, is retried `retries` times (Ray re-runs it,
possibly on another node; our jobs resume from their checkpoints). After that its outcome carries the
error and the others go on. A task whose input is refused (a ValueError: the same on every attempt)
is not retried: it returns a `Refusal`, reported at once in the words the plain path prints. Each attempt's stdout/stderr and traceback are appended to its log file.
"""
from __future__ import annotations

import contextlib
import itertools
import os
import socket
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from common import progress

LOCAL = "local"          # `--ray` without an address: start a Ray instance on this machine


@dataclass(frozen=True)
class RayOptions:
    address: str = LOCAL               # "local": start Ray here; else a cluster address ("auto", "ray://host:10001")
    retries: int = 2                   # re-runs after a failure or a dead worker, then the job is reported failed
    local_cpus: int | None = None      # CPUs of a locally started Ray (default: all of this machine's)
    cpus_per_task: float = 1.0         # CPUs each job asks for (its torch / numba threads)

    def __post_init__(self):
        if self.retries < 0:
            raise ValueError(f"Ray retries must be >= 0, got {self.retries}")
        if self.local_cpus is not None and self.local_cpus < 1:
            raise ValueError(f"local Ray CPUs must be >= 1, got {self.local_cpus}")
        if self.cpus_per_task <= 0:
            raise ValueError(f"CPUs per Ray task must be > 0, got {self.cpus_per_task}")


@dataclass(frozen=True)
class TaskSpec:
    key: str                           # names the job in the bar, the log and the outcome
    fn: Callable[..., Any]             # module-level function run on a worker
    args: tuple = ()
    num_cpus: float = 1.0
    num_gpus: float = 0.0
    log_path: Path | None = None       # each attempt's output is appended here (a path every node sees)


@dataclass(frozen=True)
class TaskOutcome:
    key: str
    value: Any = None
    error: str | None = None           # None: finished; else the last attempt's error, one line
    refused: bool = False              # the error is a refusal of the input (not retried)

    @property
    def ok(self) -> bool:
        return self.error is None


def _import_ray():
    try:
        import ray
    except ImportError:
        raise RuntimeError("--ray needs Ray: pip install 'e4dgs-toolkit[ray]' (or pip install ray)") from None
    return ray


def limit_threads(n: int) -> None:
    """Keep a task to its n CPUs: torch's and numba's thread pools here, and child processes' via
    OMP_NUM_THREADS (child_env gives them NUMBA_NUM_THREADS too). (Ray sets OMP_NUM_THREADS alone;
    numba would still start one thread per core, and two tasks sharing a core each collapse, measured
    2.6x slower on this project's 2-core machine.)

    NUMBA_NUM_THREADS is set in this process only while numba is not imported yet: numba re-reads
    the environment at every compilation and refuses a pool size other than the one it launched
    with, so changing it afterwards made every job on a fresh numba cache fail."""
    os.environ["OMP_NUM_THREADS"] = str(n)
    if "numba" not in sys.modules:
        os.environ["NUMBA_NUM_THREADS"] = str(n)
    import numba
    import torch

    torch.set_num_threads(n)
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))


def die_with_parent() -> None:
    """preexec_fn of a worker process: the kernel kills it when its parent dies, even by SIGKILL
    (Linux prctl PR_SET_PDEATHSIG), so a killed `e4dgs dataset` leaves no orphan rendering on."""
    import ctypes
    import signal

    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)      # PR_SET_PDEATHSIG = 1
    except OSError:                        # not Linux: nothing to arrange
        pass


def child_env() -> dict[str, str]:
    """The environment for a task's child process: numba's pool sized like OMP_NUM_THREADS."""
    env = dict(os.environ)
    if "OMP_NUM_THREADS" in env:
        env["NUMBA_NUM_THREADS"] = env["OMP_NUM_THREADS"]
    return env


@dataclass(frozen=True)
class Refusal:
    """What a task returns instead of raising when its input is refused (a ValueError: bad config,
    dataset or file): the same on every attempt, so Ray does not retry it; the driver reports `line`
    as the task's error, in the words the plain path prints."""
    line: str


def run_logged(fn: Callable[..., Any], args: tuple, key: str, log_path: str | None, tracker=None,
               threads: int | None = None) -> Any:
    """One attempt of a job on a worker: announce it, limit its threads, send its output to the job's
    log, re-raise errors."""
    if tracker is not None:
        try:                  # the progress actor may be gone (killed for memory): that costs the display only
            tracker.started.remote(key)
        except Exception:     # noqa: BLE001
            pass
    if threads is not None:
        limit_threads(threads)
    if log_path is None:
        try:
            return fn(*args)
        except ValueError as exc:
            return Refusal(_one_line(exc))
    Path(log_path).parent.mkdir(parents=True, exist_ok=True)
    before = os.environ.get(progress.ENV)
    os.environ[progress.ENV] = str(progress_path(log_path))     # the job's loops (and its children) report there
    try:
        with open(log_path, "a", buffering=1) as log, contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
            print(f"--- {key}: attempt started {time.strftime('%Y-%m-%d %H:%M:%S')} on {socket.gethostname()} "
                  f"(pid {os.getpid()})")
            try:
                value = fn(*args)
            except ValueError as exc:         # a refusal of the job's input: the same on every attempt
                traceback.print_exc()
                print(f"--- {key}: refused (not retried)")
                return Refusal(_one_line(exc))
            except BaseException:
                traceback.print_exc()
                raise
            print(f"--- {key}: finished {time.strftime('%Y-%m-%d %H:%M:%S')}")
            return value
    finally:
        if before is None:
            os.environ.pop(progress.ENV, None)
        else:
            os.environ[progress.ENV] = before


def progress_path(log_path: str | os.PathLike) -> Path:
    """Where a job with this log reports its progress (common.progress): beside the log."""
    return Path(f"{log_path}.progress")


class _Tracker:
    """Which jobs have started an attempt (a tiny Ray actor; the bar's 'running' count)."""

    def __init__(self):
        self.keys: set[str] = set()

    def started(self, key: str) -> None:
        self.keys.add(key)

    def started_keys(self) -> set[str]:
        return set(self.keys)


def _one_line(exc: BaseException) -> str:
    """The root error of a Ray exception in one line ('ValueError: ...', 'worker died ...')."""
    cause = getattr(exc, "cause", None)
    if isinstance(cause, BaseException):
        return f"{type(cause).__name__}: {str(cause).splitlines()[0] if str(cause) else ''}".rstrip(": ")
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


@contextlib.contextmanager
def ray_session(opts: RayOptions, log_path: str | os.PathLike | None = None):
    """Connect to the cluster at opts.address, or start a local Ray (shut down again on exit). Ray's
    own messages to the driver (a page of text for each memory kill) go to `log_path` (default: a file
    in the temporary folder), one line each to the console."""
    ray = _import_ray()
    if ray.is_initialized():
        yield ray
        return
    kwargs = {"log_to_driver": False, "include_dashboard": False}
    try:
        if opts.address == LOCAL:
            ray.init(num_cpus=opts.local_cpus or os.cpu_count(), **kwargs)
        else:
            ray.init(address=opts.address, **kwargs)
    except Exception as exc:      # noqa: BLE001 - Ray raises many kinds here; each means the same to the user
        raise ConnectionError(f"ray: cannot {'start a local Ray' if opts.address == LOCAL else 'connect to Ray at ' + repr(opts.address)}"
                              f" ({_one_line(exc)})") from None
    restore = _ray_messages_to(Path(log_path) if log_path else Path(tempfile.gettempdir()) / f"e4dgs-ray-{os.getpid()}.log")
    try:
        yield ray
    finally:
        restore()
        ray.shutdown()


def _ray_messages_to(log: Path) -> Callable[[], None]:
    """Send what Ray's driver thread prints of the cluster's errors (ray._private.worker.print_to_stdstream,
    looked up by name on each message) to `log`, with one line on stderr per message; returns the undo."""
    import ray._private.worker as ray_worker

    original = ray_worker.print_to_stdstream

    def to_log(data, ignore_prefix=False):
        text = "\n".join(str(line) for line in (data.get("lines") or []))
        try:
            log.parent.mkdir(parents=True, exist_ok=True)
            with open(log, "a") as fh:
                fh.write(f"--- {time.strftime('%Y-%m-%d %H:%M:%S')} from {data.get('pid', '?')}\n{text}\n")
        except OSError:
            pass
        first = next((ln.strip() for ln in text.splitlines() if ln.strip()), "")
        print(f"ray: {first[:200]} (Ray's full message: {log})", file=sys.stderr, flush=True)

    ray_worker.print_to_stdstream = to_log
    return lambda: setattr(ray_worker, "print_to_stdstream", original)


def cluster_gpus() -> float:
    """GPUs in the connected cluster (call inside ray_session; 0 for a local Ray without one)."""
    return float(_import_ray().cluster_resources().get("GPU", 0.0))


def run_tasks(specs: list[TaskSpec], opts: RayOptions, on_outcome: Callable[[TaskOutcome], None],
              desc: str = "jobs", progress: bool = True) -> list[TaskOutcome]:
    """Run every spec as a Ray task; call on_outcome (on the driver) as each finishes or finally fails."""
    from tqdm import tqdm

    keys = [s.key for s in specs]
    if len(set(keys)) != len(keys):
        raise ValueError("task keys must be unique")
    outcomes: list[TaskOutcome] = []
    if not specs:
        return outcomes
    logs = next((Path(s.log_path).parent for s in specs if s.log_path is not None), None)
    with ray_session(opts, logs / "ray.log" if logs is not None else None) as ray:
        # restarted if killed (by Ray's memory monitor, say): its count starts again, the grid goes on
        global _TRACKER_NAME
        _TRACKER_NAME = f"e4dgs-taskpool-tracker-{os.getpid()}-{next(_RUNS)}"
        tracker = ray.remote(num_cpus=0, max_restarts=-1)(_Tracker).options(name=_TRACKER_NAME).remote()
        remote = ray.remote(run_logged)
        pending = {}
        for s in specs:
            ref = remote.options(num_cpus=s.num_cpus, num_gpus=s.num_gpus, max_retries=opts.retries,
                                 retry_exceptions=True, name=s.key).remote(
                s.fn, s.args, s.key, None if s.log_path is None else str(s.log_path), tracker,
                max(1, int(s.num_cpus)))
            pending[ref] = s
        failed = 0
        for s in specs:                  # a report left by an earlier run is not this one's
            if s.log_path is not None:
                progress_path(s.log_path).unlink(missing_ok=True)
        shown_at, last_status = 0.0, ""
        with tqdm(total=len(specs), desc=desc, unit="job", disable=not progress) as bar:
            while pending:
                ready, _ = ray.wait(list(pending), num_returns=1, timeout=1.0)
                for ref in ready:
                    spec = pending.pop(ref)
                    try:
                        value = ray.get(ref)
                        outcome = (TaskOutcome(spec.key, error=value.line, refused=True) if isinstance(value, Refusal)
                                   else TaskOutcome(spec.key, value=value))
                        failed += isinstance(value, Refusal)
                    except Exception as exc:     # noqa: BLE001 - any failure of one task is that task's outcome
                        outcome = TaskOutcome(spec.key, error=_one_line(exc))
                        failed += 1
                    outcomes.append(outcome)
                    with tqdm.external_write_mode():          # the caller's log lines above the bar
                        on_outcome(outcome)
                    bar.update(1)
                    if spec.log_path is not None:
                        progress_path(spec.log_path).unlink(missing_ok=True)
                running = _running(ray, tracker, pending)
                status = f"done {len(outcomes) - failed}, running {running}, failed {failed}"
                # redraw on a change of the counts, and with the running jobs' positions every few
                # seconds: a log gets a line per change, not one per second of polling
                if progress and (status != last_status or time.time() - shown_at >= PROGRESS_EVERY_S):
                    shown_at, last_status = time.time(), status
                    inside = _inside(pending)
                    text = status + (f" | {inside}" if inside else "")
                    if text != getattr(bar, "postfix", None):
                        bar.set_postfix_str(text)
        try:
            ray.kill(tracker)          # now, not when Ray collects the handle (a later run's actor is another)
        except Exception:      # noqa: BLE001 - already gone (killed for memory and not restarted)
            pass
    return outcomes


_RUNS = itertools.count()
_TRACKER_NAME = ""


def tracker_name() -> str:
    """The name of the progress actor of this process's current (or last) run_tasks call: one per call,
    so a second call never meets the first's actor, which Ray removes asynchronously (a busy machine
    once had the second call refused: the name was still taken)."""
    return _TRACKER_NAME


PROGRESS_EVERY_S = 5.0       # how often the bar shows the running jobs' positions


def _inside(pending: dict) -> str:
    """Each running job's position in its unit of work, from its progress file ('' when none reported)."""
    parts = []
    for s in pending.values():
        if s.log_path is not None:
            text = progress.describe(progress.read(progress_path(s.log_path)))
            if text:
                parts.append(f"{s.key}: {text}")
    return "; ".join(parts)


def _running(ray, tracker, pending: dict) -> str:
    """How many pending tasks have started ('?' while the progress actor is unreachable: it may have
    been killed and be restarting; progress display is all it costs)."""
    try:
        started = ray.get(tracker.started_keys.remote(), timeout=5.0)
    except Exception:      # noqa: BLE001
        return "?"
    return str(sum(s.key in started for s in pending.values()))
