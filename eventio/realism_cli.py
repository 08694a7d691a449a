"""`e4dgs realism`: the statistics of one event recording, or of a simulated one beside a real one with
their distances (eventio.realism), printed as a table and saved as realism.json and realism.png
(the distributions overlaid: per-pixel rate, inter-event interval, rate over time)."""
from __future__ import annotations

import argparse
import json
import sys
import math
from pathlib import Path

# (statistic, its label, format) in the order of the table
ROWS = (("n_events", "events", "{:,.0f}"), ("duration_s", "duration (s)", "{:.3f}"),
        ("rate_ev_per_s", "event rate (ev/s)", "{:,.0f}"), ("on_fraction", "ON fraction", "{:.3f}"),
        ("active_fraction", "active pixels", "{:.2%}"), ("pixel_rate_median_hz", "per-pixel rate median (Hz)", "{:.3g}"),
        ("pixel_rate_p99_hz", "per-pixel rate p99 (Hz)", "{:.3g}"), ("pixel_rate_max_hz", "per-pixel rate max (Hz)", "{:.3g}"),
        ("iei_min_us", "inter-event interval min (us)", "{:.0f}"), ("iei_p0_1_us", "inter-event interval p0.1 (us)", "{:.0f}"),
        ("iei_p1_us", "inter-event interval p1 (us)", "{:.0f}"), ("iei_p50_us", "inter-event interval p50 (us)", "{:.0f}"),
        ("same_polarity_fraction", "consecutive same polarity", "{:.3f}"),
        ("ba_fraction", "isolated events (background activity)", "{:.2%}"),
        ("ba_rate_hz", "background activity (Hz per pixel)", "{:.3g}"), ("hot_pixels", "hot pixels", "{:,.0f}"))


def add_realism_parser(sub) -> None:
    p = sub.add_parser("realism", help="statistics of an event recording, or a simulated one against a real one",
                       description="Prints the statistics of an event recording (any format `import` reads, or the "
                                   "toolkit's .h5): rate and its time course, ON fraction, active pixels, per-pixel "
                                   "rate, same-pixel inter-event interval and its floor, consecutive same polarity, "
                                   "background activity, hot pixels. Given a second recording (the real one), prints "
                                   "both side by side with their distances: Wasserstein-1 between log10 per-pixel "
                                   "rates and between log10 inter-event intervals, relative errors, and the "
                                   "correlation of the 10 ms rate series when the clips cover the same span. Writes "
                                   "realism.json and realism.png (the distributions overlaid) to --out.")
    p.add_argument("recording", type=Path, help="an event recording (the simulated one when two are given)")
    p.add_argument("real", type=Path, nargs="?", default=None, help="a real recording to compare it with")
    p.add_argument("--out", type=Path, default=None, help="folder for realism.json and realism.png (default: none)")
    p.set_defaults(func=run_realism)


def _read(path: Path):
    from eventio.formats import read_recording
    from eventio.h5io import read_events

    if not path.exists():
        raise SystemExit(f"error: {path}: no such file or folder")
    try:
        return read_events(path) if path.suffix == ".h5" else read_recording(path)[0]
    except (ValueError, OSError) as exc:
        raise SystemExit(f"error: {' '.join(str(exc).split())}") from None


def _fmt(fmt: str, v) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else fmt.format(v)


def report_table(stats: list, names: list[str], dist: dict | None) -> str:
    """The Markdown table of one or two RealismStats (and the distances of the first to the second)."""
    head = "| statistic | " + " | ".join(names) + (" | relative error |" if dist else " |")
    lines = [head, "|---|" + "---|" * (len(names) + (1 if dist else 0))]
    for key, label, fmt in ROWS:
        vals = [getattr(s, key) for s in stats]
        rel = (dist or {}).get("relative", {}).get(key)
        lines.append(f"| {label} | " + " | ".join(_fmt(fmt, v) for v in vals)
                     + (f" | {_fmt('{:+.0%}', rel)} |" if dist else " |"))
    if dist:
        corr = dist["rate_correlation"]
        lines += ["", f"Wasserstein-1, log10 per-pixel rate: {_fmt('{:.3f}', dist['w1_log_rate'])} decades; "
                      f"log10 inter-event interval: {_fmt('{:.3f}', dist['w1_log_iei'])} decades; "
                      "10 ms rate series correlation: " + (f"{corr:.3f}" if corr is not None else
                                                           "- (the clips cover different spans)")]
    return "\n".join(lines) + "\n"


def draw(stats: list, names: list[str], path: Path) -> None:
    """realism.png: per-pixel rate, inter-event interval and rate over time, one colour per stream."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from common.fileio import atomic_output

    fig, ax = plt.subplots(1, 3, figsize=(14, 4))
    for s, name in zip(stats, names):
        ax[0].hist(s.log_pixel_rates, bins=60, histtype="step", density=True, label=name)
        ax[1].hist(s.log_iei, bins=60, histtype="step", density=True, label=name)
        ax[2].plot(np.arange(len(s.rate_series)) * 0.01, s.rate_series / 0.01, label=name, lw=1)
    ax[0].set(xlabel="log10 per-pixel rate (Hz), active pixels", ylabel="density")
    ax[1].set(xlabel="log10 same-pixel inter-event interval (us)", ylabel="density")
    ax[2].set(xlabel="time from first event (s)", ylabel="events / s (10 ms bins)")
    for a in ax:
        a.legend(fontsize=8)
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)


def run_realism(args: argparse.Namespace) -> int:
    from common.fileio import write_text_atomic
    from eventio.realism import distances, stream_stats

    paths = [args.recording] + ([args.real] if args.real is not None else [])
    stats = []
    for p in paths:
        try:
            stats.append(stream_stats(_read(p)))
        except ValueError as exc:
            raise SystemExit(f"error: {p}: {exc}") from None
    names = [p.name for p in paths] if len({p.name for p in paths}) == len(paths) else [str(p) for p in paths]
    dist = distances(stats[0], stats[1]) if len(stats) == 2 else None
    if dist is not None and (stats[0].width, stats[0].height) != (stats[1].width, stats[1].height):
        print(f"warning: {names[0]} is {stats[0].width}x{stats[0].height} pixels and {names[1]} "
              f"{stats[1].width}x{stats[1].height}: per-pixel figures and the distances compare, the event rate "
              "and active fraction are of different sensors", file=sys.stderr)
    print(report_table(stats, names, dist), end="")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        doc = {"recordings": {n: s.summary() for n, s in zip(names, stats)}, "distances": dist,
               "definitions": "eventio/realism.py; docs/reference/realism.md"}
        write_text_atomic(args.out / "realism.json", json.dumps(doc, indent=1, default=float))
        draw(stats, names, args.out / "realism.png")
        print(f"realism: wrote {args.out / 'realism.json'} and {args.out / 'realism.png'}")
    return 0
