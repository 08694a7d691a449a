"""`e4dgs train-e2vid` and `e4dgs e2vid`."""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
from pathlib import Path

from common.argtypes import add_main_input, nonnegative_int, positive_float, positive_int

MIN_EVENTS_PER_WINDOW = 100     # fewer than this per window is noise, and a run of hours
LONG_RUN_WINDOWS = 2000         # more windows than this: say how long it will take before starting


def add_train_e2vid_parser(sub) -> None:
    p = sub.add_parser("train-e2vid", help="train E2VID / FireNet on simulated event sequences",
                       description="Train an events-to-video network on sequences the project's simulator makes on "
                                   "the fly. Resumes from OUT/checkpoint.pt when started again with the same config; "
                                   "then evaluates on held-out simulated sequences against the high-pass filter.")
    p.add_argument("--config", type=Path, default=None, help="E2VIDTrainConfig YAML (default: the defaults)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value (e.g. iterations=200); repeatable")
    p.add_argument("--out", type=Path, default=Path("runs/e2vid"), help="training folder (default runs/e2vid)")
    p.add_argument("--export", type=Path, default=None, help="also write the weights (official layout) here")
    p.add_argument("--val-sequences", type=positive_int, default=8, help="held-out simulated sequences for the report")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run_train_e2vid)


def run_train_e2vid(args: argparse.Namespace) -> int:
    from e2vid.evaluate import evaluate_heldout
    from e2vid.train import E2VIDTrainConfig, E2VIDTrainer
    from common.config import ConfigError, build_config, parse_set
    from common.fileio import write_text_atomic

    try:
        cfg = build_config(E2VIDTrainConfig, args.config, parse_set(args.overrides))
        trainer = E2VIDTrainer(cfg, args.out, progress=not args.no_progress)
        trainer.run()
        selected = trainer.use_best()
        net = trainer.net
    except (ConfigError, ValueError, FileNotFoundError) as exc:
        raise SystemExit(f"error: {exc}") from None
    report = evaluate_heldout(net, n_sequences=args.val_sequences, progress=not args.no_progress)
    report["selected"] = selected
    write_text_atomic(args.out / "report.json", json.dumps(report, indent=1))
    if args.export:
        from e2vid.report import training_report_md
        from common.config import dump_config

        trainer.export(args.export, {"heldout": report})
        overrides = " ".join(f"--set {o}" for o in args.overrides)
        write_text_atomic(args.export.with_name("README.md"), training_report_md(
            cfg.arch, trainer.iteration, trainer.wall_s, trainer.log, report, dump_config(cfg),
            f"e4dgs train-e2vid {overrides} --export {args.export}".replace("  ", " ")))
    print(f"train-e2vid: {cfg.arch}, {trainer.iteration} iterations, {trainer.wall_s:.0f} s; held-out "
          f"PSNR {report['network']['psnr']:.2f} dB raw / {report['network_corrected']['psnr']:.2f} corrected, "
          f"high-pass filter {report['hpf_corrected']['psnr']:.2f} corrected -> {args.out}")
    return 0


def add_e2vid_parser(sub) -> None:
    p = sub.add_parser("e2vid", help="reconstruct intensity video from an event file",
                       description="Run an E2VID/FireNet network over an event file (DSEC-layout .h5) and write "
                                   "PNG frames plus timestamps.txt.")
    add_main_input(p, "events", "EVENTS", "event file, e.g. data/quick/lego/events/cam0.h5", old_option="--events")
    p.add_argument("--out", type=Path, required=True, help="output folder for frames")
    p.add_argument("--weights", type=Path, default=None, help="network file (default: the shipped weights)")
    p.add_argument("--dt-ms", type=positive_float, default=None,
                   help="one frame every DT ms, at least 0.001 (timestamps are whole microseconds); the last frame "
                        "is at the stream's end (default: 30 frames over the stream)")
    p.add_argument("--events-per-window", type=nonnegative_int, default=0,
                   help=f"split windows holding more events (0: never; else at least {MIN_EVENTS_PER_WINDOW})")
    p.set_defaults(func=run_e2vid)


def estimated_seconds(net, width: int, height: int, n_windows: int) -> float:
    """n_windows x the measured time of one network pass at this size (the second of two)."""
    import time

    import torch

    from e2vid.networks import Reconstructor

    recon = Reconstructor(net)
    x = torch.zeros(net.cfg.num_bins, height, width)
    with torch.no_grad():
        recon(x)
        t = time.perf_counter()
        recon(x)
    return n_windows * (time.perf_counter() - t)


def run_e2vid(args: argparse.Namespace) -> int:
    import numpy as np

    from e2vid.networks import Reconstructor
    from e2vid.official import CheckpointError, load_checkpoint
    from e2vid.reconstruct import frame_times_us, reconstruct_frames
    from e2vid.weights import default_weights_path
    from common.fileio import write_text_atomic
    from common.imageio import write_png
    from eventio.event_file import EventFile
    from eventio.h5io import EventFileError

    try:
        net, _ = load_checkpoint(args.weights or default_weights_path())
        with EventFile(args.events) as ev:
            stream = ev.stream()
    except (CheckpointError, EventFileError, FileNotFoundError, OSError) as exc:
        raise SystemExit(f"error: {exc}") from None
    if len(stream) == 0:
        raise SystemExit(f"error: {args.events}: no events")
    if args.dt_ms is not None and args.dt_ms < 0.001:
        raise SystemExit(f"error: --dt-ms {args.dt_ms:g}: below the event timestamps' resolution of 1 us "
                         "(the smallest interval is 0.001)")
    if 0 < args.events_per_window < MIN_EVENTS_PER_WINDOW:
        raise SystemExit(f"error: --events-per-window {args.events_per_window}: a window must hold at least "
                         f"{MIN_EVENTS_PER_WINDOW} events for the network to see anything (0: never split)")
    t0, t1 = int(stream.t_us[0]), int(stream.t_us[-1])
    times = frame_times_us(t0, t1, args.dt_ms * 1000 if args.dt_ms else None)
    n_windows = len(times) + (len(stream) // args.events_per_window if args.events_per_window else 0)
    if n_windows > LONG_RUN_WINDOWS:
        seconds = estimated_seconds(net, stream.width, stream.height, n_windows)
        print(f"e4dgs e2vid: warning: {n_windows:,} windows, about {seconds / 60:.0f} min at the measured "
              f"{1e3 * seconds / n_windows:.0f} ms each; a larger --dt-ms or --events-per-window is faster "
              "(Ctrl-C stops it)", file=sys.stderr)
    frames = reconstruct_frames(Reconstructor(net), stream.events, stream.width, stream.height, times,
                                args.events_per_window or None, net.cfg.num_bins, progress=True)
    made = [d for d in [args.out, *args.out.parents] if not d.exists()]
    written = []
    try:
        args.out.mkdir(parents=True, exist_ok=True)
        for k, f in enumerate(frames):
            written.append(write_png(args.out / f"{k:05d}.png", np.round(f * 255).astype(np.uint8)))
        write_text_atomic(args.out / "timestamps.txt", "".join(f"{t}\n" for t in times))
    except BaseException:      # a full disk, a kill: no partial video is left that looks complete
        for p in written:
            p.unlink(missing_ok=True)
        for d in made:
            with contextlib.suppress(OSError):
                d.rmdir()
        raise
    print(f"e2vid: {len(frames)} frames ({stream.width}x{stream.height}) from {len(stream)} events -> {args.out}")
    return 0
