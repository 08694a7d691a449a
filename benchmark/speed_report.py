"""The speed study's tables and plot (speed.md, speed.png) from results rows, and the crossing speed
at which each event method overtakes D3DGS on blurred frames.

Rows of study "speed" hold one cell at one speed factor of one scene (variant "x<s>"); the main
study's D3DGS on sharp frames is the reference line (the sharp frames are the same at every speed).
Each score stands next to its method's untrained floor (the starting model after the same
correction), and a crossing whose event method is within FLOOR_MARGIN_DB of its floor there is said
to rest on the floor: it says the RGB method fell, not that the events taught anything.
"""
from __future__ import annotations

import io
import math
from collections import defaultdict
from pathlib import Path

from dataclasses import dataclass

from benchmark.rows import describe_rows, labels_of, sees_events
from common.fileio import atomic_output


@dataclass(frozen=True)
class SpeedRoles:
    """The study's two reference cells (the preset's speed.reference / speed.rgb_reference)."""
    reference: str = "d3dgs_sharp"      # the line: trained on sharp frames, the same at every speed
    rgb_reference: str = "d3dgs_blur"   # the RGB method the event methods must overtake


FLOOR_MARGIN_DB = 1.0                         # above the floor by less than this: "rests on the floor"
PROTOCOLS = (("psnr", "floor_psnr", "paper protocol (colour for RGB inputs, gray after gain/offset for events only)"),
             ("psnr_luma", "floor_psnr_luma", "luma (every method on the gray target)"),
             ("psnr_dyn", "floor_psnr_dyn", "dynamic region (paper protocol over the pixels that move)"))


def speed_grid(rows: list[dict]) -> dict[tuple[str, str], dict[str, dict[float, dict]]]:
    """{(dataset, scene): {cell: {speed: row}}} of the speed study's rows ("" is the preset's dataset)."""
    grid: dict[tuple[str, str], dict[str, dict[float, dict]]] = defaultdict(lambda: defaultdict(dict))
    for r in rows:
        if r.get("study") == "speed" and r.get("speed") is not None:
            grid[(r.get("dataset") or "", r["scene"])][r["cell"]][float(r["speed"])] = r
    return grid


def _ok(cells: dict[str, dict[float, dict]]) -> dict[str, dict[float, dict]]:
    """The cells' rows without the failed ones (which have no scores)."""
    return {c: {s: r for s, r in v.items() if r.get("status") != "failed"} for c, v in cells.items()}


def crossing_speed(speeds: list[float], ahead_db: list[float | None]) -> tuple[float | None, str]:
    """The speed at which `ahead_db` (event method minus RGB method, per speed in increasing order)
    turns positive for good: interpolated in log speed between the last sweep point behind and the
    first ahead. Returns (speed, how): how is 'ahead at every speed', 'crosses', 'never ahead'
    or 'no data'. A method ahead, then behind again, crosses where it is ahead from then on."""
    pts = [(s, d) for s, d in zip(speeds, ahead_db) if d is not None]
    if not pts:
        return None, "no data"
    if pts[-1][1] <= 0:
        return None, "never ahead"
    i = len(pts) - 1
    while i > 0 and pts[i - 1][1] > 0:
        i -= 1
    if i == 0:
        return pts[0][0], "ahead at every speed"
    (s0, d0), (s1, d1) = pts[i - 1], pts[i]
    f = -d0 / (d1 - d0)                        # d0 <= 0 < d1
    return math.exp(math.log(s0) + f * (math.log(s1) - math.log(s0))), "crosses"


def _sharp_reference(rows: list[dict], reference: str) -> dict[str, dict]:
    """scene -> the row of the reference cell (the speed study's, else the main study's)."""
    out = {r["scene"]: r for r in rows if r.get("study") == "main" and r.get("cell") == reference}
    out.update({r["scene"]: r for r in rows if r.get("study") == "speed" and r.get("cell") == reference})
    return out


def _ordered(cells, order: tuple[str, ...]) -> list[str]:
    return [c for c in order if c in cells] + [c for c in cells if c not in order]


def _sees_events(cell_rows: dict[float, dict]) -> bool:
    return any(sees_events(r) for r in cell_rows.values())


def _fmt(v: float | None, floor: float | None = None) -> str:
    if v is None:
        return "–"
    return f"{v:.2f}" + (f" ({floor:.2f})" if floor is not None else "")


