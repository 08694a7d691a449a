"""The blur table of generated scenes, from their manifests (printed by `e4dgs dataset` and by
`python -m tools.dataset_summary`), and the moving pixels' share of the events."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from scene_format.naming import split_variant
from scene_format.reader import SceneDataset
from eventio.h5io import read_window


def blur_table(root: Path, scenes: list[str] | None = None) -> str:
    """Per scene and blur level: target, exposure, measured blur (median / p90 px over geometry,
    per-camera medians), blurred-vs-sharp PSNR (median over frames), and the image speed per frame."""
    lines = ["| scene | level | target px | exposure ms (frames) | blur px median / p90 | per-camera median px | "
             "PSNR vs sharp dB | px per frame median / p90 | events/s per camera (M) |", "|" + "---|" * 9]
    rows = []
    for d in sorted(p for p in Path(root).iterdir() if (p / "manifest.json").exists()):
        if scenes is not None and split_variant(d.name)[0] not in scenes:     # a scene's speed variants with it
            continue
        m = json.loads((d / "manifest.json").read_text())
        blur = m.get("blur") or {}
        speed = blur.get("px_per_frame") or {}
        rate = ", ".join(f"{r / 1e6:.1f}" for r in m.get("events_per_second_per_camera", []))
        for name, lv in blur.get("levels", {}).items():
            cams = ", ".join(f"{c['median_px']:.1f}" for c in lv["per_camera"])
            target = f"{lv['target_px']:g}" if lv.get("target_px") is not None else "-"
            speed_x = (m.get("speed") or {}).get("factor", 1.0)
            rows.append(((m["scene"], speed_x), f"| {d.name} | {name} | {target} | {lv['exposure_ms']:.2f} ({lv['n_frames']}) | "
                         f"{lv['median_px']:.1f} / {lv['p90_px']:.1f} | {cams} | {lv['psnr_vs_sharp_db']['median_db']:.1f} | "
                         f"{speed.get('median', float('nan')):.2f} / {speed.get('p90', float('nan')):.2f} | {rate} |"))
    return "\n".join(lines + [line for _, line in sorted(rows, key=lambda r: r[0])])


def event_share(x: np.ndarray, y: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """x, y: int [N] event pixels; mask: bool [H, W] moving pixels.
    Returns (moving share of the pixels, moving share of the events)."""
    n = len(x)
    return float(mask.mean()), (float(mask[y, x].sum()) / n if n else 0.0)


def density_ratio(pixel_share: float, event_share_: float) -> float:
    """Events per moving pixel over events per static pixel (1: the moving parts fire no more than
    the static ones; inf when no static pixel fires)."""
    static_events, static_px = 1.0 - event_share_, 1.0 - pixel_share
    if pixel_share <= 0.0:
        return float("nan")
    if static_events <= 0.0:
        return float("inf")
    return (event_share_ / pixel_share) / (static_events / static_px)


def moving_event_share(scene_dir: Path, half_window_us: int = 1667) -> dict:
    """Over a scene's test views with moving pixels (its dynamic masks): the moving share of the pixels,
    the moving share of the events within +-half_window_us of each view's time (event-weighted over
    the views) and their density ratio. Raises FileNotFoundError when the scene has no masks."""
    ds = SceneDataset(scene_dir)
    px, ev, n = [], [], []
    for rec in ds.frames("test"):
        mask = ds.dynamic_mask(rec)
        if mask is None:
            raise FileNotFoundError(f"{scene_dir}: no dynamic masks (`e4dgs masks` writes them)")
        if not mask.any():
            continue
        e = read_window(ds.event_file(rec.camera), rec.t_us - half_window_us, rec.t_us + half_window_us).events
        p, s = event_share(e["x"].astype(np.int64), e["y"].astype(np.int64), mask)
        px.append(p)
        ev.append(s)
        n.append(len(e))
    w = np.asarray(n, np.float64)
    pixel_share = float(np.mean(px)) if px else 0.0
    events = float(np.dot(ev, w) / w.sum()) if w.sum() > 0 else 0.0
    return {"views": len(px), "pixel_share": pixel_share, "event_share": events,
            "density_ratio": density_ratio(pixel_share, events), "events_per_view": float(w.mean()) if len(w) else 0.0}


def moving_event_table(root: Path) -> str:
    """The moving pixels' share of the events per scene of a dataset folder (scenes without masks left out)."""
    lines = ["| scene | views | moving pixels % | their events % | events per moving / static pixel | events per view (M) |",
             "|" + "---|" * 6]
    for d in sorted(p for p in Path(root).iterdir() if (p / "dynamic" / "masks.json").exists()):
        r = moving_event_share(d)
        lines.append(f"| {d.name} | {r['views']} | {100 * r['pixel_share']:.1f} | {100 * r['event_share']:.1f} | "
                     f"{r['density_ratio']:.2f} | {r['events_per_view'] / 1e6:.2f} |")
    return "\n".join(lines)
