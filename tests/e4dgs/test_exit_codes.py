"""Exit codes: every command and tool that takes an input file or folder, given one that does not
exist, prints one error naming it and exits non-zero, leaving no output behind. The inputs are found
from the parsers themselves (tests/e4dgs/test_sweep.py's PARSERS), so a new command or tool is swept
without being listed; the test fails on a parser with an input it does not know how to fill."""
import argparse
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from tests.e4dgs.test_sweep import PARSERS, ROOT, run_cli

# What each command's other required options get (a plausible value; the missing input must fail first).
FILLERS = {"fps": "3000", "format": "npz", "name": "mine", "inputs": "events", "method": "e4dgs", "config": "e4dgs/quick",
           "recipe": "quick=e4dgs/quick:mlp"}
# Options and positionals that are outputs or optional settings, not inputs read.
OUTPUTS = {"out", "json", "picture", "export"}
# Inputs that are not files: left out of the sweep, each with why.
NOT_SWEPT = {
    "e4dgs dataset": "its paths are outputs, or scene files covered by the scene-file tests",
    "e4dgs bench": "--data is where the dataset is generated when missing (an output too)",
    "e4dgs train-e2vid": "trains from synthetic data; --config is covered by the config sweep",
    "tools/bench_adaptive": "--out is an output",
    "tools/bench_ray": "--data is where its dataset is made when missing (an output too)",
}
# Output names of the commands that check an output's suffix (the missing input must be what fails).
OUT_NAME = {"e4dgs simulate": "result.h5", "e4dgs import": "result.h5", "e4dgs export": "result.npz",
            "e4dgs draw-events": "result.png", "e4dgs view": "result.png"}


def input_actions(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The actions that name a file or folder the command reads."""
    out = []
    for a in parser._actions:
        if a.dest == "help" or a.dest.startswith("_") or a.dest in OUTPUTS:
            continue
        typename = getattr(a.type, "__name__", "")
        path_like = typename in ("Path", "existing_file", "existing_folder")
        if path_like and (not a.option_strings or a.required or a.dest in ("data", "events", "clip", "run", "scene")):
            out.append(a)
        elif a.required and a.option_strings and a.dest in ("run", "scene"):
            out.append(a)
    return out


CASES = [(cmd, a.dest) for cmd, p in PARSERS.items() if cmd not in NOT_SWEPT for a in input_actions(p)]


def argv_for(cmd: str, missing_dest: str, missing: Path, out: Path) -> list[str]:
    parser = PARSERS[cmd]
    inputs = {a.dest for a in input_actions(parser)}
    argv: list[str] = []
    for group in parser._mutually_exclusive_groups:     # a required choice: its first option
        if group.required:
            a = group._group_actions[0]
            argv += [a.option_strings[-1], FILLERS[a.dest]]
    for a in parser._actions:
        if a.dest == "help" or a.dest.startswith("_"):
            continue
        value = None
        if a.dest == missing_dest:
            value = str(missing)
        elif a.dest in OUTPUTS and (a.required or not a.option_strings):
            value = str(out / OUT_NAME.get(cmd, "result"))
        elif a.dest in inputs:
            value = str(missing)          # every input missing: the first one read fails
        elif a.required or (not a.option_strings and a.nargs not in ("?", "*")):
            value = FILLERS.get(a.dest)
            if value is None:
                raise AssertionError(f"{cmd}: no filler for its required {a.dest!r}: add one to FILLERS")
        if value is None:
            continue
        if a.option_strings:
            argv += [a.option_strings[-1], value]
        else:
            argv.append(value)
    return argv


def test_every_parser_with_an_input_is_swept():
    assert len(CASES) >= 20, CASES
    swept = {cmd for cmd, _ in CASES}
    for cmd, parser in PARSERS.items():
        if input_actions(parser) and cmd not in NOT_SWEPT:
            assert cmd in swept


@pytest.mark.parametrize("cmd,dest", CASES, ids=[f"{c}:{d}" for c, d in CASES])
def test_a_missing_input_is_one_error_and_a_non_zero_exit(cmd, dest, tmp_path, capsys):
    missing = tmp_path / "nothing_here"
    out = tmp_path / "out"
    argv = argv_for(cmd, dest, missing, out)
    if cmd in ("e4dgs viewer", "tools/bench_viewer"):           # a server if it went wrong: a child with a timeout
        args = ([sys.executable, "-m", "e4dgs.cli", cmd.split(" ", 1)[1], *argv] if cmd.startswith("e4dgs")
                else [sys.executable, "-m", f"tools.{cmd.split('/')[1]}", *argv])
        r = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, timeout=120)
        rc, lines = r.returncode, [ln for ln in (r.stderr + r.stdout).splitlines() if ln.strip()]
    elif cmd.startswith("e4dgs "):
        rc, lines = run_cli([cmd.split(" ", 1)[1], *argv], capsys)
    else:
        from tools.tool_cli import run_tool

        module = importlib.import_module(f"tools.{cmd.split('/')[1]}")
        try:
            rc = run_tool(module.main, argv)
        except SystemExit as exc:
            rc = exc.code if isinstance(exc.code, int) else 1
            if isinstance(exc.code, str):
                print(exc.code, file=sys.stderr)
        captured = capsys.readouterr()
        lines = [ln for ln in (captured.err + captured.out).splitlines() if ln.strip()]
    text = "\n".join(lines)
    assert rc not in (0, None), f"{cmd} {argv}: exit {rc}\n{text}"
    assert "nothing_here" in text, f"{cmd}: the error does not name the missing input:\n{text}"
    assert "Traceback" not in text and "internal error" not in text, text
    assert not out.exists() or not any(out.rglob("*")), f"{cmd}: left {sorted(out.rglob('*'))}"
