"""Output files that appear only when complete (write to a temporary name, then rename), locks that
keep two runs from writing one output, and the removal of temporaries a killed run left behind."""
from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import os
import re
import shutil
from pathlib import Path
from typing import Iterator


def temp_path_for(path: str | os.PathLike) -> Path:
    """Temporary sibling of `path` (same folder, so the final rename is atomic)."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _remove(p: Path) -> None:
    """A file or a whole folder (an output written as a folder, e.g. a ROS2 bag)."""
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        p.unlink(missing_ok=True)


def remove_stale_temps(path: str | os.PathLike) -> list[Path]:
    """Delete temporaries of `path` (`.<name>.<pid>.tmp`) whose writing process no longer runs (a
    run killed while writing); returns what was removed."""
    path = Path(path)
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.(\d+)\.tmp$")
    removed = []
    if not path.parent.is_dir():
        return removed
    for p in path.parent.iterdir():
        m = pattern.match(p.name)
        if m and int(m.group(1)) != os.getpid() and not _pid_alive(int(m.group(1))):
            _remove(p)
            removed.append(p)
    return removed


class OutputLockedError(OSError):
    """Another process holds the lock of this output."""


@contextlib.contextmanager
def output_lock(path: str | os.PathLike) -> Iterator[Path]:
    """Hold an exclusive lock on output `path` (a `.<name>.lock` file beside it) for the `with` block.
    A second process asking for it gets OutputLockedError at once, naming the holder's pid. The lock
    dies with its process, so a killed run never leaves the output locked; the file is removed on exit."""
    path = Path(path)
    created = [d for d in [path.parent, *path.parent.parents] if not d.exists()]   # removed again if left empty
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = path.with_name(f".{path.name}.lock")
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise
            raise OutputLockedError(f"{path}: another run (pid {holder}) is writing this output; wait for it to "
                                    "finish or choose another output") from None
        try:   # the holder before us may have removed the file after we opened it: lock the one on disk
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
        yield lock
    finally:
        lock.unlink(missing_ok=True)
        os.close(fd)
        for d in created:
            with contextlib.suppress(OSError):
                d.rmdir()


def disk_nearly_full(folder: Path, min_free: int = 1 << 20) -> bool:
    """Whether the file system of `folder` has less than `min_free` bytes left."""
    try:
        st = os.statvfs(folder)
    except OSError:
        return False
    return st.f_bavail * st.f_frsize < min_free


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path to write (a file, or a folder the block creates); on success rename it to
    `path`, on failure delete it.

    Nothing appears at `path` unless the `with` block finished without an exception; temporaries
    of `path` left by killed runs are removed first. A folder output needs `path` not to exist.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temps(path)
    tmp = temp_path_for(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        if exc.filename is None and exc.strerror:      # a write's error (a full disk) names no file: name ours
            raise OSError(exc.errno, exc.strerror, str(path)) from exc
        raise
    except Exception as exc:
        # a library's own words for a failed write ("[enforce fail at inline_container.cc] unexpected pos"
        # from torch.save on a full disk): said plainly when the disk is in fact full
        if disk_nearly_full(path.parent):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path)) from exc
        raise
    finally:
        if tmp.exists() or tmp.is_symlink():
            _remove(tmp)


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    with atomic_output(path) as tmp:
        tmp.write_text(text)


def sha256_file(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


_DIGESTS: dict[tuple, str] = {}
DIGEST_CACHE_FILE = "file-sha256.json"


def sha256_files_cached(paths: list[str | os.PathLike], cache: Path | None = None) -> list[str]:
    """sha256_file of each file as it is on disk now, remembered by (absolute path, size, mtime, inode):
    a file rewritten, replaced or copied over gets another key and is read again. The digests are kept
    in memory and in `cache` (a JSON file; default common.machine.cache_dir() / file-sha256.json, read
    and written once per call), so a scene folder is read once per machine, not once per benchmark; a
    cache that cannot be read or written is skipped. OSError for a file that is not there."""
    import json

    from common.machine import cache_dir

    keys = []
    for path in paths:
        p = Path(path).resolve()
        st = p.stat()
        keys.append((str(p), st.st_size, st.st_mtime_ns, st.st_ino))
    todo = [k for k in keys if k not in _DIGESTS]
    if todo:
        cache = Path(cache) if cache is not None else cache_dir() / DIGEST_CACHE_FILE
        try:
            stored = json.loads(cache.read_text())
            stored = stored if isinstance(stored, dict) else {}
        except (OSError, ValueError):
            stored = {}
        fresh = 0
        for key in todo:
            name = "|".join(map(str, key))
            digest = stored.get(name)
            if not (isinstance(digest, str) and re.fullmatch(r"[0-9a-f]{64}", digest)):
                digest = stored[name] = sha256_file(key[0])
                fresh += 1
            _DIGESTS[key] = digest
        if fresh:
            try:
                cache.parent.mkdir(parents=True, exist_ok=True)
                write_text_atomic(cache, json.dumps(stored))
            except OSError:
                pass
    return [_DIGESTS[k] for k in keys]


def link_tree(src: str | os.PathLike, dst: str | os.PathLike, pattern: str = "*") -> None:
    """Every file under src (matching `pattern`) at the same place under dst: a hard link, or a copy
    where the file system refuses links (another device). An existing file at dst is replaced."""
    import shutil

    src, dst = Path(src), Path(dst)
    for f in sorted(p for p in src.rglob(pattern) if p.is_file()):
        target = dst / f.relative_to(src)
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.exists():
            target.unlink()
        try:
            os.link(f, target)
        except OSError:
            shutil.copy2(f, target)


def output_inside_input(output: str | os.PathLike, inputs: dict[str, str | os.PathLike]) -> str | None:
    """A message when `output` is, or lies inside, one of `inputs` ({what: path}), else None: writing
    there would change an input (a run inside its dataset, which `e4dgs check` would not notice)."""
    out = Path(output).resolve()
    for what, path in inputs.items():
        src = Path(path).resolve()
        if out == src or src in out.parents:
            return f"{output}: inside {what} {path}; an output must not be written into its input, choose another folder"
    return None


def _same_or_inside(a: Path, b: Path) -> tuple[bool, bool]:
    """(a is b, a lies inside folder b), comparing resolved paths (links and '..' followed)."""
    ra, rb = a.resolve(), b.resolve()
    same = ra == rb or (a.exists() and b.exists() and os.path.samefile(a, b))
    return same, rb in ra.parents


def output_overlap(outputs: list[tuple[str, Path]], inputs: list[tuple[str, Path]],
                   protected: frozenset[str] = frozenset()) -> str | None:
    """Why an output would land on an input, or None: an output that is an input (a file, or the folder
    an input lies in when the output is a folder), or one inside an input folder named in `protected`
    (datasets and frame folders a command must leave as they are). Names are the command's options."""
    for oname, out in outputs:
        for iname, inp in inputs:
            same, inside = _same_or_inside(out, inp)
            if same:
                return f"{oname} {out}: is also {iname} {inp}, an input; choose another output name"
            if inside and inp.is_dir() and iname in protected:
                return f"{oname} {out}: lies inside {iname} {inp}, an input folder this command only reads; write elsewhere"
            if _same_or_inside(inp, out)[1] and out.exists() and out.is_file():
                return f"{oname} {out}: is a file, and {iname} {inp} would be inside it"
    return None