def _speed_header(speeds: list[float], cells: dict[str, dict[float, dict]]) -> list[str]:
    """Per speed: blur px (median / p90), blurred-vs-sharp PSNR and events per second per camera,
    from the rows' data (the D3DGS rows carry the shutter's blur; any row carries the event rate)."""
    out = []
    for s in speeds:
        data = next((c[s].get("data") for c in cells.values() if s in c and (c[s].get("data") or {}).get("blur_median_px")),
                    None) or next((c[s].get("data") for c in cells.values() if s in c and c[s].get("data")), None) or {}
        px = (f"{data['blur_median_px']:.0f} / {data['blur_p90_px']:.0f} px" if data.get("blur_median_px") is not None
              else "–")
        db = f"{data['blur_psnr_db']:.1f} dB" if data.get("blur_psnr_db") is not None else "–"
        rate = f"{data['events_per_s_per_camera'] / 1e6:.0f} Mev/s" if data.get("events_per_s_per_camera") else "–"
        out.append(f"x{s:g}: {px}, {db}, {rate}")
    return out


def speed_tables(rows: list[dict], roles: SpeedRoles = SpeedRoles(), order: tuple[str, ...] = ()) -> str:
    """speed.md: per scene (and sensor), PSNR in both protocols at every speed, each with its floor,
    the sharp reference and the crossing speeds."""
    rows = describe_rows(rows)
    grid = speed_grid(rows)
    if not grid:
        return ""
    sharp = _sharp_reference(rows, roles.reference)
    labels = labels_of(rows)
    rgb_ref = roles.rgb_reference
    md = io.StringIO()
    md.write("# Speed study\n\nEvery cell trained on each speed variant of the scene (the same render traversed x times "
             "faster; a fixed shutter, so the blur grows with the speed; events simulated again at every speed with the "
             "scene's sensor). Each score is followed by its method's untrained floor in brackets (the starting model "
             "scored after the same correction). Reference: D3DGS on the sharp frames, the same at every speed.\n")
    for (dataset, scene), cells in sorted(grid.items()):
        if dataset and rgb_ref not in cells and rgb_ref in grid.get(("", scene), {}):
            # another sensor sees the same frames: the RGB methods' runs of the scene are its reference
            cells = {rgb_ref: grid[("", scene)][rgb_ref], **cells}
        speeds = sorted({s for c in cells.values() for s in c})
        title = f"{scene}" + (f", sensor of dataset `{dataset}`" if dataset else "")
        md.write(f"\n## {title}\n\nPer speed: blur median / p90, blurred vs sharp PSNR, events per second per camera: "
                 + "; ".join(_speed_header(speeds, cells)) + ".\n")
        for key, floor_key, what in PROTOCOLS:
            if not any(r.get(key) is not None for c in cells.values() for r in c.values()):
                continue                                   # rows scored before this protocol existed
            md.write(f"\n**PSNR, {what}** (dB; floor in brackets)\n\n| Method | " + " | ".join(f"x{s:g}" for s in speeds)
                     + " |\n|---|" + "---|" * len(speeds) + "\n")
            ref = sharp.get(scene)
            if ref is not None:
                md.write(f"| {labels.get(roles.reference, roles.reference)} (reference) | "
                         + " | ".join(_fmt(ref.get(key)) for _ in speeds) + " |\n")
            for cell in [c for c in _ordered(cells, order) if c != roles.reference]:
                vals = [("failed" if cells[cell][s].get("status") == "failed" else
                         _fmt(cells[cell][s].get(key), cells[cell][s].get(floor_key))) if s in cells[cell] else "–"
                        for s in speeds]
                md.write(f"| {labels[cell]} | " + " | ".join(vals) + " |\n")
            md.write("\n" + crossing_lines(_ok(cells), speeds, key, floor_key, rgb_ref, labels, order) + "\n")
        failed = [(c, s, r) for c, v in cells.items() for s, r in sorted(v.items()) if r.get("status") == "failed"]
        for c, s, r in failed:
            md.write(f"- failed: {labels.get(c, c)} at x{s:g}: {' '.join(str(r.get('error', '')).split())}\n")
    md.write(f"\nA crossing rests on the floor when the event method is less than {FLOOR_MARGIN_DB:g} dB above its "
             "untrained floor at the first speed it is ahead: the RGB method fell to it, the events taught little.\n")
    return md.getvalue()


