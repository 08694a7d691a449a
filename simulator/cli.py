"""`e4dgs simulate` and `e4dgs draw-events`: frames -> event file, event file -> picture or video."""
from __future__ import annotations

import argparse
import re
from pathlib import Path

from common.argtypes import add_main_input, name_list, positive_float, positive_int, seed_int

IMAGE_SUFFIXES = {".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}


def list_frames(folder: Path) -> list[Path]:
    if not folder.is_dir():
        raise SystemExit(f"error: --frames {folder}: not a directory")
    # hidden files (macOS ._ resource forks, editors' backups) are not frames
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))
    by_stem: dict[str, Path] = {}
    for f in files:
        if f.stem in by_stem:
            raise SystemExit(f"error: --frames {folder}: {by_stem[f.stem].name} and {f.name} are the same frame in two "
                             "formats; keep one")
        by_stem[f.stem] = f
    if len(files) < 2:
        raise SystemExit(f"error: --frames {folder}: need at least two images ({', '.join(sorted(IMAGE_SUFFIXES))}), found {len(files)}")
    return files


def check_no_gaps(files: list[Path]) -> None:
    """With --fps, frame k is timed k / fps: a missing number in a numbered sequence would shift every
    later frame by one period, so it is an error (names without numbers are taken in order)."""
    numbers = [re.search(r"(\d+)$", f.stem) for f in files]
    if any(numbers) and not all(numbers):       # frame10, frame_a: no order by number covers both
        numbered = next(f for f, m in zip(files, numbers) if m)
        other = next(f for f, m in zip(files, numbers) if not m)
        raise SystemExit(f"error: --frames {numbered.parent}: {numbered.name} ends in a frame number but {other.name} "
                         "does not, so the frames have no order by number; name every frame with a (zero-padded) "
                         "number, or give --timestamps")
    if not all(numbers):
        return
    values = [int(m.group(1)) for m in numbers]
    for a, b, fa, fb in zip(values, values[1:], files, files[1:]):
        if b <= a:
            raise SystemExit(f"error: --frames {fa.parent}: sorted by name, {fa.name} comes before {fb.name} but "
                             "has a higher number; zero-pad the frame numbers")
    for a, b, fa, fb in zip(values, values[1:], files, files[1:]):
        if b != a + 1:
            raise SystemExit(f"error: --frames {fa.parent}: the numbering has a gap ({fa.name} is followed by "
                             f"{fb.name}); with --fps every frame must be present (or give --timestamps)")


