"""The `e4dgs` command: one entry point, one subcommand per tool."""
from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    from benchmark.cli import add_bench_parser
    from datagen.cli import add_dataset_parser
    from e2vid.cli import add_e2vid_parser, add_train_e2vid_parser
    from recon.cli import add_render_parser, add_train_parser
    from simulator.cli import add_simulate_parser, add_view_parser

    parser = argparse.ArgumentParser(prog="e4dgs", description="Event-camera 4D reconstruction toolkit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_simulate_parser(sub)
    add_view_parser(sub)
    add_dataset_parser(sub)
    add_train_parser(sub)
    add_render_parser(sub)
    add_train_e2vid_parser(sub)
    add_e2vid_parser(sub)
    add_bench_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
