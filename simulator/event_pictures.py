"""Pictures of events: an event frame (ON and OFF in two colours) and a sliding-window video."""
from __future__ import annotations

import errno
import itertools
import os
import re
from pathlib import Path
from typing import Iterable

import numpy as np

from common.fileio import atomic_output
from eventio.events import EventStream

ON_RGB = np.array([220, 40, 40], np.float64)    # red
OFF_RGB = np.array([40, 80, 220], np.float64)   # blue (mirror of ON, so a tie is neutral)
BACKGROUND_RGB = np.array([255, 255, 255], np.float64)

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


def event_frame(stream: EventStream, saturate_count: int = 3) -> np.ndarray:
    """RGB uint8 [H,W,3]: white background, ON events red, OFF blue, mixed pixels blended.

    Colour strength grows with the event count and saturates at `saturate_count` events.
    """
    H, W = stream.height, stream.width
    ev = stream.events
    idx = ev["y"].astype(np.int64) * W + ev["x"]
    on = np.bincount(idx[ev["p"] > 0], minlength=H * W).reshape(H, W).astype(np.float64)
    off = np.bincount(idx[ev["p"] < 0], minlength=H * W).reshape(H, W).astype(np.float64)
    total = on + off
    strength = np.minimum(total / max(saturate_count, 1), 1.0)[..., None]
    frac_on = np.divide(on, total, out=np.zeros_like(on), where=total > 0)[..., None]
    colour = frac_on * ON_RGB + (1.0 - frac_on) * OFF_RGB
    img = (1.0 - strength) * BACKGROUND_RGB + strength * colour
    return np.round(img).astype(np.uint8)


FLOW_RGB = (0, 140, 0)      # arrows of a drawn flow: dark green, apart from ON red and OFF blue


def overlay_flow(frame: np.ndarray, flow: np.ndarray, valid: np.ndarray, scale: int = 1, step_px: int = 8) -> np.ndarray:
    """The event frame scaled up `scale` times (nearest), with a flow [H, W, 2] (px, at the sensor's
    resolution) drawn as arrows from every step_px-th valid pixel centre to where it goes (non-finite
    flow skipped)."""
    import cv2

    if flow.shape[:2] != frame.shape[:2]:
        raise ValueError(f"the flow is {flow.shape[1]}x{flow.shape[0]} pixels, the events {frame.shape[1]}x{frame.shape[0]}")
    img = np.ascontiguousarray(np.repeat(np.repeat(frame, scale, 0), scale, 1) if scale > 1 else frame)
    h, w = flow.shape[:2]
    for y in range(step_px // 2, h, step_px):
        for x in range(step_px // 2, w, step_px):
            if valid[y, x] and np.isfinite(flow[y, x]).all():
                a = ((x + 0.5) * scale, (y + 0.5) * scale)
                # an arrow leaving the picture is drawn to just past its edge (a huge flow stays drawable)
                b = (np.clip((x + 0.5 + flow[y, x, 0]) * scale, -w * scale, 2 * w * scale),
                     np.clip((y + 0.5 + flow[y, x, 1]) * scale, -h * scale, 2 * h * scale))
                cv2.arrowedLine(img, tuple(int(round(v)) for v in a), tuple(int(round(v)) for v in b), FLOW_RGB, 1,
                                cv2.LINE_AA, tipLength=0.3)
    return img


def annotate(frame: np.ndarray, t0_us: int, t1_us: int, scale: int = 1) -> np.ndarray:
    """The event frame scaled up `scale` times (nearest), over a strip with its time window and the
    colour key (ON red, OFF blue)."""
    import cv2

    img = np.repeat(np.repeat(frame, scale, 0), scale, 1) if scale > 1 else frame
    h, w = img.shape[:2]
    strip = np.full((18, w, 3), 255, np.uint8)
    text = f"{t0_us / 1000:.3f}-{t1_us / 1000:.3f} ms"
    cv2.putText(strip, text, (3, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    for k, (label, rgb) in enumerate((("ON", ON_RGB), ("OFF", OFF_RGB))):
        x = w - 70 + 36 * k
        if x > 0:
            strip[5:13, x:x + 8] = rgb.astype(np.uint8)
            cv2.putText(strip, label, (x + 10, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([img, strip], 0)


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