def read_timestamps(path: Path, n_frames: int) -> list[int]:
    values = []
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise SystemExit(f"error: --timestamps {path}: {exc.strerror}") from None
    for lineno, line in enumerate(lines, 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            values.append(int(line))
        except ValueError:
            raise SystemExit(f"error: {path}:{lineno}: expected an integer microsecond timestamp, got {line!r}") from None
    if len(values) != n_frames:
        raise SystemExit(f"error: {path}: {len(values)} timestamps for {n_frames} frames")
    for k in range(1, len(values)):
        if values[k] <= values[k - 1]:
            raise SystemExit(f"error: {path}: timestamp {k + 1} ({values[k]} us) is not after timestamp {k} "
                             f"({values[k - 1]} us); the frames' times must increase")
    return values


def add_simulate_parser(sub) -> None:
    p = sub.add_parser("simulate", help="convert a folder of frames into an event file (DSEC HDF5)",
                       description="Simulate a DVS on a frame sequence. A killed run resumes from its last "
                                   "checkpoint when started again with the same inputs.")
    add_main_input(p, "frames", "FRAMES", "folder of frames sorted by name: EXR (linear) or PNG, JPEG, TIFF, BMP "
                   "(sRGB, linearised)", old_option="--frames")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--fps", type=positive_float, help="frame rate; frame k is at t0 + round(k * 1e6 / fps) us")
    src.add_argument("--timestamps", type=Path, help="file with one microsecond timestamp per frame")
    p.add_argument("--t0", default="0", help="time of the first frame with --fps: us, or with a unit (10ms, -5ms, "
                                             "0.5s); may be negative (default 0)")
    p.add_argument("--out", type=Path, required=True, help="output event file (.h5)")
    p.add_argument("--config", type=Path, help="sensor config: a YAML file or a shipped sensor's name (ideal, realistic, davis346, "
                                               "imx636, dvxplorer: configs/sensors/); default: noise-free, C = 0.2")
    p.add_argument("--effects", type=name_list, default=[], metavar="NAMES",
                   help="comma-separated optional effects of the --config sensor to switch on, with the values it "
                        "supplies: latency, readout, bandwidth, on_off_mismatch (default: none)")
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the sensor's noise and threshold mismatch (default 0)")
    p.add_argument("--checkpoint-every", type=positive_int, default=500, metavar="N",
                   help="save a resumable checkpoint every N frames (default 500)")
    p.add_argument("--format", action="append", default=[], metavar="FORMAT", choices=EXTRA_FORMATS,
                   help="also write the events in this format beside the .h5 (repeatable): "
                        + ", ".join(EXTRA_FORMATS) + " (docs/reference/formats.md)")
    p.set_defaults(func=run_simulate, sibling_outputs=lambda a: [(f"--format {f}", extra_output(a.out, f))
                                                                 for f in dict.fromkeys(a.format)])


EXTRA_FORMATS = ("aedat4", "evt3", "evt2", "rosbag", "rosbag2", "npz", "txt")
UNSIGNED_TIME_FORMATS = ("evt3", "evt2", "rosbag", "rosbag2")


def extra_output(out: Path, fmt: str) -> Path:
    """Where `--format fmt` writes beside the event file: its stem with the format's suffix (a ROS2 bag,
    a folder, as <stem>_rosbag2)."""
    from eventio.formats import SUFFIX
    return out.with_name(f"{out.stem}_rosbag2") if fmt == "rosbag2" else out.with_suffix(SUFFIX[fmt])


def check_output(out: Path, frames: Path) -> None:
    """--out must be an HDF5 file name outside the frames folder, not a folder (before anything is written)."""
    if out.suffix.lower() not in (".h5", ".hdf5"):
        raise SystemExit(f"error: --out {out}: expected an event file name ending in .h5 (it is written as HDF5)")
    if out.is_dir():
        raise SystemExit(f"error: --out {out}: is a folder; expected an event file name ending in .h5")
    if out.resolve().parent == frames.resolve():
        raise SystemExit(f"error: --out {out}: inside the FRAMES folder; write the events elsewhere")
    for folder in [out.parent, *out.parent.parents]:      # the nearest existing ancestor must be a folder
        if folder.exists():
            if not folder.is_dir():
                raise SystemExit(f"error: --out {out}: {folder} is not a folder, so the event file cannot be made there")
            break


def run_simulate(args: argparse.Namespace) -> int:
    from common.config import ConfigError
    from simulator.config import SimulatorConfig
    from simulator.files import simulate_files
    from simulator.sensor_presets import load_sensor

    try:
        if args.effects and not args.config:
            raise ConfigError("--effects: needs --config (the sensor that supplies the effects' values)")
        config = load_sensor(args.config, args.effects) if args.config else SimulatorConfig()
    except ConfigError as exc:
        raise SystemExit(f"error: {exc}") from None
    check_output(args.out, args.frames)
    for fmt in dict.fromkeys(args.format):      # before any work: a ROS2 bag is a folder, never overwritten
        if fmt == "rosbag2" and extra_output(args.out, fmt).exists():
            raise SystemExit(f"error: --format rosbag2: {extra_output(args.out, fmt)} exists (a ROS2 bag is a folder, "
                             "never overwritten); remove it or choose another --out")
    files = list_frames(args.frames)
    if args.timestamps:
        t_us = read_timestamps(args.timestamps, len(files))
    else:
        check_no_gaps(files)
        from eventio.representations import parse_time_us

        try:
            t0 = parse_time_us(args.t0)
        except ValueError as exc:
            raise SystemExit(f"error: --t0: {exc}") from None
        if len(files) > 1 and args.fps > 1e6:
            raise SystemExit(f"error: --fps {args.fps:g}: frames would be less than 1 us apart, and timestamps are whole "
                             "microseconds; the highest frame rate is 1e6 (or give --timestamps)")
        t_us = [t0 + int(round(k * 1e6 / args.fps)) for k in range(len(files))]
    negative = [f for f in dict.fromkeys(args.format) if f in UNSIGNED_TIME_FORMATS] if min(t_us) < 0 else []
    if negative:
        raise SystemExit(f"error: --format {negative[0]}: its times are unsigned, and the frames start at {min(t_us)} us; "
                         "give a --t0 / timestamps >= 0 or another format")
    try:
        r = simulate_files(files, t_us, args.out, config, args.seed, args.checkpoint_every)
    except ValueError as exc:    # a bad frame: one line naming it
        raise SystemExit(f"error: {exc}") from None
    print(f"{args.out}: {r.n_events} events from {len(files)} frames ({r.width}x{r.height})")
    if args.format:
        from eventio.formats import write_stream
        from eventio.h5io import read_events

        stream = read_events(args.out)
        for fmt in dict.fromkeys(args.format):
            try:
                path = write_stream(extra_output(args.out, fmt), stream, fmt)
            except ValueError as exc:
                raise SystemExit(f"error: --format {fmt}: {exc}") from None
            print(f"{path}: the same events as {fmt}")
    return 0


MAX_VIEW_SIDE = 8192          # pixels a side of a drawn event picture
MAX_VIEW_FRAMES = 100_000     # frames of one video (~25 min of drawing at ~70 frames/s)


def add_view_parser(sub) -> None:
    p = sub.add_parser("draw-events", aliases=["view"],
                       help="draw the events of a time window as a PNG, or of a sliding window as an MP4",
                       description="ON events red, OFF events blue on white, stronger with more events; each image "
                                   "labelled with its time window and the colour key. (`view` is this command's "
                                   "old name, kept until 0.3.)")
    add_main_input(p, "events", "EVENTS", "event file (.h5; other formats: `e4dgs import` first)")
    p.add_argument("--t0", default=None, help="window start (us, or with unit: 10ms, 0.5s); default: start")
    p.add_argument("--t1", default=None, help="window end (exclusive); default: end of the stream")
    p.add_argument("--out", type=Path, required=True, help=".png for one frame, .mp4 for a video")
    p.add_argument("--window", default="10ms", help="video: events shown per frame (default 10ms)")
    p.add_argument("--step", default=None, help="video: time between frames (default: the window)")
    p.add_argument("--fps", type=positive_float, default=30.0, help="video frame rate (default 30)")
    p.add_argument("--scale", type=positive_int, default=None,
                   help="enlarge each pixel this many times (default: enough for ~640 px wide, small sensors grow; "
                        "with --plain, 1)")
    p.add_argument("--plain", action="store_true", help="no time label or colour key under the image, at the sensor's "
                                                        "own pixels unless --scale")
    p.add_argument("--flow", type=Path, default=None,
                   help="draw this optical flow over the events as arrows (green): a ground-truth flow file of a scene, "
                        "ground_truth/flow/cam<k>/<j>.png (DSEC-Flow) or .npz, of the sensor's size")
    p.set_defaults(func=run_view)


def run_view(args: argparse.Namespace) -> int:
    from common.imageio import write_png
    from eventio.event_file import EventFile
    from eventio.h5io import EventFileError
    import numpy as np

    from eventio.representations import annotate, event_frame, overlay_flow, parse_time_us, save_video, window_starts

    try:
        ev = EventFile(args.events)      # every event and the ms index checked once (windows trust the index)
        if ev.n == 0:
            raise SystemExit(f"error: {args.events}: no events (an empty stream): nothing to draw")
        # the stream's own span (a recording may start anywhere, e.g. at Unix-epoch microseconds), also
        # when the file records no end (its attribute would fall back to the offset)
        first = int(ev.times(0, 1)[0]) if ev.n else ev.t_offset_us
        last = int(ev.times(ev.n - 1, ev.n)[0]) if ev.n else ev.t_offset_us
        start, end = first, max(ev.t_end_us, last) + 1
        # a plain picture is data: the sensor's own pixels unless --scale says otherwise
        scale = args.scale or (1 if args.plain else max(1, 640 // ev.width))
        if max(ev.width, ev.height) * scale > MAX_VIEW_SIDE:
            raise SystemExit(f"error: --scale {scale}: the picture would be {ev.width * scale}x{ev.height * scale} "
                             f"pixels; at most {MAX_VIEW_SIDE} a side (--scale <= {max(1, MAX_VIEW_SIDE // max(ev.width, ev.height))})")

        flow = None
        if args.flow is not None:
            from common.flow import read_flow

            flow = read_flow(args.flow)
            if flow[0].shape[:2] != (ev.height, ev.width):
                raise SystemExit(f"error: --flow {args.flow}: {flow[0].shape[1]}x{flow[0].shape[0]} pixels, the events "
                                 f"{ev.width}x{ev.height}")

        def draw(stream, a: int, b: int):
            frame = event_frame(stream)
            if flow is not None:
                frame = overlay_flow(frame, *flow, scale=scale)     # scaled by the overlay
            elif scale > 1:
                frame = np.repeat(np.repeat(frame, scale, 0), scale, 1)
            return frame if args.plain else annotate(frame, a, b)
        t0 = parse_time_us(args.t0) if args.t0 is not None else start
        t1 = parse_time_us(args.t1) if args.t1 is not None else end
        if t1 <= t0:
            raise SystemExit(f"error: --t1 ({t1} us) must be after --t0 ({t0} us)")
        suffix = args.out.suffix.lower()
        if suffix == ".png":
            stream = ev.window(t0, t1)
            write_png(args.out, draw(stream, t0, t1))
            print(f"{args.out}: {len(stream)} events in [{t0}, {t1}) us")
        elif suffix == ".mp4":
            window = parse_time_us(args.window)
            step = parse_time_us(args.step) if args.step else window
            if window <= 0 or step <= 0:
                raise SystemExit("error: --window and --step must be positive")
            n_frames = (max(t1 - t0 - window, 0) + step - 1) // step + 1
            if n_frames > MAX_VIEW_FRAMES:
                raise SystemExit(f"error: --window {args.window} / --step {args.step or args.window} over [{t0}, {t1}) us "
                                 f"makes {n_frames} frames; at most {MAX_VIEW_FRAMES} (a longer --step or a shorter "
                                 "--t0 .. --t1)")
            starts = window_starts(t0, t1, window, step)
            from tqdm import tqdm

            frames = (draw(ev.window(s, s + window), s, s + window)
                      for s in tqdm(starts, desc="view", unit="frame"))
            save_video(args.out, frames, fps=args.fps)
            print(f"{args.out}: {len(starts)} frames of {window} us every {step} us ({save_video.codec})")
        else:
            raise SystemExit(f"error: --out {args.out}: expected a .png or .mp4 file name")
    except (EventFileError, ValueError) as exc:
        raise SystemExit(f"error: {exc}") from None
    return 0
