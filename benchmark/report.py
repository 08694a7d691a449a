"""Tables and plots from results.jsonl (`e4dgs bench --report` regenerates them without training).

leaderboard.md/.csv/.json  the paper's Table 1 layout: per scene PSNR / SSIM / LPIPS, their average and
                        the training time; best in bold, second best underlined (per column), where
                        the difference exceeds the seed spread (benchmark.ties), else marked as a tie;
                        a cell trained at several seeds shows mean ± sd over them
accuracy_vs_time.png/.md  test PSNR against training wall-clock seconds at each snapshot
blur.md                 the blur-robustness study (events-only methods never see RGB: one value for all levels)
ablation.md             E-4DGS with each component switched off (the paper's Table 2 layout)
speed.md/.png           the speed study: PSNR against motion speed, floors, crossing speeds (benchmark.speed_report)
"""
from __future__ import annotations

import csv
import io
import math
from collections import defaultdict
from pathlib import Path

from benchmark.rows import cell_order, describe_rows, labels_of, sees_rgb
from benchmark.speed_report import SpeedRoles, plot_speed, speed_tables
from benchmark.ties import (ALPHA, average_error, combine_seeds, degrees_of_freedom, mean_sd, pooled_spread,
                            rank_with_ties, standard_error, welch_df)
from common.fileio import atomic_output, write_text_atomic

METRICS = (("psnr", "PSNR↑", True), ("ssim", "SSIM↑", True), ("lpips", "LPIPS↓", False))


def _fmt(key: str, v: float | None) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    return f"{v:.2f}" if key == "psnr" else f"{v:.3f}"


def _mark(text: str, rank: str) -> str:
    """A value with its rank: best **bold**, second <u>underlined</u>; a tie (rank ending in "=") also ≈."""
    tie = "≈" if rank.endswith("=") else ""
    rank = rank.rstrip("=")
    return f"**{text}{tie}**" if rank == "best" else f"<u>{text}{tie}</u>" if rank == "second" else text


def main_table(rows: list[dict]) -> tuple[list[str], dict[str, dict[str, dict]]]:
    """(scenes in order, cell -> scene -> row) of the main study; a cell trained at several seeds is
    one row of their means (benchmark.ties.combine_seeds: n_seeds, spread)."""
    groups: dict[str, dict[str, list[dict]]] = defaultdict(lambda: defaultdict(list))
    scenes: list[str] = []
    for r in rows:
        if r["study"] != "main":
            continue
        groups[r["cell"]][r["scene"]].append(r)
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
    table: dict[str, dict[str, dict]] = defaultdict(dict)
    for cell, per_scene in groups.items():
        for scene, rs in per_scene.items():
            table[cell][scene] = combine_seeds(rs)
    return scenes, table


def kind_spreads(table, preset_spread: dict[str, dict[str, float]] | None) -> tuple[dict, dict[str, str]]:
    """(cell -> {metric: sd} a one-seed cell is taken to have, cell -> where it comes from): measured
    over seeds in these rows where a scene has two or more, else the preset's seed_spread."""
    pooled = pooled_spread(table)
    out, source = {}, {}
    for c in table:
        if c in pooled:
            out[c], source[c] = pooled[c], "these results"
        elif (preset_spread or {}).get(c):
            out[c], source[c] = preset_spread[c], "the preset's seed_spread"
    return out, source


def column_ranks(table, cells: list[str], scenes: list[str], col: tuple[str, str], spreads: dict,
                 higher: bool) -> dict[str, str]:
    """Ranks of one column (scene or "average", metric) with ties (benchmark.ties.rank_with_ties)."""
    scene, key = col
    values = {}
    for c in cells:
        if scene == "average":
            m = _average(table, c, scenes, key)
            rows = [table[c].get(s) for s in scenes]
            errors = [standard_error(r, key, spreads.get(c)) for r in rows] if None not in rows else [None]
            se = average_error(errors)
            df = welch_df(errors, [degrees_of_freedom(r, key) for r in rows]) if se else math.inf
        else:
            r = table[c].get(scene)
            m = r.get(key) if r else None
            se = standard_error(r, key, spreads.get(c)) if r else None
            df = degrees_of_freedom(r, key) if r else math.inf
        values[c] = (m, se, df) if m is not None else None
    return rank_with_ties(values, higher)


