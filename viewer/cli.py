"""`e4dgs viewer`: serve a dataset or trained runs to the browser until Ctrl-C."""
from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path

from common.argtypes import positive_float


def add_viewer_parser(sub) -> None:
    p = sub.add_parser("viewer", help="browser viewer of a dataset scene or trained runs (viser, on localhost)",
                       description="Serve a generated scene (its cameras moving along their trajectories, frames, "
                                   "blur levels and events on a time line) or one or more trained runs (rendered "
                                   "from the browser's camera at the slider's time; a second run is shown beside "
                                   "the first at the same view and time). Stop with Ctrl-C.")
    p.add_argument("paths", nargs="+", type=Path, metavar="DATA_OR_RUN",
                   help="a scene folder (data/quick/hinge) or run folders (runs/quick/hinge/e4dgs-<hash>, or its "
                        "prefix runs/quick/hinge/e4dgs when only one run matches)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0 picks a free one)")
    p.add_argument("--slowmo", type=positive_float, default=100.0,
                   help="play back this many times slower than real time (default 100: a 0.1 s clip in 10 s)")
    p.set_defaults(func=run_viewer)


def run_viewer(args: argparse.Namespace) -> int:
    from viewer.sources import open_source

    if not 0 <= args.port <= 65535:
        raise SystemExit(f"error: --port: expected 0..65535, got {args.port}")
    sources = [open_source(p) for p in args.paths]          # a bad path: one line, before the server starts
    if len(sources) > 1 and any(s.model is None for s in sources):
        raise SystemExit("error: several paths must all be runs (a dataset is shown alone, or beside a run "
                         "through the run's own scene)")
    from viewer.app import Viewer

    try:
        viewer = Viewer(sources, host=args.host, port=args.port, slowmo=args.slowmo)
    except OSError as exc:
        raise SystemExit(f"error: cannot serve on {args.host}:{args.port} ({exc.strerror or exc}); "
                         "choose another --port") from None
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    print(f"viewer: {' | '.join(s.label for s in sources)}")
    for s in sources:
        if s.note:
            print(f"viewer: {s.path}: {s.note}")
    print(f"viewer: open {viewer.url} in a browser (Ctrl-C stops)", flush=True)
    try:
        done.wait()
    finally:
        viewer.stop()
        print("viewer: stopped", flush=True)
    return 0
