"""The `e4dgs` command: one entry point, one subcommand per tool.

Failures the user can act on (bad input files or values, file-system errors such as a full disk or
a read-only folder, a locked output) print one line naming the file or field and exit 1; anything
else prints a one-line internal error. `--debug` (anywhere on the line, or E4DGS_DEBUG=1) shows
the traceback instead.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import warnings

from common.config import ConfigWarning
from common.deprecations import kept_until, renamed_commands


def build_parser() -> argparse.ArgumentParser:
    from benchmark.cli import add_bench_parser, add_score_parser, add_testviews_parser, add_verify_parser
    from datagen.cli import add_check_parser, add_dataset_parser, add_masks_parser
    from e2vid.cli import add_e2vid_parser, add_train_e2vid_parser
    from eventio.realism_cli import add_realism_parser
    from recon.cli import add_render_parser, add_train_parser
    from scene_format.convert_cli import add_export_parser, add_import_parser
    from simulator.cli import add_simulate_parser, add_view_parser
    from viewer.cli import add_viewer_parser

    from common.argtypes import CommandParser

    parser = argparse.ArgumentParser(prog="e4dgs", formatter_class=argparse.RawDescriptionHelpFormatter,
                                     description="Event-camera 4D reconstruction toolkit: synthetic multi-view event "
                                                 "datasets, E-4DGS and baselines, a leaderboard.",
                                     epilog="`e4dgs COMMAND --help` describes each command.")
    parser.add_argument("--debug", action="store_true", help="show tracebacks of failures")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=CommandParser)
    for add in (add_dataset_parser, add_check_parser, add_masks_parser, add_simulate_parser, add_realism_parser,
                add_train_parser, add_render_parser, add_e2vid_parser, add_train_e2vid_parser,
                add_bench_parser, add_testviews_parser, add_score_parser, add_verify_parser,
                add_viewer_parser, add_view_parser,
                add_export_parser, add_import_parser):
        add(sub)
    group_commands(parser, sub)
    return parser


# `e4dgs --help` lists the commands by the stage of the work they belong to
STAGES = (("data", ("dataset", "check", "masks", "simulate", "realism")),
          ("train", ("train", "render", "e2vid", "train-e2vid")),
          ("score", ("bench", "testviews", "score", "verify")),
          ("look", ("viewer", "draw-events")),
          ("convert", ("export", "import")))
RENAMED_COMMANDS = renamed_commands()            # old name -> new (common.deprecations)


def group_commands(parser: argparse.ArgumentParser, sub) -> None:
    """Replace argparse's flat list of commands with one list per stage (STAGES names every command)."""
    helps = {a.dest: a.help for a in sub._choices_actions}
    listed = [c for _, names in STAGES for c in names]
    if sorted(listed) != sorted(helps):
        raise RuntimeError(f"e4dgs: STAGES and the commands differ: {sorted(set(listed) ^ set(helps))}")
    width = max(map(len, listed)) + 2
    lines = []
    for stage, names in STAGES:
        lines.append(f"{stage}:")
        lines += [f"  {n:<{width}}{helps[n]}" for n in names]
    parser.description += "\n\ncommands by stage:\n" + "\n".join(lines)
    sub._choices_actions.clear()          # listed above instead


def describe_failure(exc: BaseException) -> str:
    """One line for a failure: file-system errors as 'FILE: reason', input errors as their message."""
    import yaml

    if isinstance(exc, OSError) and exc.strerror and exc.filename is not None:
        return f"{exc.filename}: {exc.strerror}"
    if isinstance(exc, yaml.YAMLError):
        return f"invalid YAML: {' '.join(str(exc).split())}"
    if isinstance(exc, (ValueError, OSError, RuntimeError, KeyError)):
        return " ".join(str(exc).split()) or type(exc).__name__
    return f"internal error ({type(exc).__name__}: {exc}); run again with --debug for the traceback"


TIME_OPTIONS = ("--t0", "--t1")      # values that may be negative times with units (-5ms)


def join_negative_values(argv: list[str]) -> list[str]:
    """`--t0 -5ms` as `--t0=-5ms`: argparse takes a value starting with '-' for an option unless it is
    a plain number, so a negative time with a unit would be refused."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] in TIME_OPTIONS and i + 1 < len(argv) and re.match(r"-\d|-\.\d", argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


OUTPUT_OPTIONS = ("out", "export")             # every other path an option names is an input
PROTECTED_INPUTS = frozenset({"FRAMES", "SCENE", "RUN", "--data", "RENDERS", "recording", "source", "EVENTS",
                              "--timestamps", "--config", "--weights", "data"})


def _option_name(dest: str, parser_actions) -> str:
    for a in parser_actions:
        if a.dest == dest:
            return a.option_strings[-1] if a.option_strings else (a.metavar if isinstance(a.metavar, str) else dest)
    return dest


def check_outputs_apart(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Before any work: no output a command writes (siblings included, from the command's
    `sibling_outputs`) is one of its inputs or lies inside an input folder it only reads."""
    from pathlib import Path

    from common.fileio import output_overlap

    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[args.command]
    outputs, inputs = [], []
    for dest, value in vars(args).items():
        values = value if isinstance(value, list) else [value]
        for v in values:
            if isinstance(v, Path):
                (outputs if dest in OUTPUT_OPTIONS else inputs).append((_option_name(dest, sub._actions), v))
    siblings = getattr(args, "sibling_outputs", None)
    if siblings is not None:
        outputs += [(f"{name} (written beside --out)", p) for name, p in siblings(args)]
    why = output_overlap(outputs, inputs, PROTECTED_INPUTS)
    if why:
        raise SystemExit(f"error: {why}")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("E4DGS_DEBUG") == "1"
    argv = join_negative_values([a for a in argv if a != "--debug"])
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command in RENAMED_COMMANDS:
        print(f"warning: `e4dgs {args.command}` is deprecated (kept until {kept_until('command', args.command)}): it is `e4dgs "
              f"{RENAMED_COMMANDS[args.command]}`", file=sys.stderr)
        args.command = RENAMED_COMMANDS[args.command]
    check_outputs_apart(args, parser)
    try:
        with warnings.catch_warnings():   # warnings as one line each; the toolkit's own every time
            warnings.filterwarnings("always", category=ConfigWarning)
            warnings.showwarning = lambda message, *_a, **_k: print(f"warning: {message}", file=sys.stderr)
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"e4dgs {args.command}: interrupted", file=sys.stderr)
        return 130
    except SystemExit:
        raise
    except Exception as exc:  # noqa: BLE001 - the one place that turns failures into one line
        if debug:
            raise
        print(f"e4dgs {args.command}: error: {describe_failure(exc)}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
