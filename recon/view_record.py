"""The scored views of an evaluation, kept so that its scores can be audited: every prediction as it
was scored (after the method's correction) as a 16-bit PNG, and `views.json` with each view's scores
and the SHA-256 of its PNG. The scores are computed from the 16-bit images themselves (the float
render rounded to 1/65535), so recomputing them from the files gives the same numbers bit for bit.

    <folder>/views.json            {"format", "scene", "split", "lpips_net", "channels", "views": [...], "means"}
    <folder>/cam<k>/<index>.png    the scored prediction of view cam<k>/<index> (gray or RGB, 16-bit)

A row of the benchmark holds the SHA-256 of views.json (`views_sha256`), so a row, its per-view
values and its images are tied together: `e4dgs verify` recomputes them (benchmark.verify).
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from common.fileio import atomic_output, write_text_atomic

VIEWS_FILE = "views.json"
FORMAT = 1
LEVELS = 65535


def quantized(image: np.ndarray) -> np.ndarray:
    """float [H, W, C] -> the same in steps of 1/65535 (clipped to [0, 1]): what a 16-bit PNG holds."""
    return (np.round(np.clip(np.asarray(image, np.float64), 0.0, 1.0) * LEVELS) / LEVELS).astype(np.float32)


def encode_png16(image: np.ndarray) -> bytes:
    """float [H, W, 1 | 3] in [0, 1] (already quantized) -> 16-bit PNG bytes (gray or RGB)."""
    import cv2

    u16 = np.round(np.clip(image, 0.0, 1.0) * LEVELS).astype(np.uint16)
    u16 = u16[..., 0] if u16.shape[-1] == 1 else u16[..., ::-1]
    ok, buf = cv2.imencode(".png", u16)
    if not ok:
        raise ValueError("16-bit PNG encoding failed")
    return buf.tobytes()


def decode_png16(data: bytes, where: str) -> np.ndarray:
    """16-bit PNG bytes -> float32 [H, W, 1 | 3] in [0, 1]; ValueError naming `where` if it is not one."""
    import cv2

    raw = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16:
        raise ValueError(f"{where}: not a 16-bit PNG")
    img = raw.astype(np.float32) / LEVELS
    return img[..., None] if img.ndim == 2 else np.ascontiguousarray(img[..., ::-1])


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def write_views(folder: Path, stems: list[str], preds: list[np.ndarray], views: list[dict], means: dict,
                meta: dict) -> str:
    """Write the scored predictions and views.json into `folder`; returns views.json's SHA-256.
    `preds` are the quantized predictions, `views` their view_scores, `meta` the evaluation's facts
    (scene, split, lpips_net, ...)."""
    folder = Path(folder)
    entries = []
    for stem, pred, scores in zip(stems, preds, views):
        data = encode_png16(pred)
        path = folder / f"{stem}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path) as tmp:
            tmp.write_bytes(data)
        entries.append({"view": stem, "render": f"{stem}.png", "render_sha256": sha256(data), **scores})
    text = json.dumps({"format": FORMAT, **meta, "channels": int(preds[0].shape[-1]), "views": entries,
                       "means": means}, indent=1, sort_keys=True)
    write_text_atomic(folder / VIEWS_FILE, text)
    return sha256(text.encode())


def read_views(folder: Path) -> tuple[dict, str]:
    """(views.json of `folder`, its SHA-256); ValueError naming the file when it is missing or not one."""
    path = Path(folder) / VIEWS_FILE
    try:
        raw = path.read_bytes()
        doc = json.loads(raw)
    except FileNotFoundError:
        raise ValueError(f"{path}: missing (the run's scored views)") from None
    except ValueError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("views"), list):
        raise ValueError(f"{path}: not a views file of format {FORMAT}")
    return doc, sha256(raw)