def _fmt_cell(key: str, row: dict | None, value: float | None) -> str:
    """A value, with ± its seeds' sd where the cell has several seeds, and † for a row kept from
    another version (--reuse-older)."""
    text = _fmt(key, value)
    if row and row.get("n_seeds", 1) > 1 and key in (row.get("spread") or {}):
        text += f" ± {_fmt(key, row['spread'][key])}"
    return text + ("†" if row and row.get("older") else "")


def _average(table, cell, scenes, key):
    """Mean of `key` over the scenes, or None unless every scene has a row with a value for it."""
    vals = [table[cell][s].get(key) for s in scenes if s in table[cell]]
    return sum(vals) / len(vals) if len(vals) == len(scenes) and vals and None not in vals else None


def is_failed(row: dict) -> bool:
    """A job that failed on every attempt (a Ray run's record of it; it has no metrics)."""
    return row.get("status") == "failed"


def failed_section(failed: list[dict]) -> str:
    if not failed:
        return ""
    lines = [f"| {r['key']} | {r.get('error', '')} |" for r in failed]
    return ("\n### Failed jobs\n\nThese jobs failed on every attempt; `e4dgs bench` runs them again. Their worker "
            "logs are in logs/.\n\n| Job | Last error |\n|---|---|\n" + "\n".join(lines) + "\n")


