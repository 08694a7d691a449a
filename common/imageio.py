"""Image files: linear OpenEXR (read/write) and 8/16-bit PNG (sRGB, linearised on read).

Single-channel EXRs are written as channel `V` (as Blender writes them); RGB as `R`, `G`, `B`.
Readers return float32 arrays: [H, W] for one channel, [H, W, 3] for RGB (an opaque alpha dropped,
a transparent one refused).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from common.fileio import atomic_output

_SINGLE_CHANNEL_NAMES = ("V", "Y", "L")          # luminance; Blender writes single-channel EXRs as V
_NOT_INTENSITY = ("A", "Z", "DEPTH", "ALPHA")


class ImageReadError(ValueError):
    """An image file cannot be read as the linear frame it should be."""


def read_exr(path: str | os.PathLike) -> np.ndarray:
    import OpenEXR

    path = Path(path)
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            channels = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    except Exception as exc:  # OpenEXR raises plain RuntimeError/Exception types
        raise ImageReadError(f"{path}: cannot read OpenEXR file ({exc})") from None
    upper = {name.split(".")[-1].upper(): arr for name, arr in channels.items()}
    image = None
    if all(c in upper for c in "RGB"):
        image = np.stack([upper[c] for c in "RGB"], axis=-1).astype(np.float32)
    else:
        name = next((n for n in _SINGLE_CHANNEL_NAMES if n in upper), None)
        if name is not None:
            image = upper[name].astype(np.float32)
        elif len(channels) == 1 and next(iter(upper)) not in _NOT_INTENSITY:
            image = next(iter(channels.values())).astype(np.float32)
    alpha = upper.get("A")
    if image is not None and alpha is not None and not np.all(alpha >= 1.0):     # NaN alpha is refused too
        raise ImageReadError(f"{path}: has transparent pixels (alpha down to {float(np.nanmin(alpha)):.3g}); expected "
                             "opaque frames (an RGBA render, premultiplied or not, is not the frame a camera saw: "
                             "composite it over its background first)")
    if image is not None:
        return image
    raise ImageReadError(f"{path}: expected intensity: channels R,G,B or one luminance channel (V, Y or L), found "
                         f"{', '.join(sorted(channels))}" + (" (alpha and depth are not intensity)"
                                                            if set(upper) & set(_NOT_INTENSITY) else ""))


def write_exr(path: str | os.PathLike, image: np.ndarray, half: bool = False) -> Path:
    """Write float image [H,W] (channel V) or [H,W,3] (R,G,B) atomically; ZIP-compressed."""
    import OpenEXR

    image = np.asarray(image, dtype=np.float16 if half else np.float32)
    if image.ndim == 2:
        channels = {"V": np.ascontiguousarray(image)}
    elif image.ndim == 3 and image.shape[2] == 3:
        channels = {c: np.ascontiguousarray(image[..., i]) for i, c in enumerate("RGB")}
    else:
        raise ValueError(f"write_exr: expected [H,W] or [H,W,3], got shape {image.shape}")
    header = {"type": OpenEXR.scanlineimage, "compression": OpenEXR.ZIP_COMPRESSION}
    path = Path(path)
    with atomic_output(path) as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
    return path


def read_png_linear(path: str | os.PathLike) -> np.ndarray:
    """8- or 16-bit PNG (or other cv2-readable integer image), treated as sRGB and linearised."""
    import cv2

    from common.color import srgb_to_linear

    path = Path(path)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageReadError(f"{path}: cannot read image")
    if img.dtype == np.uint8:
        v = img.astype(np.float64) / 255.0
    elif img.dtype == np.uint16:
        v = img.astype(np.float64) / 65535.0
    else:
        raise ImageReadError(f"{path}: expected an 8- or 16-bit image, got {img.dtype}")
    if v.ndim == 3 and v.shape[2] in (2, 4):             # gray + alpha, BGRA: only opaque frames are frames
        alpha = v[..., -1]
        if alpha.min() < 1.0:
            raise ImageReadError(f"{path}: has transparent pixels (alpha down to {alpha.min():.3g}); expected opaque "
                                 "frames (flatten them onto a background first)")
    if v.ndim == 3:
        v = v[..., 2::-1] if v.shape[2] >= 3 else v[..., 0]  # BGR(A) -> RGB
    return srgb_to_linear(v).astype(np.float32)


def write_png(path: str | os.PathLike, image: np.ndarray) -> Path:
    """uint8 [H,W] or RGB [H,W,3] -> PNG, atomically."""
    import cv2

    path = Path(path)
    with atomic_output(path) as tmp:
        ok, buf = cv2.imencode(".png", image[..., ::-1] if image.ndim == 3 else image)
        if not ok:
            raise ValueError(f"{path}: PNG encoding failed")
        tmp.write_bytes(buf.tobytes())
    return path


def write_png_srgb(path: str | os.PathLike, linear: np.ndarray) -> Path:
    """Linear [H,W] or [H,W,3] image -> 8-bit sRGB PNG (atomic)."""
    from common.color import linear_to_srgb

    return write_png(path, np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8))


def read_linear_image(path: str | os.PathLike) -> np.ndarray:
    """Linear float32 image from EXR (as stored) or PNG/JPG/TIF (sRGB, linearised)."""
    path = Path(path)
    if path.suffix.lower() == ".exr":
        return read_exr(path)
    return read_png_linear(path)
