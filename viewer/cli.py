"""`e4dgs viewer`: serve a dataset or trained runs to the browser until Ctrl-C."""
from __future__ import annotations

import argparse
import signal
import threading
from pathlib import Path

from common.argtypes import port_int, positive_float


def add_viewer_parser(sub) -> None:
    p = sub.add_parser("viewer", help="browser viewer of a dataset scene or trained runs (viser, on localhost)",
                       description="Serve a generated scene (its cameras moving along their trajectories, frames, "
                                   "blur levels and events on a time line) or one or more trained runs (rendered "
                                   "from the browser's camera at the slider's time; a second run is shown beside "
                                   "the first at the same view and time), or one event file (.h5, e.g. from `e4dgs "
                                   "import`: its stream on a time line from its first event). Stop with Ctrl-C.")
    p.add_argument("paths", nargs="+", type=Path, metavar="DATA_OR_RUN",
                   help="a scene folder (data/quick/hinge), run folders (runs/quick/hinge/e4dgs-<hash>, or its "
                        "prefix runs/quick/hinge/e4dgs when only one run matches), or an event file (.h5)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=port_int, default=8080, help="port (default 8080; 0 picks a free one)")
    p.add_argument("--slowmo", type=positive_float, default=100.0,
                   help="play back this many times slower than real time (default 100: a 0.1 s clip in 10 s)")
    p.set_defaults(func=run_viewer)


def check_host(host: str, timeout_s: float = 3.0) -> None:
    """--host must be an address of this machine's kind: an IP literal (checked as one: 999.1.1.1 is
    not) or a name that resolves within timeout_s (a resolver without a network could hang)."""
    import ipaddress
    import re
    import socket
    from concurrent.futures import ThreadPoolExecutor, TimeoutError as FutureTimeout

    if re.fullmatch(r"[0-9.]+|[0-9a-fA-F:]*:[0-9a-fA-F:.]*", host):
        try:
            ipaddress.ip_address(host)
        except ValueError:
            raise SystemExit(f"error: --host {host}: not an IP address") from None
        return
    pool = ThreadPoolExecutor(1)
    try:
        pool.submit(socket.getaddrinfo, host, None).result(timeout=timeout_s)
    except FutureTimeout:
        raise SystemExit(f"error: --host {host}: the name did not resolve within {timeout_s:g} s") from None
    except OSError as exc:
        raise SystemExit(f"error: --host {host}: unknown host ({exc.strerror or exc})") from None
    finally:
        pool.shutdown(wait=False)


def _event_file_viewer(args: argparse.Namespace):
    from eventio.h5io import EventFileError
    from viewer.event_stream import EventStreamViewer

    try:
        viewer = EventStreamViewer(args.paths[0], host=args.host, port=args.port)
    except (EventFileError, ValueError) as exc:
        raise SystemExit(f"error: {exc}") from None
    except OSError as exc:
        raise SystemExit(f"error: cannot serve on {args.host}:{args.port} ({exc.strerror or exc}); "
                         "choose another --port") from None
    return viewer, [viewer.label]


def run_viewer(args: argparse.Namespace) -> int:
    from viewer.sources import open_source

    check_host(args.host)
    if len(args.paths) == 1 and args.paths[0].is_file() and args.paths[0].suffix == ".h5":
        viewer, labels, notes = *_event_file_viewer(args), []    # a bare event file: its stream on a time line
    else:
        sources = [open_source(p) for p in args.paths]      # a bad path: one line, before the server starts
        if len(sources) > 1 and any(s.model is None for s in sources):
            raise SystemExit("error: several paths must all be runs (a dataset is shown alone, or beside a run "
                             "through the run's own scene)")
        from viewer.app import Viewer

        try:
            viewer = Viewer(sources, host=args.host, port=args.port, slowmo=args.slowmo)
        except OSError as exc:
            raise SystemExit(f"error: cannot serve on {args.host}:{args.port} ({exc.strerror or exc}); "
                             "choose another --port") from None
        labels, notes = [s.label for s in sources], [f"{s.path}: {s.note}" for s in sources if s.note]
    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    print(f"viewer: {' | '.join(labels)}")
    for note in notes:
        print(f"viewer: {note}")
    print(f"viewer: open {viewer.url} in a browser (Ctrl-C stops)", flush=True)
    try:
        done.wait()
    finally:
        viewer.stop()
        print("viewer: stopped", flush=True)
    return 0