def leaderboard(rows: list[dict], header: str = "", failed: list[dict] = (), order: tuple[str, ...] = (),
                seed_spread: dict[str, dict[str, float]] | None = None) -> tuple[str, str]:
    scenes, table = main_table(rows)
    for r in failed:                      # a failed main job still gets its row and column
        if r["study"] == "main" and r["scene"] not in scenes:
            scenes.append(r["scene"])
    failed_cells = {(r["cell"], r["scene"]) for r in failed if r["study"] == "main"}
    main_rows = [r for r in list(rows) + list(failed) if r["study"] == "main"]
    cells = cell_order(main_rows, order)
    labels = labels_of(main_rows)
    columns = [(s, k) for s in scenes for k, _, _ in METRICS] + [("average", k) for k, _, _ in METRICS]
    values = {col: {c: (_average(table, c, scenes, col[1]) if col[0] == "average"
                        else table[c].get(col[0], {}).get(col[1])) for c in cells} for col in columns}
    spreads, spread_source = kind_spreads(table, seed_spread)
    ranks = {col: column_ranks(table, cells, scenes, col, spreads, dict((k, h) for k, _, h in METRICS)[col[1]])
             for col in columns}
    md = io.StringIO()
    if header:
        md.write(header.rstrip() + "\n\n")
    md.write("| Method | " + " | ".join(f"{s} {lbl}" for s in scenes + ["Average"] for _, lbl, _ in METRICS)
             + " | Train time (s/scene) | Gaussians |\n")
    md.write("|---|" + "---|" * (len(columns) + 2) + "\n")
    out_csv = io.StringIO()
    w = csv.writer(out_csv)
    w.writerow(["method", "label"] + [f"{s}_{k}" for s, k in columns] + ["train_s_per_scene", "gaussians_mean",
                                                                         "seeds", "older_version"])
    for c in cells:
        times = [table[c][s].get("wall_s") for s in scenes if s in table[c]]
        gauss = [table[c][s].get("n_gaussians") for s in scenes if s in table[c]]
        t = sum(times) / len(times) if times and None not in times else None
        g = sum(gauss) / len(gauss) if gauss and None not in gauss else None
        tail = f" | {_fmt_s(t)} | {_fmt_s(g)} |\n"
        md.write(f"| {labels.get(c, c)} | " + " | ".join(
            "failed" if (c, s) in failed_cells
            else _mark(_fmt_cell(k, table[c].get(s) if s != "average" else None, values[(s, k)][c]),
                       ranks[(s, k)].get(c, "")) for s, k in columns) + tail)
        seeds = sorted({r.get("n_seeds", 1) for r in table[c].values()})
        older = "; ".join(f"{s}: {table[c][s]['older']}" for s in scenes if table[c].get(s, {}).get("older"))
        w.writerow([c, labels.get(c, c)] + [("" if values[col][c] is None else f"{values[col][c]:.4f}") for col in columns]
                   + ["" if t is None else f"{t:.1f}", "" if g is None else f"{g:.0f}", "/".join(map(str, seeds)), older])
    external = [labels[c] for c in cells if any(r.get("external") for r in table[c].values())]
    if external:
        md.write("\nScored from outside renders (`e4dgs score`, their own training): " + ", ".join(external)
                 + "; their train time is what their authors reported.\n")
    md.write(spread_note(table, cells, scenes, labels, spreads, spread_source))
    md.write("\nBest per column in **bold**, second <u>underlined</u>. PSNR/SSIM/LPIPS are means of per-image "
             "values over each scene's held-out views; methods that see no RGB (events only) are scored "
             "against grayscale ground truth after the log-intensity gain (>= 0) / offset correction, methods that "
             "see RGB against RGB. Train time: training-only wall-clock seconds, mean over scenes.\n")
    machines = sorted({(r["cpu"], r.get("precision") or "?") for c in cells for r in table[c].values() if r.get("cpu")})
    if machines:   # seconds mean something only beside the processor (and the deformation's dtype on it)
        md.write("Train times measured on: " + "; ".join(f"{cpu}, deformation in {prec}" for cpu, prec in machines) + ".\n")
    speeds = sorted({(labels.get(c, c), table[c][s]["speed"]) for c in cells for s in scenes
                     if table[c].get(s, {}).get("speed") not in (None, 1, 1.0)})      # x1 is the scene itself
    if speeds:
        md.write("Speed variants: " + "; ".join(f"{label} at x{sp:g}" for label, sp in speeds) + " (the same motion "
                 "x times faster; its blurred frames and its events). The others train on the scene at speed 1.\n")
    md.write(luma_table(scenes, table, cells, labels, spreads))
    md.write(dynamic_table(scenes, table, cells, labels, spreads))
    md.write(floor_table(scenes, table, cells, labels))
    if len(scenes) > 1:
        md.write("\n### Per scene\n\n| Scene | Method | PSNR↑ | SSIM↑ | LPIPS↓ | Iterations | Train (s) | Gaussians |\n"
                 "|---|---|---|---|---|---|---|---|\n")
        for s in scenes:
            for c in cells:
                r = table[c].get(s)
                if r:
                    md.write(f"| {s} | {labels.get(c, c)} | {_fmt('psnr', r['psnr'])} | {_fmt('ssim', r['ssim'])} | "
                             f"{_fmt('lpips', r.get('lpips'))} | {r.get('iterations') or '–'} | {_fmt_s(r.get('wall_s'))} | "
                             f"{_fmt_s(r.get('n_gaussians'))} |\n")
    md.write(failed_section(list(failed)))
    return md.getvalue(), out_csv.getvalue()


