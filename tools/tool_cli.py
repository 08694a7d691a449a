"""What every tools/ script shares with the `e4dgs` command: range-checked option types (common.argtypes;
no bare int / float, so 0, -1, a huge value, inf and nan are refused when parsed, naming the option),
outputs checked before any work, and failures as one line (exit 1; `--debug` or E4DGS_DEBUG=1 shows the
traceback)."""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Callable

from common.argtypes import float_in, int_in, nonnegative_int, positive_float, positive_int  # noqa: F401 (re-exported)

camera_index = int_in(0, 63, "a camera index")


def output_file(text: str) -> Path:
    """An output file's path, checked when parsed: not a folder, and its folder exists or can be made
    (the nearest existing ancestor is a writable folder), so a run never ends unable to save."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{path} is a folder; expected a file name")
    folder = next((d for d in [path.parent, *path.parent.parents] if d.exists()), Path("."))
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"{folder} is not a folder, so {path} cannot be written")
    if not os.access(folder, os.W_OK):
        raise argparse.ArgumentTypeError(f"{folder} is not writable, so {path} cannot be written")
    return path


def existing_folder(text: str) -> Path:
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{path}: {'not a folder' if path.exists() else 'no such folder'}")
    return path


def existing_file(text: str) -> Path:
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{path}: {'not a file' if path.exists() else 'no such file'}")
    return path


def write_json(path: Path, doc) -> None:
    """A tool's figures as JSON (NumPy scalars as numbers, anything else as text), written atomically."""
    import json

    from common.fileio import write_text_atomic

    write_text_atomic(path, json.dumps(doc, indent=1, default=lambda v: v.item() if hasattr(v, "item") else str(v)))


def run_tool(main: Callable[..., int], argv: list[str] | None = None) -> int:
    """Run a tool's main(argv) as `e4dgs` runs a command: a failure is one line naming what is wrong."""
    from e4dgs.cli import describe_failure

    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("E4DGS_DEBUG") == "1"
    argv = [a for a in argv if a != "--debug"]
    name = Path(sys.argv[0]).stem if sys.argv and sys.argv[0] else "tool"
    try:
        return int(main(argv) or 0)
    except KeyboardInterrupt:
        print(f"{name}: interrupted", file=sys.stderr)
        return 130
    except SystemExit:
        raise
    except Exception as exc:  # noqa: BLE001 - the one place a tool turns failures into one line
        if debug:
            raise
        print(f"{name}: error: {describe_failure(exc)}", file=sys.stderr)
        return 1
