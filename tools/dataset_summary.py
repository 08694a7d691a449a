"""Summarise a generated dataset (prints tables): time per scene, events per camera, size on disk, and
per blur level the chosen exposure, the measured blur length and the blurred-vs-sharp PSNR; with
--moving-events, per scene with dynamic masks the moving pixels' share of the events (within one
frame interval, +-1.67 ms, of each test view) and how much denser they fire than the static pixels.

    python -m tools.dataset_summary data/quick [--moving-events]
"""
from __future__ import annotations

import argparse
import json

from datagen.summary import blur_table, moving_event_table
from tools.tool_cli import existing_folder, run_tool


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("root", type=existing_folder)
    ap.add_argument("--moving-events", action="store_true", help="the moving pixels' share of the events per scene")
    args = ap.parse_args(argv)
    scenes = sorted(p for p in args.root.iterdir() if (p / "manifest.json").exists())
    if not scenes:
        raise SystemExit(f"dataset_summary: error: {args.root}: no finished scene folder (none holds a manifest.json); "
                         "expected a dataset root such as data/quick")
    print(f"dataset {args.root}")
    print("| scene | timestamps | render s | simulate s | write s | total s | events per camera (M) | size MB | preview |")
    print("|---|---|---|---|---|---|---|---|---|")
    total_s = total_mb = 0.0
    for d in scenes:
        m = json.loads((d / "manifest.json").read_text())
        mb = sum(p.stat().st_size for p in d.rglob("*") if p.is_file()) / 1e6
        s = m["seconds"]
        ev = ", ".join(f"{n / 1e6:.2f}" for n in m["counts"]["events_per_camera"])
        print(f"| {m['scene']} | {m['counts']['timestamps']} | {s['render']:.0f} | {s['simulate']:.1f} | {s['write']:.1f} | "
              f"{s['total']:.0f} | {ev} | {mb:.0f} | {d / 'preview' / 'contact_sheet.png'} |")
        total_s += s["total"]
        total_mb += mb
    print(f"\ntotal: {total_s / 60:.1f} min of generation, {total_mb / 1e3:.2f} GB on disk")
    print("\n" + blur_table(args.root))
    if args.moving_events:
        print("\n" + moving_event_table(args.root))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