def spread_note(table, cells: list[str], scenes: list[str], labels: dict[str, str], spreads: dict,
                source: dict[str, str]) -> str:
    """What the ranks rest on: seeds per cell, the spread a one-seed cell is taken to have and from
    where, and which rows come from another version (†)."""
    out = io.StringIO()
    n = sorted({r.get("n_seeds", 1) for c in cells for r in table[c].values()})
    varied = {"train": "training's random draws", "init": "the initial points",
              "noise": "the event sensor's noise realisation"}
    used = {a for c in cells for r in table[c].values() if r.get("n_seeds", 1) > 1 for a in r.get("seed_axes", ())}
    axes = [a for a in varied if a in used] + sorted(used - set(varied))
    one = "" if "noise" in axes else "; the dataset is one realisation"
    what = f" (a seed varies {' and '.join(varied.get(a, a) for a in axes)}{one})" if axes else ""
    out.write(f"\nSeeds per cell: {', '.join(map(str, n))}{what}; a cell with several shows mean ± sample standard deviation. "
              f"Bold / underline mark the best / second group: each of its values is better than every value below "
              f"it by Welch's t-test at {ALPHA:g} (two-sided; standard errors from the seeds' sd / sqrt(seeds) with "
              f"seeds - 1 degrees of freedom, a one-seed cell taking the seed spread of its kind), so two cells with "
              f"equal true means are called different {ALPHA:.0%} of the time; ≈ marks a group of several, which "
              "the seeds cannot separate.")
    missing = [labels.get(c, c) for c in cells if c not in spreads and all(r.get("n_seeds", 1) == 1 for r in table[c].values())]
    known = [f"{labels.get(c, c)} {spreads[c]['psnr']:.2f} dB ({source[c]})" for c in cells if c in spreads and "psnr" in spreads[c]]
    if known:
        out.write(" PSNR seed spread (sd) per cell: " + "; ".join(known) + ".")
    if missing:
        out.write(" No seed spread known for " + ", ".join(missing) + ": their ranks are plain orderings.")
    older: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))    # note -> scene -> cells
    for c in cells:
        for s in scenes:
            if table[c].get(s, {}).get("older"):
                older[table[c][s]["older"]][s].append(labels.get(c, c))
    if older:
        parts = [f"{note}: " + ", ".join(f"{s} ({'every cell' if len(cs) == len(cells) else ', '.join(cs)})"
                                         for s, cs in per.items()) for note, per in older.items()]
        out.write("\n\n† Kept from another version with `--reuse-older`, not trained by the code and data as they "
                  "are now: " + "; ".join(parts) + ".")
    return out.getvalue() + "\n"


def _fmt_s(v: float | None) -> str:
    return "–" if v is None else f"{v:.0f}"


def floor_table(scenes: list[str], table, cells: list[str], labels: dict[str, str]) -> str:
    """Every score next to its method's untrained floor: PSNR and floor (paper protocol, then luma)
    per scene. A score says something about what a method learned only as far as it is above it."""
    if not any(table[c].get(s, {}).get("floor_psnr") is not None for c in cells for s in scenes):
        return ""
    md = io.StringIO()
    md.write("\n### Above the untrained floor\n\n| Method | " + " | ".join(f"{s} PSNR (floor)" for s in scenes)
             + " | " + " | ".join(f"{s} luma (floor)" for s in scenes) + " |\n|---|" + "---|" * (2 * len(scenes)) + "\n")
    for c in cells:
        vals = []
        for key, floor in (("psnr", "floor_psnr"), ("psnr_luma", "floor_psnr_luma")):
            for s in scenes:
                r = table[c].get(s) or {}
                vals.append(f"{_fmt('psnr', r.get(key))} ({_fmt('psnr', r.get(floor))})" if r.get(floor) is not None
                            else _fmt("psnr", r.get(key)))
        md.write(f"| {labels.get(c, c)} | " + " | ".join(vals) + " |\n")
    md.write("\nFloor: the method's own starting model (its initial points, nothing trained) scored the same way, after "
             "the same correction. For events-only methods the gain / offset fit alone lifts a flat image to it.\n")
    return md.getvalue()


