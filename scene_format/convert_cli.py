"""`e4dgs export` and `e4dgs import`: event files between our HDF5 and the formats cameras and their
software write (eventio.formats: AEDAT4, Prophesee EVT 3.0 / 2.0 .raw, ROS1 / ROS2 bags, .npz,
E2VID text)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from common.argtypes import positive_int

FORMAT_HELP = "aedat4 | evt3 | evt2 | rosbag | rosbag2 | npz | txt | h5"


def add_export_parser(sub) -> None:
    from eventio.formats import FORMATS

    p = sub.add_parser("export", help="an event file, or every camera of a scene, in another format",
                       description="Write an event file (.h5) in another format, or every camera of a generated "
                                   "scene: one file per camera in the --out folder, or for rosbag / rosbag2 one bag "
                                   "with /cam{k}/events, camera_info, pose and image_raw topics.")
    p.add_argument("source", type=Path, help="event file (.h5) or scene folder")
    p.add_argument("--format", required=True, choices=FORMATS, metavar="FORMAT", help=FORMAT_HELP)
    p.add_argument("--out", type=Path, required=True, help="output file (a folder for a scene, or a ROS2 bag)")
    p.add_argument("--message-us", type=positive_int, default=1000,
                   help="ROS bags: microseconds of events per EventArray message (default 1000)")
    p.set_defaults(func=run_export)


def run_export(args: argparse.Namespace) -> int:
    from scene_format.export import export_scene
    from eventio.formats import write_stream
    from eventio.h5io import EventFileError, read_events
    from eventio.vendor_formats import FormatError

    src = args.source
    if not src.exists():
        raise SystemExit(f"error: {src}: no such event file or scene folder")
    if args.out.resolve() == src.resolve():
        raise SystemExit(f"error: --out {args.out}: is the source itself")
    if src.is_file():
        check_export_name(args.out, args.format)
    t0 = time.perf_counter()
    try:
        if src.is_dir():
            written = export_scene(src, args.format, args.out, args.message_us)
        else:
            stream = read_events(src)
            written = [write_stream(args.out, stream, args.format, message_us=args.message_us)]
    except (FormatError, EventFileError, ValueError) as exc:
        raise SystemExit(f"error: {exc}") from None
    print(f"{args.out}: {args.format}, {len(written)} file(s) in {time.perf_counter() - t0:.1f} s")
    return 0


def check_export_name(out: Path, fmt: str) -> None:
    """SystemExit unless `out` names a file of `fmt` (its suffix; a ROS2 bag is a folder), not a folder."""
    from eventio.formats import SUFFIX

    want = SUFFIX[fmt]
    if fmt == "rosbag2":
        known = {s for s in SUFFIX.values() if s}
        if out.suffix.lower() in known:
            raise SystemExit(f"error: --out {out}: a ROS2 bag is a folder; give a name without the {out.suffix} suffix")
        return
    if out.is_dir():
        raise SystemExit(f"error: --out {out}: is a folder; --format {fmt} writes one file (e.g. {out / ('events' + want)})")
    if out.suffix.lower() != want:
        raise SystemExit(f"error: --out {out}: --format {fmt} writes a {want} file; name it {out.with_suffix(want).name} "
                         f"(a reader finds the format from the contents, but other tools go by the name)")


def add_import_parser(sub) -> None:
    p = sub.add_parser("import", help="a recording (AEDAT4, EVT 3.0 / 2.0 .raw, ROS bag, .npz, .txt) into our HDF5",
                       description="Read a recording in any supported format (found from its contents) and write "
                                   "the toolkit's event file, which `view`, `e2vid` and `check` take.")
    p.add_argument("recording", type=Path, help="the recording (a ROS2 bag is a folder)")
    p.add_argument("--out", type=Path, required=True, help="event file to write (.h5)")
    p.add_argument("--topic", default=None, help="ROS bags with several event topics: which one")
    p.add_argument("--stream", default=None, help="AEDAT4 files with several event streams: which one")
    p.set_defaults(func=run_import)


def run_import(args: argparse.Namespace) -> int:
    from eventio.formats import read_recording
    from eventio.h5io import EventFileError, write_events
    from eventio.vendor_formats import FormatError

    if not args.recording.exists():
        raise SystemExit(f"error: {args.recording}: no such file or folder")
    if args.out.suffix != ".h5":
        raise SystemExit(f"error: --out {args.out}: expected a .h5 file name (the toolkit's event file)")
    if args.out.exists() and args.out.resolve() == args.recording.resolve():
        raise SystemExit(f"error: --out {args.out}: is the recording itself")
    try:
        stream, fmt = read_recording(args.recording, args.topic, args.stream)
        write_events(args.out, stream)
    except (FormatError, EventFileError, ValueError) as exc:
        raise SystemExit(f"error: {exc}") from None
    span = (int(stream.events["t"][-1]) - int(stream.events["t"][0])) / 1e6 if len(stream) else 0.0
    print(f"{args.out}: {len(stream)} events ({fmt}, {stream.width}x{stream.height}, {span:.3f} s)")
    return 0
