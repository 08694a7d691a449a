"""What adaptive temporal sampling (render.adaptive_px) saves and costs against rendering every frame
(prints a table).

Generates each scene of a dataset preset once rendering every frame of its time line and once per
bound (px of image motion between rendered frames), into a temporary folder, and compares each
adaptive scene with the fixed-rate one: frames rendered and render seconds; the events (count error,
and each event's time to the nearest fixed-rate event of the same pixel and polarity, as
tools.bench_render_rate does); the sharp frames (identical: the kept frames are always rendered);
the blurred frames (PSNR of the adaptive blurred frames against the fixed-rate ones, every level).
Speed variants are left out (they take the scene's rendered frames).

    python -m tools.bench_adaptive --preset quick --scenes hinge lego garage --bounds 0.5 1 2 [--cameras 2]
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
import yaml

from common.machine import cpu_summary
from common.imageio import read_png_linear
from tools.bench_render_rate import nearest_time_errors
from datagen.build import generate_dataset
from datagen.config import PRESETS_DIR
from eventio.h5io import read_events
from tools.tool_cli import output_file, positive_float, positive_int, run_tool

RETRIES = 2           # restarts of a generator that died from a signal


def generate(preset: Path, scene: str, extra: dict, out: Path) -> dict:
    """The manifest of `scene` generated with the preset's overrides plus `extra`."""
    data = yaml.safe_load(preset.read_text())
    data["scenes"] = [scene]
    over = data.setdefault("overrides", {})
    for key, value in extra.items():
        over[key] = {**over.get(key, {}), **value} if isinstance(value, dict) else value
    data["scene_overrides"] = {k: v for k, v in (data.get("scene_overrides") or {}).items() if k == scene}
    for s in data["scene_overrides"].values():
        s.pop("speeds", None)
    p = out.with_suffix(".yaml")
    p.write_text(yaml.safe_dump(data))
    # a generator killed by a signal (Blender's renderer sometimes corrupts its heap on long clips)
    # is started again and resumes from its checkpoint, as `e4dgs dataset --retries` does
    if generate_dataset(p, [scene], out, retries=RETRIES, log=lambda msg: print(msg, flush=True)):
        raise SystemExit(f"{scene}: generation failed (the generator's messages are above)")
    return json.loads((out / scene / "manifest.json").read_text())


def compare(fixed: Path, adaptive: Path, n_cameras: int, width: int) -> dict:
    """Event count error, nearest-event time errors (us) and blurred-frame PSNR of `adaptive` against `fixed`."""
    n = n_ref = 0
    errs = []
    for k in range(n_cameras):
        a, f = read_events(adaptive / "events" / f"cam{k}.h5"), read_events(fixed / "events" / f"cam{k}.h5")
        n, n_ref = n + len(a), n_ref + len(f)
        errs.append(nearest_time_errors(a.events, f.events, width))
    errs = np.concatenate(errs)
    found = errs[np.isfinite(errs)]
    psnr = {}
    for level_dir in sorted((fixed / "blur").glob("*")):
        vals = []
        for png in sorted(level_dir.rglob("*.png")):
            x, y = read_png_linear(png), read_png_linear(adaptive / png.relative_to(fixed))
            mse = float(np.mean((x - y) ** 2))
            vals.append(99.0 if mse == 0 else 10 * np.log10(1.0 / mse))
        psnr[level_dir.name] = float(np.median(vals)) if vals else float("nan")
    sharp_same = all((adaptive / p.relative_to(fixed)).read_bytes() == p.read_bytes()
                     for p in sorted((fixed / "frames").rglob("*.exr")))
    return {"events": n, "count_error": (n - n_ref) / max(n_ref, 1), "median_us": float(np.median(found)) if len(found) else 0.0,
            "p90_us": float(np.percentile(found, 90)) if len(found) else 0.0,
            "unmatched": (len(errs) - len(found)) / max(len(errs), 1), "blur_psnr_db": psnr, "sharp_identical": sharp_same}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="quick")
    ap.add_argument("--scenes", nargs="+", default=["hinge", "lego", "garage"])
    ap.add_argument("--bounds", type=positive_float, nargs="+", default=[0.5, 1.0, 2.0], help="render.adaptive_px values")
    ap.add_argument("--max-stride", type=positive_int, default=8)
    ap.add_argument("--cameras", type=positive_int, default=None, help="cameras per scene (default: the preset's)")
    ap.add_argument("--out", type=Path, default=None, help="keep the generated scenes here (default: a temporary folder)")
    ap.add_argument("--json", type=output_file, default=None, help="also write the rows as JSON")
    args = ap.parse_args(argv)
    preset = Path(args.preset) if args.preset.endswith((".yaml", ".yml")) else PRESETS_DIR / f"dataset_{args.preset}.yaml"
    if not preset.is_file():
        raise SystemExit(f"error: --preset: no dataset preset {args.preset!r} ({preset} does not exist)")
    base = {"camera": {"n_cameras": args.cameras}} if args.cameras else {}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        root = args.out or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        for scene in args.scenes:
            ref = generate(preset, scene, base, root / f"{scene}_fixed")
            C = ref["counts"]["cameras"]
            width = json.loads((root / f"{scene}_fixed" / scene / "cameras.json").read_text())["intrinsics"]["width"]
            rows.append({"scene": scene, "bound_px": 0.0, "rendered": ref["counts"]["timestamps"],
                         "timestamps": ref["counts"]["timestamps"], "render_s": ref["seconds"]["render"],
                         "events": sum(ref["counts"]["events_per_camera"])})
            print(f"{scene}: every frame: {rows[-1]['rendered']} frames, render {rows[-1]['render_s']:.1f} s", flush=True)
            for b in args.bounds:
                extra = {**base, "render": {"adaptive_px": b, "max_stride": args.max_stride}}
                m = generate(preset, scene, extra, root / f"{scene}_b{b:g}")
                cmp = compare(root / f"{scene}_fixed" / scene, root / f"{scene}_b{b:g}" / scene, C, width)
                rows.append({"scene": scene, "bound_px": b, "rendered": m["render_plan"]["rendered_frames"],
                             "timestamps": m["counts"]["timestamps"], "render_s": m["seconds"]["render"],
                             "px_between": m["render_plan"]["px_between_rendered_frames"], **cmp})
                print(f"{scene}: bound {b:g} px: {rows[-1]['rendered']} frames, render {rows[-1]['render_s']:.1f} s", flush=True)
    cpu = cpu_summary()
    print(f"\nadaptive temporal sampling against every frame, preset {args.preset}, CPU {cpu}")
    print("| scene | bound px | frames rendered | render s | events | count error | time to nearest fixed-rate event, "
          "median / p90 (us) | no counterpart | blurred frames PSNR vs fixed (dB) | sharp frames |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if not r["bound_px"]:
            print(f"| {r['scene']} | every frame | {r['rendered']} | {r['render_s']:.1f} | {r['events']:,} | | | | | |")
            continue
        blur = ", ".join(f"{k} {v:.1f}" for k, v in r["blur_psnr_db"].items())
        print(f"| {r['scene']} | {r['bound_px']:g} | {r['rendered']} / {r['timestamps']} | {r['render_s']:.1f} | "
              f"{r['events']:,} | {100 * r['count_error']:+.2f} % | {r['median_us']:.1f} / {r['p90_us']:.1f} | "
              f"{100 * r['unmatched']:.2f} % | {blur} | {'identical' if r['sharp_identical'] else 'DIFFER'} |")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"cpu": cpu, "preset": args.preset, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
