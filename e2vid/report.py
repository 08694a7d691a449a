"""The short Markdown report written next to exported weights (`e4dgs train-e2vid --export`)."""
from __future__ import annotations

import numpy as np


def loss_curve_rows(log: list[dict], n_rows: int = 8) -> list[dict]:
    """Means of the logged terms over n_rows equal slices of training."""
    if not log:
        return []
    edges = np.linspace(0, len(log), min(n_rows, len(log)) + 1).astype(int)
    rows = []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = log[a:b]
        corr = [r["monitor_corr"] for r in seg if "monitor_corr" in r]
        rows.append({"iterations": f"{seg[0]['iteration']}-{seg[-1]['iteration']}", "wall_s": seg[-1]["wall_s"],
                     **{k: float(np.mean([r[k] for r in seg])) for k in ("loss", "l1", "lpips", "tc")},
                     "monitor_corr": corr[-1] if corr else None})
    return rows


def training_report_md(arch: str, iterations: int, wall_s: float, log: list[dict], heldout: dict,
                       config_yaml: str, command: str) -> str:
    lines = [f"# Shipped E2VID weights: `{arch}` trained on simulated events", "",
             f"Made by `{command}` on a 2-core CPU: {iterations} iterations in {wall_s / 60:.1f} min of training.",
             "Training data: sequences generated on the fly by `e2vid/synth.py` (procedural gratings, noise and",
             "shapes moved by random 2D similarity motions, rendered at 3000 frames/s, turned into events by the",
             "project's simulator with a random sensor per sequence; no benchmark scene is used).", "",
             "## Loss curve (means over slices of training)", "",
             "Monitor correlation: mean per-frame correlation with the ground truth on held-out monitor clips, at",
             "the end of the slice.", "",
             "| iterations | wall (min) | total | L1 | LPIPS (alex) | temporal | monitor correlation |",
             "|---|---|---|---|---|---|---|"]
    for r in loss_curve_rows(log):
        corr = "" if r["monitor_corr"] is None else f"{r['monitor_corr']:.3f}"
        lines.append(f"| {r['iterations']} | {r['wall_s'] / 60:.1f} | {r['loss']:.4f} | {r['l1']:.4f} | "
                     f"{r['lpips']:.4f} | {r['tc']:.4f} | {corr} |")
    sel = heldout.get("selected")
    if sel and sel.get("monitor_corr") is not None:
        lines += ["", f"Shipped weights: iteration {sel['iteration']}, the best monitor correlation "
                  f"({sel['monitor_corr']:.3f})."]
    s = heldout["sequences"]
    lines += ["", f"## Held-out quality ({s['n']} simulated sequences of {s['steps']} steps at "
              f"{s['size'][1]}x{s['size'][0]}, seeds from {s['seed_base']}, first {s['skip']} frames skipped)", "",
              "| reconstruction | PSNR | SSIM | correlation |", "|---|---|---|---|"]
    names = {"network": f"{arch}, raw output", "network_corrected": f"{arch}, after log gain/offset fit",
             "hpf_corrected": f"high-pass filter (cutoff {heldout.get('hpf_cutoff_rad_s', 30)} rad/s), after the same fit"}
    for key, label in names.items():
        corr = heldout[key].get("corr")
        lines.append(f"| {label} | {heldout[key]['psnr']:.2f} | {heldout[key]['ssim']:.3f} | "
                     f"{'' if corr is None else f'{corr:.3f}'} |")
    lines += ["", "## Config", "", "```yaml", config_yaml.rstrip(), "```", ""]
    return "\n".join(lines)
