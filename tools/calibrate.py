"""The one calibration of the blur levels: the speeds at which D3DGS on blurred frames loses, on one
scene, what the paper's Table 3 says it loses on garage.

    python -m tools.calibrate runs/quick/results.jsonl --scene garage

reads the speed study's D3DGS-on-blurred-frames rows of that scene and the main study's D3DGS on
sharp frames, prints the cost (sharp minus blurred PSNR) at every measured speed, and the speed of
each level, interpolated linearly in log speed between the two measured speeds around its target
cost. A target larger than every measured cost is out of reach: the sweep (bounded by the clip the
shutter must fit in) never costs that much. The declared levels (configs/bench/quick.yaml
`speed_levels`) are these speeds; every other scene and method is then a test, not a fit.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from tools.tool_cli import existing_file, run_tool

# The paper's Table 3 (garage): D3DGS 19.05 / 18.89 / 16.98 dB at mild / medium / strong blur,
# 20.36 dB on sharp frames (Table 1), so these costs in dB.
PAPER_GARAGE_COST_DB = {"mild": 20.36 - 19.05, "medium": 20.36 - 18.89, "strong": 20.36 - 16.98}


def level_speed(costs: list[tuple[float, float]], target_db: float) -> tuple[float | None, str]:
    """(speed, how) at which the cost first reaches target_db, from (speed, cost dB) pairs: linear in
    log speed between the last measured speed below the target and the first at or above it. how:
    'interpolated', 'measured' (a sweep point hits it exactly), or 'out of reach' (speed None)."""
    pts = sorted(costs)
    for (s0, c0), (s1, c1) in zip(pts, pts[1:]):
        if c0 < target_db <= c1:
            if c1 == target_db:
                return s1, "measured"
            f = (target_db - c0) / (c1 - c0)
            return math.exp(math.log(s0) + f * (math.log(s1) - math.log(s0))), "interpolated"
    if pts and pts[0][1] >= target_db:
        return pts[0][0], "measured"
    return None, "out of reach"


def costs_from_rows(rows: list[dict], scene: str, key: str = "psnr") -> tuple[float, list[tuple[float, float, dict]]]:
    """(sharp PSNR, [(speed, cost dB, row)]) of D3DGS on `scene` from results rows."""
    sharp = [r for r in rows if r.get("cell") == "d3dgs_sharp" and r.get("scene") == scene and r.get("status") != "failed"
             and r.get("study") in ("main", "speed")]
    if not sharp:
        raise ValueError(f"no D3DGS (sharp RGB) row for scene {scene!r}: run `e4dgs bench --studies main` first")
    ref = sharp[0][key]
    blurred = {}
    for r in rows:
        if (r.get("cell") == "d3dgs_blur" and r.get("scene") == scene and r.get("speed") is not None
                and not r.get("dataset") and r.get("status") != "failed"):
            blurred[float(r["speed"])] = r
    if not blurred:
        raise ValueError(f"no speed-study rows of D3DGS (blurred RGB) on {scene!r}: run `e4dgs bench --studies speed`")
    return ref, [(s, ref - r[key], r) for s, r in sorted(blurred.items())]


def main(argv=None) -> int:
    import json

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", type=existing_file, help="results.jsonl of a bench run with the speed study")
    ap.add_argument("--scene", default="garage")
    args = ap.parse_args(argv)
    try:
        rows = [json.loads(line) for line in args.results.read_text().splitlines() if line.strip()]
        ref, costs = costs_from_rows(rows, args.scene)
    except UnicodeDecodeError:
        print(f"error: {args.results}: not a text file (expected results.jsonl, one JSON row a line)", file=sys.stderr)
        return 1
    except (OSError, ValueError) as exc:
        message = str(exc)
        print(f"error: {message if str(args.results) in message else f'{args.results}: {message}'}", file=sys.stderr)
        return 1
    print(f"D3DGS on {args.scene}: {ref:.2f} dB on sharp frames\n\n| speed | blur median / p90 px | blurred vs sharp dB "
          f"| D3DGS blurred PSNR | cost dB |\n|---|---|---|---|---|")
    for s, cost, r in costs:
        d = r.get("data") or {}
        px = f"{d['blur_median_px']:.1f} / {d['blur_p90_px']:.1f}" if d.get("blur_median_px") is not None else "–"
        db = f"{d['blur_psnr_db']:.1f}" if d.get("blur_psnr_db") is not None else "–"
        print(f"| x{s:g} | {px} | {db} | {r['psnr']:.2f} | {cost:+.2f} |")
    print("\n| level | paper's cost (Table 3, garage) dB | speed |\n|---|---|---|")
    for level, target in PAPER_GARAGE_COST_DB.items():
        s, how = level_speed([(s, c) for s, c, _ in costs], target)
        where = (f"x{s:.3g} ({how})" if s is not None else
                 f"out of reach: the largest measured cost is {max(c for _, c, _ in costs):.2f} dB "
                 f"(x{max(costs, key=lambda p: p[1])[0]:g})")
        print(f"| {level} | {target:.2f} | {where} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