FREE_SPACE_MARGIN = 1 << 20     # bytes kept free beyond a native writer's estimate (its own metadata)


def require_free_space(path: str | os.PathLike, n_bytes: int) -> None:
    """OSError ENOSPC naming `path` when its file system has less than `n_bytes` (+ a margin) free:
    asked before writers that cannot fail cleanly on a full disk (HDF5 can crash the process,
    dv-processing aborts it), with an upper bound of what they will write."""
    path = Path(path)
    folder = next((d for d in [path.parent, *path.parent.parents] if d.exists()), Path("/"))
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    if free < n_bytes + FREE_SPACE_MARGIN:
        raise OSError(errno.ENOSPC, f"No space left on device (needs up to {(n_bytes + FREE_SPACE_MARGIN) / 1e6:.1f} MB, "
                                    f"{free / 1e6:.1f} MB free)", str(path))


def as_disk_error(exc: BaseException, path: str | os.PathLike) -> OSError | None:
    """A library's error that is a full disk or a write failure in disguise (h5py's 'Driver write
    request failed ... errno = 28', sqlite's 'database or disk is full'), as an OSError naming `path`;
    None for anything else."""
    text = str(exc)
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC or "errno = 28" in text or "disk is full" in text \
            or "No space left" in text:
        return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
    return None
