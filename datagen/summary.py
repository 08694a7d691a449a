"""The blur table of generated scenes, from their manifests (printed by `e4dgs dataset` and by
`python -m tools.dataset_summary`)."""
from __future__ import annotations

import json
from pathlib import Path

from scene_format.naming import split_variant


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