def dynamic_table(scenes: list[str], table, cells: list[str], labels: dict[str, str], spreads: dict | None = None) -> str:
    """PSNR over the moving pixels (the scenes' dynamic masks) next to the whole image's, per scene and on
    average, with SSIM and LPIPS over the same pixels on average; ranks on the region's columns."""
    if not any(table[c].get(s, {}).get("psnr_dyn") is not None for c in cells for s in scenes):
        return ""
    cols = [(s, "psnr_dyn") for s in scenes] + [("average", k) for k in ("psnr_dyn", "ssim_dyn", "lpips_dyn")]
    values = {col: {c: (_average(table, c, scenes, col[1]) if col[0] == "average" else table[c].get(col[0], {}).get(col[1]))
                    for c in cells} for col in cols}
    ranks = {col: column_ranks(table, cells, scenes, col, spreads or {}, higher=col[1] != "lpips_dyn") for col in cols}
    md = io.StringIO()
    md.write("\n### Dynamic region: the pixels that move\n\n| Method | "
             + " | ".join(f"{s} PSNR (whole)" for s in scenes)
             + " | Average PSNR (whole) | Average SSIM | Average LPIPS |\n|---|" + "---|" * (len(scenes) + 3) + "\n")
    for c in cells:
        vals = []
        for col in cols:
            key = col[1].removesuffix("_dyn")
            whole = (_average(table, c, scenes, key) if col[0] == "average" else table[c].get(col[0], {}).get(key))
            text = _mark(_fmt(key, values[col][c]), ranks[col].get(c, ""))
            vals.append(f"{text} ({_fmt(key, whole)})" if key == "psnr" else text)
        md.write(f"| {labels.get(c, c)} | " + " | ".join(vals) + " |\n")
    frac = [next((table[c][s].get("dyn_fraction") for c in cells if table[c].get(s, {}).get("dyn_fraction") is not None),
                 None) for s in scenes]
    md.write("\nScores over each test view's dynamic pixels only (the scene's masks: a pixel is dynamic when the "
             "surface it sees moves >= 2 px over the clip as seen from that view), whole-image PSNR in brackets, "
             "after the same correction; means over the views with dynamic pixels. Dynamic share of the pixels: "
             + ", ".join(f"{s} {100 * f:.1f} %" for s, f in zip(scenes, frac) if f is not None) + ".\n")
    return md.getvalue()


def luma_table(scenes: list[str], table, cells: list[str], labels: dict[str, str], spreads: dict | None = None) -> str:
    """PSNR of every method on one target, the luma the events-only methods are scored on (a colour
    prediction's luma against the truth's, after the method's own correction): the main table
    scores colour methods on RGB, a harder target, so its columns mix two quantities."""
    values = {s: {c: table[c][s].get("psnr_luma") if s in table[c] else None for c in cells} for s in scenes}
    values["average"] = {c: _average(table, c, scenes, "psnr_luma") for c in cells}
    ranks = {col: column_ranks(table, cells, scenes, (col, "psnr_luma"), spreads or {}, higher=True) for col in values}
    md = io.StringIO()
    md.write("\n### The same target for every method: PSNR of the luma\n\n| Method | "
             + " | ".join(scenes + ["Average"]) + " |\n|---|" + "---|" * (len(scenes) + 1) + "\n")
    for c in cells:
        md.write(f"| {labels.get(c, c)} | " + " | ".join(_mark(_fmt("psnr", values[col][c]), ranks[col].get(c, ""))
                                                      for col in scenes + ["average"]) + " |\n")
    md.write("\nEvery prediction (after its method's correction) and its ground truth reduced to Rec.709 luma, "
             "sRGB-encoded, as the dataset's gray frames are: the quantity events-only methods are scored on "
             "above. –: a result recorded before this score existed.\n")
    return md.getvalue()


def accuracy_vs_time(rows: list[dict]) -> str:
    labels = labels_of(rows)
    md = io.StringIO()
    md.write("| Scene | Method | " + "Snapshots: iteration @ training s → PSNR |\n|---|---|---|\n")
    for r in rows:
        if r["study"] != "main":
            continue
        pts = ", ".join(f"{p.get('iteration', '–')} @ {p['wall_s']:.0f} s → {p['psnr']:.2f}" for p in r.get("snapshots") or [])
        md.write(f"| {r['scene']} | {labels.get(r['cell'], r['cell'])} | {pts} |\n")
    return md.getvalue()


