"""Event file formats side by side: one camera's events written and read back in every format, with
the writing and reading libraries, whether the events came back the same (per timestamp; t to the
format's resolution, x, y, polarity, count, sensor size), file size, and write / read speed in
millions of events per second, all in one run (median of --repeats, formats alternated).

    python -m tools.bench_formats [--events data/quick/hinge/events/cam0.h5] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path
from tools.tool_cli import positive_int, run_tool

LIBRARIES = {"h5": ("h5py (ours)", "h5py (ours)"), "aedat4": ("dv-processing", "dv-processing"),
             "evt3": ("ours (eventio.evt_codec)", "evt3"), "evt2": ("ours (eventio.evt_codec)", "expelliarmus"),
             "rosbag": ("rosbags + ours (messages)", "rosbags + ours (messages)"),
             "rosbag2": ("rosbags + ours (messages)", "rosbags + ours (messages)"),
             "npz": ("NumPy", "NumPy"), "txt": ("ours (E2VID text)", "ours (E2VID text)")}


def size_of(path: Path) -> int:
    return sum(f.stat().st_size for f in path.rglob("*") if f.is_file()) if path.is_dir() else path.stat().st_size


def main(argv=None) -> int:
    from common.machine import cpu_summary
    from eventio.formats import FORMATS, SUFFIX, read_recording, same_events, write_stream
    from eventio.h5io import read_events

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--events", type=Path, default=Path("data/quick/hinge/events/cam0.h5"))
    ap.add_argument("--repeats", type=positive_int, default=3)
    ap.add_argument("--formats", nargs="+", default=list(FORMATS), choices=FORMATS)
    args = ap.parse_args(argv)
    if not args.events.exists():
        raise SystemExit(f"error: --events {args.events}: no such event file (make dataset writes data/quick)")
    stream = read_events(args.events)
    n = len(stream)
    times = {f: ([], []) for f in args.formats}
    result = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for fmt in args.formats:
                path = Path(tmp) / f"r{r}_{fmt}{SUFFIX[fmt]}"
                t0 = time.perf_counter()
                write_stream(path, stream, fmt)
                t1 = time.perf_counter()
                back, found = read_recording(path)
                t2 = time.perf_counter()
                times[fmt][0].append(t1 - t0)
                times[fmt][1].append(t2 - t1)
                result[fmt] = (found == fmt and same_events(stream, back), size_of(path))
                if path.is_dir():
                    import shutil
                    shutil.rmtree(path)
                else:
                    os.unlink(path)
    print(f"{args.events}: {n:,} events, {stream.width}x{stream.height}; median of {args.repeats}; CPU: {cpu_summary()}")
    print("| format | written by | read by | same events | size MB | bytes / event | write M ev/s | read M ev/s |")
    print("|---|---|---|---|---:|---:|---:|---:|")
    for fmt in args.formats:
        w, rd = (statistics.median(x) for x in times[fmt])
        ok, size = result[fmt]
        print(f"| {fmt} | {LIBRARIES[fmt][0]} | {LIBRARIES[fmt][1]} | {'yes' if ok else 'NO'} | {size / 1e6:.1f} | "
              f"{size / max(n, 1):.2f} | {n / w / 1e6:.2f} | {n / rd / 1e6:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_tool(main))
