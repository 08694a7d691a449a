"""Summarise the ground truth of generated scenes (prints a table) and draw one view of it:

    python -m tools.ground_truth_summary data/quick_gt [--picture out.png --scene hinge --camera 0 --frame 0]

Per scene: the kinds, the seconds the ground truth took against the scene's other seconds, its bytes
against the folder's, the brightness-constancy check (PSNR of a kept frame against the next one
warped back by the flow, over the valid pixels; unwarped beside it) and the share of events per object.
The picture: the sharp frame, depth, forward flow (colour wheel) and the events around the frame with
the flow drawn as arrows, as the viewer and `e4dgs draw-events --flow` show them.
"""
from __future__ import annotations

import argparse
import sys
import json
from pathlib import Path

import numpy as np

from common.argtypes import nonnegative_int
from tools.tool_cli import existing_folder, run_tool


def _bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def table(root: Path) -> list[str]:
    lines = ["| scene | kinds | GT s | other s | GT MB | scene MB | warp PSNR (unwarped) dB | events per object (cam0) |",
             "|---|---|---|---|---|---|---|---|"]
    for d in sorted(p for p in root.iterdir() if (p / "manifest.json").exists()):
        m = json.loads((d / "manifest.json").read_text())
        gt = m.get("ground_truth")
        if not gt or gt.get("shared_with"):
            continue
        s = m["seconds"]
        other = s.get("total", 0.0) - s.get("ground_truth", 0.0)
        w = gt.get("warp_check", {})
        warp = f"{w['psnr_db_warped']:.2f} ({w['psnr_db_unwarped']:.2f})" if w else "-"
        by = (gt.get("events_by_object") or [{}])[0]
        n = max(sum(by.values()), 1)
        shares = ", ".join(f"{k} {100 * v / n:.0f} %" for k, v in sorted(by.items(), key=lambda kv: -kv[1])[:4])
        lines.append(f"| {d.name} | {', '.join(gt['kinds'])} | {s.get('ground_truth', 0):.0f} | {other:.0f} | "
                     f"{_bytes(d / 'ground_truth') / 1e6:.1f} | {_bytes(d) / 1e6:.1f} | {warp} | {shares} |")
    return lines


def picture(scene: Path, camera: int, frame: int, out: Path) -> Path:
    import cv2

    from common.flow import depth_to_rgb, flow_to_rgb
    from common.imageio import write_png
    from scene_format.reader import SceneDataset
    from eventio.representations import event_frame, overlay_flow
    from viewer.panels import ScenePanels, to_uint8_rgb

    d = SceneDataset(scene)
    if camera >= d.n_cameras:
        raise ValueError(f"--camera {camera}: {scene} has cameras 0 to {d.n_cameras - 1}")
    panels = ScenePanels(d)
    recs = {r.index: r for r in panels.sharp[camera]}
    if frame not in recs or frame + 1 not in recs:
        raise ValueError(f"--frame {frame}: expected a kept frame with a next one (0 to {max(recs) - 1})")
    rec, nxt = recs[frame], recs[frame + 1]
    gt = d.ground_truth(camera, frame)
    events = panels.events(camera).window(rec.t_us, nxt.t_us)
    tiles = [to_uint8_rgb(d.load_image(rec.path)), depth_to_rgb(gt.depth_m), flow_to_rgb(gt.flow_px, gt.flow_valid),
             overlay_flow(event_frame(events), gt.flow_px, gt.flow_valid, scale=1, step_px=12)]
    labels = [f"{scene.name} cam{camera} frame {frame}", "depth (near bright)", f"flow to frame {frame + 1}",
              f"events {rec.t_us / 1000:.2f}-{nxt.t_us / 1000:.2f} ms + flow"]
    h, w = tiles[0].shape[:2]
    row = []
    for t, label in zip(tiles, labels):
        strip = np.full((18, w, 3), 255, np.uint8)
        cv2.putText(strip, label, (3, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
        row.append(np.concatenate([t, strip], 0))
    panels.close()
    return write_png(out, np.concatenate(row, 1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", type=existing_folder, help="a dataset root generated with ground_truth")
    ap.add_argument("--picture", type=Path, default=None, help="also draw one view (PNG)")
    ap.add_argument("--scene", default=None, help="with --picture: the scene folder's name")
    ap.add_argument("--camera", type=nonnegative_int, help="with --picture (default 0)")
    ap.add_argument("--frame", type=nonnegative_int, help="with --picture: a kept frame with a next one (default 0)")
    args = ap.parse_args(argv)
    if args.picture is None:
        given = [f"--{k}" for k in ("scene", "camera", "frame") if getattr(args, k) is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: only with --picture (what to draw)")
    rows = table(args.root)
    if len(rows) == 2:
        raise ValueError(f"{args.root}: no scene folder with ground truth (generate with `ground_truth: [depth, flow, "
                         "normals, ids]` in the preset's overrides)")
    print("\n".join(rows))
    if args.picture is not None:
        names = [p.name for p in sorted(args.root.iterdir()) if (p / "manifest.json").exists()]
        name = args.scene or names[0]
        if name not in names:
            raise ValueError(f"--scene {name}: not a scene folder of {args.root} ({', '.join(names)})")
        camera, frame = args.camera if args.camera is not None else 0, args.frame if args.frame is not None else 0
        print(f"wrote {picture(args.root / name, camera, frame, args.picture)}")
    return 0


if __name__ == "__main__":
    sys.exit(run_tool(main))