def plot_accuracy_vs_time(rows: list[dict], path: Path, order: tuple[str, ...] = ()) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes, table = main_table(rows)
    labels = labels_of(rows)
    fig, axes = plt.subplots(1, max(len(scenes), 1), figsize=(4.2 * max(len(scenes), 1), 3.4), squeeze=False)
    for ax, s in zip(axes[0], scenes):
        for c in cell_order([r for r in rows if r["study"] == "main"], order):
            r = table.get(c, {}).get(s)
            if r and r.get("snapshots"):
                ax.plot([p["wall_s"] for p in r["snapshots"]], [p["psnr"] for p in r["snapshots"]], "o-",
                        label=labels.get(c, c))
        ax.set_title(s)
        ax.set_xlabel("training wall-clock (s)")
        ax.set_ylabel("test PSNR (dB)")
        ax.grid(alpha=0.3)
    if axes[0][0].get_legend_handles_labels()[0]:      # a leaderboard without snapshots has no curve to name
        axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def blur_table(rows: list[dict], levels=("mild", "medium", "strong"), order: tuple[str, ...] = (),
               reference: str = "d3dgs_sharp") -> str:
    blur = [r for r in rows if r["study"] == "blur"]
    if not blur:
        return ""
    labels = labels_of(rows)
    scene = blur[0]["scene"]
    by = {(r["cell"], r["variant"]): r for r in blur}
    main = {r["cell"]: r for r in rows if r["study"] == "main" and r["scene"] == scene}
    as_speed = any(r.get("speed") is not None for r in blur)      # levels are motion speeds
    cells = [c for c in cell_order(blur + list(main.values()), order) if c != reference]
    md = io.StringIO()
    md.write(f"Blur robustness on **{scene}**.\n\n")
    if as_speed:
        for lv in levels:
            data = next((r.get("data") for (c, v), r in by.items() if v == lv and (r.get("data") or {}).get("blur_median_px")),
                        None) or {}
            speed = next((r["speed"] for (c, v), r in by.items() if v == lv), None)
            if speed is not None:
                parts = [f"speed x{speed:g}"]
                if data.get("exposure_ms") is not None:
                    parts.append(f"{data['exposure_ms']:.2f} ms shutter")
                if data.get("blur_median_px") is not None:
                    parts.append(f"blur {data['blur_median_px']:.1f} / {data['blur_p90_px']:.1f} px (median / p90)")
                if data.get("blur_psnr_db") is not None:
                    parts.append(f"blurred frames {data['blur_psnr_db']:.1f} dB from sharp")
                md.write(f"- {lv}: " + ", ".join(parts) + "\n")
        md.write("\n")
    md.write("| Method | " + " | ".join(f"{lv} {lbl}" for lv in levels for _, lbl, _ in METRICS) + " |\n")
    md.write("|---|" + "---|" * (3 * len(levels)) + "\n")
    for c in cells:
        vals = []
        for lv in levels:
            r = by.get((c, lv)) or (main.get(c) if c in main and not sees_rgb(main[c]) and not as_speed else None)
            vals += [_fmt_cell(k, r, r.get(k) if r else None) for k, _, _ in METRICS]
        md.write(f"| {labels.get(c, c)} | " + " | ".join(vals) + " |\n")
    if as_speed:
        md.write("\nEach level is a motion speed: every method, events-only ones included, trains on that speed variant "
                 "(its blurred frames and its events).\n")
    else:
        no_rgb = [labels[c] for c in cells if c in main and not sees_rgb(main[c])]
        if no_rgb:
            md.write(f"\n{' and '.join(no_rgb)} never see the RGB frames, so one run stands for every level.\n")
    return md.getvalue()


def blur_levels(rows: list[dict], cfg=None) -> tuple[str, ...]:
    """The blur study's levels: the preset's, else those its rows hold (mild, medium, strong order first)."""
    if cfg is not None:
        return tuple(cfg.blur.levels)
    held = [r["variant"] for r in rows if r["study"] == "blur"]
    known = [lv for lv in ("mild", "medium", "strong") if lv in held]
    return tuple(known + [lv for lv in dict.fromkeys(held) if lv not in known]) or ("mild", "medium", "strong")