def crossing_lines(cells: dict[str, dict[float, dict]], speeds: list[float], key: str, floor_key: str,
                   rgb_ref: str = "d3dgs_blur", labels: dict[str, str] | None = None,
                   order: tuple[str, ...] = ()) -> str:
    """One line per cell that sees events: where it overtakes the RGB reference (D3DGS on blurred
    frames) in this protocol."""
    labels = {**{c: c for c in cells}, **(labels or {})}
    labels.setdefault(rgb_ref, rgb_ref)
    rgb = cells.get(rgb_ref, {})
    lines = []
    for cell in [c for c in _ordered(cells, order) if _sees_events(cells[c])]:
        ahead = [(cells[cell][s][key] - rgb[s][key]) if s in cells[cell] and s in rgb
                 and cells[cell][s].get(key) is not None and rgb[s].get(key) is not None else None for s in speeds]
        s_x, how = crossing_speed(speeds, ahead)
        label = labels[cell]
        if how == "no data":
            lines.append(f"- {label}: no speed with both it and {labels[rgb_ref]}.")
            continue
        if how == "never ahead":
            s_last, d_last = [(s, d) for s, d in zip(speeds, ahead) if d is not None][-1]
            lines.append(f"- {label}: does not overtake {labels[rgb_ref]} within the sweep "
                         f"(up to x{s_last:g}, where it is {d_last:+.2f} dB).")
            continue
        first = next(s for s, d in zip(speeds, ahead) if d is not None and d > 0 and s >= s_x - 1e-9)
        row = cells[cell][first]
        gain = row[key] - row[floor_key] if row.get(floor_key) is not None else None
        floor_note = (f"; at x{first:g} it is {gain:.2f} dB above its floor"
                      + (" (rests on the floor)" if gain < FLOOR_MARGIN_DB else "")) if gain is not None else ""
        where = ("ahead at every speed of the sweep" if how == "ahead at every speed"
                 else f"overtakes it at x{s_x:.3g}")
        lines.append(f"- {label}: {where}{floor_note}.")
    return "\n".join(lines)


def plot_speed(rows: list[dict], path: Path, roles: SpeedRoles = SpeedRoles(), order: tuple[str, ...] = ()) -> bool:
    """speed.png: PSNR (paper protocol) against speed per scene, blur px on a second axis, D3DGS on
    sharp frames as the reference line. False when there is no speed study."""
    grid = {k: _ok(v) for k, v in speed_grid(rows).items() if not k[0]}
    if not grid:
        return False
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sharp = _sharp_reference(rows, roles.reference)
    labels = labels_of(rows)
    fig, axes = plt.subplots(1, len(grid), figsize=(5.2 * len(grid), 3.8), squeeze=False)
    for ax, ((_, scene), cells) in zip(axes[0], sorted(grid.items())):
        speeds = sorted({s for c in cells.values() for s in c})
        for cell in [c for c in _ordered(cells, order) if c != roles.reference]:
            pts = sorted(cells[cell].items())
            ax.plot([s for s, _ in pts], [r["psnr"] for _, r in pts], "o-", label=labels[cell], ms=4)
        if scene in sharp:
            ax.axhline(sharp[scene]["psnr"], color="k", ls="--", lw=1,
                       label=labels.get(roles.reference, roles.reference) + " (reference)")
        ax.set_xscale("log", base=2)
        ax.set_xlabel("speed factor (same motion, x times faster)")
        ax.set_ylabel("test PSNR (dB), paper protocol")
        ax.set_title(scene)
        ax.grid(alpha=0.3)
        blur = [(s, (r.get("data") or {}).get("blur_median_px")) for s, r in sorted(cells.get(roles.rgb_reference, {}).items())]
        blur = [(s, b) for s, b in blur if b is not None]
        if blur:
            ax2 = ax.twinx()
            ax2.plot([s for s, _ in blur], [b for _, b in blur], ":", color="grey", label="blur (median px)")
            ax2.set_ylabel("blur, median px (dotted)", color="grey")
        ax.set_xticks(speeds, [f"x{s:g}" for s in speeds], rotation=60, fontsize=7)
    if axes[0][0].get_legend_handles_labels()[0]:
        axes[0][0].legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return True
