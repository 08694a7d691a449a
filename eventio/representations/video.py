"""Sliding windows over an event stream and the MP4 they are drawn into; times read from text.

    >>> parse_time_us("1.5ms"), parse_time_us("-5ms"), parse_time_us("2s")
    (1500, -5000, 2000000)
    >>> window_starts(0, 10_000, 4_000, 3_000)        # the last window ends at the stream's end
    [0, 3000, 6000]
"""
from __future__ import annotations

import errno
import itertools
import os
import re
from pathlib import Path
from typing import Iterable

import numpy as np

from common.fileio import atomic_output

MAX_TIME_US = 2 ** 62          # microsecond timestamps are int64; keep room for offsets and sums
_TIME_RE = re.compile(r"^\s*([-+]?[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(us|ms|s)?\s*$")


def parse_time_us(text: str) -> int:
    """'1500', '1500us', '1.5ms', '0.0015s' -> 1500; '-5ms' -> -5000 (integer microseconds; event files
    may start before 0)."""
    m = _TIME_RE.match(str(text))
    if not m:
        raise ValueError(f"cannot read time {text!r}: expected a number with optional unit us, ms or s")
    scale = {"us": 1, None: 1, "ms": 1_000, "s": 1_000_000}[m.group(2)]
    value = float(m.group(1)) * scale
    if not abs(value) <= MAX_TIME_US:               # also inf / nan (1e400)
        raise ValueError(f"time {text!r} is out of range: at most {MAX_TIME_US / 1e6:.3g} s either side of 0")
    return int(round(value))


def window_starts(t0_us: int, t1_us: int, window_us: int, step_us: int) -> list[int]:
    """Start times of a sliding window of window_us every step_us over [t0_us, t1_us): full windows, and
    a last one ending at t1_us when the steps stop short of it, so that every event is shown."""
    starts = list(range(t0_us, max(t0_us + 1, t1_us - window_us + 1), step_us))
    if starts[-1] + window_us < t1_us:
        starts.append(t1_us - window_us)
    return starts


def _encode(out: Path, frames: Iterable[np.ndarray], h: int, w: int, fps: float) -> None:
    try:
        import imageio_ffmpeg
    except ImportError:
        imageio_ffmpeg = None
    if imageio_ffmpeg is not None:
        ph, pw = h + h % 2, w + w % 2                 # yuv420p needs even sides: pad with white
        writer = imageio_ffmpeg.write_frames(str(out), (pw, ph), fps=fps, codec="libx264",
                                             pix_fmt_out="yuv420p", macro_block_size=1, quality=8,
                                             ffmpeg_log_level="fatal")
        writer.send(None)
        try:
            for f in frames:
                pad = np.full((ph, pw, 3), 255, np.uint8)
                pad[:h, :w] = f
                writer.send(np.ascontiguousarray(pad))
        finally:
            writer.close()
        save_video.codec = "h264"
        return
    import cv2

    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    if not writer.isOpened():
        raise RuntimeError(f"{out}: OpenCV cannot open an MP4 writer")
    try:
        for f in frames:
            writer.write(np.ascontiguousarray(f[..., ::-1]))
    finally:
        writer.release()
    save_video.codec = "mp4v"


def save_video(path: str | os.PathLike, frames: Iterable[np.ndarray], fps: float = 30.0) -> Path:
    """Write RGB uint8 frames (any iterable: a generator keeps one frame in memory) to an MP4 file
    atomically: H.264 (yuv420p, which browsers play) through the ffmpeg of imageio-ffmpeg, or MPEG-4
    Part 2 (mp4v) through OpenCV when that ffmpeg is missing. `save_video.codec` says which."""
    path = Path(path)
    it = iter(frames)
    first = next(it, None)
    if first is None:
        raise ValueError(f"{path}: no frames to write")
    frames = itertools.chain([first], it)
    h, w = first.shape[:2]
    with atomic_output(path) as tmp:
        # the writers pick the container from the extension, so the temporary name keeps it
        tmp_mp4 = tmp.with_name(tmp.name + path.suffix)
        try:
            _encode(tmp_mp4, frames, h, w, fps)
            os.replace(tmp_mp4, tmp)
        except OSError as exc:       # ffmpeg dies on a full disk and the pipe breaks: say why, naming the file
            st = os.statvfs(tmp.parent)
            if st.f_bavail * st.f_frsize < (1 << 20) or exc.errno == errno.ENOSPC:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path)) from None
            raise OSError(exc.errno or errno.EIO, f"the video encoder stopped ({' '.join(str(exc).split())[:200]})",
                          str(path)) from None
        finally:
            tmp_mp4.unlink(missing_ok=True)
    return path