def ablation_table(rows: list[dict]) -> str:
    abl = [r for r in rows if r["study"] == "ablation"]
    if not abl:
        return ""
    scene = abl[0]["scene"]
    variants: dict[str, list[dict]] = defaultdict(list)
    for r in abl:
        variants[r["variant"]].append(r)
    seeds = sorted({r.get("seed") for r in abl if r.get("seed") is not None})
    full = variants.get("full")
    md = io.StringIO()
    md.write(f"Ablation of {abl[0].get('label') or abl[0]['cell']} on **{scene}**, {len(seeds) or 1} training seed(s) per "
             "variant: mean ± sample standard deviation over the seeds; Δ PSNR against the full method.\n\n"
             "| Variant | Seeds | PSNR↑ | Δ PSNR | SSIM↑ | LPIPS↓ | Gaussians | Train (s) |\n|---|---|---|---|---|---|---|---|\n")
    full_psnr = mean_sd([r["psnr"] for r in full])[0] if full else None
    order = (["full"] if full else []) + [v for v in variants if v != "full"]
    for name in order:
        rs = variants[name]
        cols = []
        for k in ("psnr", "ssim", "lpips"):
            m, sd = mean_sd([r[k] for r in rs])
            cols.append(f"{_fmt(k, m)} ± {_fmt(k, sd)}" if len(rs) > 1 else _fmt(k, m))
        p = mean_sd([r["psnr"] for r in rs])[0]
        delta = "–" if full_psnr is None or name == "full" else f"{p - full_psnr:+.2f}"
        n_g = mean_sd([r["n_gaussians"] for r in rs])[0]
        t = mean_sd([r["wall_s"] for r in rs])[0]
        mark = "†" if any(r.get("older") for r in rs) else ""
        md.write(f"| {name}{mark} | {len(rs)} | {cols[0]} | {delta} | {cols[1]} | {cols[2]} | {n_g:.0f} | {t:.0f} |\n")
    return md.getvalue()


def leaderboard_json(rows: list[dict], order: tuple[str, ...] = ()) -> str:
    """{cell: {label, inputs, external, scenes: {scene: {psnr, ssim, lpips, wall_s, iterations}}, average: {...}}}."""
    import json

    scenes, table = main_table(rows)
    out = {}
    for c in cell_order([r for r in rows if r["study"] == "main"], order):
        per = {s: {k: table[c][s].get(k) for k in ("psnr", "ssim", "lpips", "wall_s", "iterations", "n_gaussians",
                                                      "psnr_luma")} for s in scenes if s in table[c]}
        first = next(iter(table[c].values()))
        out[c] = {"label": first.get("label") or c, "inputs": first.get("inputs") or [],
                  "external": bool(first.get("external")), "scenes": per,
                  "average": {k: _average(table, c, scenes, k) for k in ("psnr", "ssim", "lpips", "wall_s")}}
    return json.dumps(out, indent=1)


def write_report(rows: list[dict], out_root: Path, header: str = "", cfg=None) -> list[Path]:
    """Every table and plot of results rows; `cfg` (the preset, a benchmark.config.BenchConfig) gives
    the cells' order and labels and the speed study's reference cells (without it: the rows' own)."""
    if not rows:
        raise ValueError(f"{out_root}: no results to report")
    order = tuple(cfg.cells) if cfg is not None else ()
    rows = describe_rows(rows, cfg.labels() if cfg is not None else None)
    roles = SpeedRoles(cfg.speed.reference, cfg.speed.rgb_reference) if cfg is not None else SpeedRoles()
    failed = [r for r in rows if is_failed(r)]
    rows = [r for r in rows if not is_failed(r)]
    md, table_csv = leaderboard(rows, header, failed, order, cfg.seed_spread if cfg is not None else None)
    written = []
    for name, text in (("leaderboard.md", md), ("leaderboard.csv", table_csv),
                       ("leaderboard.json", leaderboard_json(rows, order)), ("accuracy_vs_time.md", accuracy_vs_time(rows)),
                       ("blur.md", blur_table(rows, blur_levels(rows, cfg), order=order, reference=roles.reference)),
                       ("ablation.md", ablation_table(rows)), ("speed.md", speed_tables(rows + failed, roles, order))):
        if text:
            write_text_atomic(out_root / name, text)
            written.append(out_root / name)
    plot_accuracy_vs_time(rows, out_root / "accuracy_vs_time.png", order)
    written.append(out_root / "accuracy_vs_time.png")
    if plot_speed(rows, out_root / "speed.png", roles, order):
        written.append(out_root / "speed.png")
    return written
