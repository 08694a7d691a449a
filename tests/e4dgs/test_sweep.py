"""Bad input as kinds, not samples: sweeps generated from the argparse parsers of `e4dgs` and of every
tools/ script, and from the config dataclasses, so that an option or field is covered the day it is
added. Each case runs a command only up to its first check.

- every numeric option: a range-checked type (no bare int / float), refusing -1, 0 where its range
  starts above 0, a huge value, inf, nan and 1e400 when parsed, naming the option (exit 2);
- every numeric config field: a range (BOUNDS) that a value outside refuses, naming the key;
- every event-file input (import, check, view, e2vid, export): empty, truncated, of the wrong kind;
- every file output: an existing folder, a read-only folder, one of the command's inputs.
Each command case asserts one clear line, a non-zero exit, nothing left behind and no input changed.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import re
import sys
import typing
from pathlib import Path

import numpy as np
import pytest

from e4dgs.cli import build_parser, main
from tests.conftest import mount_tmpfs, unmount

ROOT = Path(__file__).resolve().parents[2]
TOOLS = sorted(p.stem for p in (ROOT / "tools").glob("*.py") if p.stem not in ("__init__", "tool_cli"))


class _Captured(Exception):
    def __init__(self, parser):
        self.parser = parser


def tool_parser(name: str) -> argparse.ArgumentParser:
    """A tool's parser, caught as its main() parses (no work is done)."""
    module = importlib.import_module(f"tools.{name}")
    original = argparse.ArgumentParser.parse_args

    def capture(self, *a, **k):
        raise _Captured(self)
    argparse.ArgumentParser.parse_args = capture
    try:
        module.main([])
    except _Captured as c:
        return c.parser
    finally:
        argparse.ArgumentParser.parse_args = original
    raise AssertionError(f"tools/{name}.py: main() parsed no arguments")


def all_parsers() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    parsers = {f"e4dgs {name}": p for name, p in sub.choices.items()}
    parsers.update({f"tools/{name}": tool_parser(name) for name in TOOLS})
    return parsers


PARSERS = all_parsers()
TEXT_TYPES = {"Path", "name_list", "output_file", "existing_folder", "existing_file", "str",
              "run_spec"}   # tools/curves_alternated NAME=CONFIG:FIELD[:SCALE]: SCALE through positive_float
NUMERIC = [(cmd, a) for cmd, p in PARSERS.items() for a in p._actions
           if a.type is not None and getattr(a.type, "__name__", "") not in TEXT_TYPES]


def test_every_option_with_a_type_uses_a_checked_one():
    """A new `type=int` / `type=float` (unbounded, nan and inf accepted) fails here the day it is added."""
    bare = [f"{cmd} {a.option_strings or a.dest}" for cmd, a in NUMERIC if not hasattr(a.type, "bounds")]
    assert not bare, f"options without a range-checked type (common.argtypes / tools.tool_cli): {bare}"
    assert len(NUMERIC) >= 40                       # the sweep below sees the options it should


def bad_values(lo, hi) -> list[str]:
    values = ["-1", "inf", "nan", "1e400", str(int(hi) * 10 + 1) if isinstance(hi, int) else f"{hi * 10:g}", "1e30"]
    if lo > 0:
        values.append("0")
    if lo > 1:
        values.append(str(lo - 1))
    return values


@pytest.mark.parametrize("cmd,action", NUMERIC, ids=[f"{c}:{a.option_strings[-1] if a.option_strings else a.dest}"
                                                     for c, a in NUMERIC])
def test_every_numeric_option_refuses_out_of_range_values_by_name(cmd, action, capsys):
    parser = PARSERS[cmd]
    lo, hi = action.type.bounds
    name = action.option_strings[-1] if action.option_strings else action.dest
    for value in bad_values(lo, hi):
        if lo <= _as_number(value) <= hi:
            continue
        argv = [name, value] if action.option_strings else [value]
        if not action.option_strings:        # a positional: the ones before it are given as valid names
            argv = _positionals_before(parser, action) + argv
        with pytest.raises(SystemExit) as exc:
            parser.parse_args([f"{a}" for a in argv] if action.option_strings else argv)
        err = capsys.readouterr().err.strip().splitlines()
        assert exc.value.code == 2 and f"argument {name if action.option_strings else action.metavar or action.dest}" \
            in err[-1], (cmd, name, value, err)


def _as_number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def _positionals_before(parser, action) -> list[str]:
    out = []
    for a in parser._actions:
        if a is action:
            break
        if not a.option_strings and a.dest != "help":
            out.append("x")
    return out


# -- config dataclasses -------------------------------------------------------------------------------
def config_classes() -> list[type]:
    """Every config dataclass a user's YAML reaches: the methods' configs and what they nest, the scene,
    simulator, E2VID and benchmark configs."""
    import recon
    from benchmark.config import BenchConfig
    from e2vid.train import E2VIDTrainConfig
    from scene_format.config import SceneConfig
    from simulator.config import SimulatorConfig

    roots = [type(recon.resolve_config(m)) for m in recon.method_names()] + \
        [SceneConfig, SimulatorConfig, E2VIDTrainConfig, BenchConfig]
    seen: list[type] = []

    def walk(cls):
        if cls in seen or not dataclasses.is_dataclass(cls):
            return
        seen.append(cls)
        for tp in typing.get_type_hints(cls).values():
            for arg in (tp, *typing.get_args(tp)):
                if dataclasses.is_dataclass(arg):
                    walk(arg)
    for cls in roots:
        walk(cls)
    return seen


NUMBER_TYPES = (int, float, typing.Optional[int], typing.Optional[float], int | None, float | None)
FIELDS = [(cls, f.name, typing.get_type_hints(cls)[f.name]) for cls in config_classes() for f in dataclasses.fields(cls)
          if f.init and typing.get_type_hints(cls)[f.name] in NUMBER_TYPES]
REQUIRED = {"SceneConfig": {"name": "x", "kind": "object"}, "BenchConfig": {"cells": {"a": {"method": "d3dgs"}}}}


def test_every_numeric_config_field_has_a_range():
    missing = [f"{cls.__name__}.{name}" for cls, name, _ in FIELDS if name not in getattr(cls, "BOUNDS", {})]
    assert not missing, f"numeric config fields without a range in their class's BOUNDS: {missing}"
    assert len(FIELDS) >= 140


@pytest.mark.parametrize("cls,name,tp", FIELDS, ids=[f"{c.__name__}.{n}" for c, n, _ in FIELDS])
def test_every_numeric_config_field_refuses_values_outside_its_range_by_key(cls, name, tp):
    from common.config import ConfigError, from_dict

    lo, hi, _ = cls.BOUNDS[name]
    is_int = int in (tp, *typing.get_args(tp)) and float not in (tp, *typing.get_args(tp))
    huge = 10 ** 15 if is_int else 1e30
    values = [huge, -huge, float("inf"), float("nan")] + ([] if is_int else [1e400])
    if lo is not None and lo > -huge:
        values.append(lo - 1)
    if hi is not None and hi < huge:
        values.append(hi + 1)
    for value in values:
        if value == value and (lo is None or lo <= value) and (hi is None or value <= hi):
            continue                       # inside the range (a seed may be huge)
        with pytest.raises(ConfigError, match=rf"\b{name}\b"):
            from_dict(cls, {**REQUIRED.get(cls.__name__, {}), name: value}, cls.__name__.lower())


# -- event-file inputs: empty, truncated, of the wrong kind -------------------------------------------
@pytest.fixture(scope="module")
def good_h5(tmp_path_factory) -> Path:
    from eventio.events import EventStream, make_events
    from eventio.h5io import write_events

    rng = np.random.default_rng(0)
    n = 20_000
    s = EventStream(make_events(np.sort(rng.integers(0, 1_000_000, n)), rng.integers(0, 64, n), rng.integers(0, 48, n),
                                rng.choice([-1, 1], n)), 64, 48)
    return write_events(tmp_path_factory.mktemp("good") / "good.h5", s)


def bad_inputs(folder: Path, good: Path) -> dict[str, Path]:
    data = good.read_bytes()
    out = {"empty": folder / "empty.h5", "truncated": folder / "truncated.h5", "png": folder / "image.h5",
           "text": folder / "notes.h5"}
    out["empty"].write_bytes(b"")
    out["truncated"].write_bytes(data[: len(data) // 2])
    out["png"].write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    out["text"].write_text("this is not an event file\n")
    return out


EVENT_COMMANDS = {
    "import": lambda f, o: ["import", f, "--out", o / "out.h5"],
    "check": lambda f, o: ["check", f],
    "view": lambda f, o: ["draw-events", f, "--out", o / "v.png"],
    "e2vid": lambda f, o: ["e2vid", f, "--out", o / "frames"],
    "export": lambda f, o: ["export", f, "--format", "npz", "--out", o / "x.npz"],
}


PROGRESS = re.compile(r"^[\w /.-]+:\s+\d+%\|")      # a tqdm bar's redraw (split at its carriage returns)


def run_cli(argv, capsys) -> tuple[int, list[str]]:
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:
        rc = exc.code if isinstance(exc.code, int) else 1
        if isinstance(exc.code, str):
            print(exc.code, file=sys.stderr)
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.strip() and not PROGRESS.match(ln) and not ln.startswith("warning:")]
    if not lines and rc:                   # `check` reports what it found on stdout (its result, exit 1)
        lines = [ln for ln in captured.out.splitlines() if ln.strip()]
    return rc, lines


@pytest.mark.parametrize("command", sorted(EVENT_COMMANDS))
@pytest.mark.parametrize("kind", ["empty", "truncated", "png", "text"])
def test_every_event_file_reader_refuses_a_broken_input_in_one_line(command, kind, good_h5, tmp_path, capsys):
    inputs = bad_inputs(tmp_path, good_h5)
    out = tmp_path / "out"
    out.mkdir()
    before = inputs[kind].read_bytes()
    rc, err = run_cli(EVENT_COMMANDS[command](inputs[kind], out), capsys)
    assert rc == 1 and len(err) == 1 and str(inputs[kind]) in err[0] and "Traceback" not in err[0], err
    assert "internal error" not in err[0], err
    assert list(out.iterdir()) == [] and inputs[kind].read_bytes() == before


# -- file outputs: an existing folder, a read-only folder, one of the inputs --------------------------
FILE_OUTPUTS = {
    "import": lambda src, out: ["import", src, "--out", out],
    "export": lambda src, out: ["export", src, "--format", "npz", "--out", out],
    "view": lambda src, out: ["draw-events", src, "--out", out],
}
SUFFIX = {"import": ".h5", "export": ".npz", "view": ".png"}


@pytest.fixture
def read_only_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    if mount_tmpfs(folder, "ro,size=1m"):
        yield folder
        unmount(folder)
    else:
        folder.chmod(0o555)                      # not root: the permission bits are enough
        yield folder
        folder.chmod(0o755)


@pytest.mark.parametrize("command", sorted(FILE_OUTPUTS))
@pytest.mark.parametrize("where", ["existing-folder", "read-only-folder", "the-input"])
def test_every_file_output_that_cannot_be_written_is_refused_in_one_line(command, where, good_h5, tmp_path,
                                                                          read_only_folder, capsys):
    src = tmp_path / "in.h5"
    src.write_bytes(good_h5.read_bytes())
    before = src.read_bytes()
    out = {"existing-folder": tmp_path / f"taken{SUFFIX[command]}", "read-only-folder": read_only_folder / f"x{SUFFIX[command]}",
           "the-input": src}[where]
    if where == "existing-folder":
        out.mkdir()
    listing = sorted(p.name for p in tmp_path.rglob("*"))
    rc, err = run_cli(FILE_OUTPUTS[command](src, out), capsys)
    assert rc != 0 and len(err) == 1 and "Traceback" not in err[0] and "internal error" not in err[0], err
    assert str(out) in err[0] or out.name in err[0], err
    assert src.read_bytes() == before and sorted(p.name for p in tmp_path.rglob("*")) == listing


# -- config files and frames: empty, truncated, binary, of the wrong kind -----------------------------
CONFIG_COMMANDS = {
    "simulate --config": lambda f, d: ["simulate", d / "frames", "--fps", "1000", "--out", d / "o.h5", "--config", f],
    "train --config": lambda f, d: ["train", d / "noscene", "--config", f, "--out", d / "run"],
    "dataset --preset": lambda f, d: ["dataset", "--preset", f, "--out", d / "data"],
    "dataset --scene-config": lambda f, d: ["dataset", "--preset", "tiny", "--scene-config", f, "--out", d / "data"],
    "bench --preset": lambda f, d: ["bench", "--preset", f, "--out", d / "runs"],
    "train-e2vid --config": lambda f, d: ["train-e2vid", "--config", f, "--out", d / "e2vid"],
}
BROKEN_YAML = {"empty-list": "[]\n", "truncated": "train: {iterations: [1, 2\n", "binary": bytes(range(256)) * 2,
               "scalar": "just words\n", "tabs": "a:\n\tb: 1\n"}


@pytest.mark.parametrize("command", sorted(CONFIG_COMMANDS))
@pytest.mark.parametrize("kind", sorted(BROKEN_YAML))
def test_every_config_input_refuses_a_broken_file_in_one_line(command, kind, tmp_path, capsys):
    import cv2

    (tmp_path / "frames").mkdir()
    for k in range(2):
        cv2.imwrite(str(tmp_path / "frames" / f"{k}.png"), np.full((8, 8, 3), 40 * k, np.uint8))
    f = tmp_path / f"{kind}.yaml"
    content = BROKEN_YAML[kind]
    f.write_bytes(content if isinstance(content, bytes) else content.encode())
    listing = sorted(p.name for p in tmp_path.rglob("*"))
    rc, err = run_cli(CONFIG_COMMANDS[command](f, tmp_path), capsys)
    assert rc in (1, 2) and len(err) == 1 and "Traceback" not in err[0] and "internal error" not in err[0], err
    assert f.name in err[0] or "noscene" in err[0], err
    assert sorted(p.name for p in tmp_path.rglob("*")) == listing


@pytest.mark.parametrize("kind", ["empty", "truncated", "text", "one-pixel"])
def test_simulate_refuses_a_broken_frame_naming_it(kind, tmp_path, capsys):
    import cv2

    frames = tmp_path / "frames"
    frames.mkdir()
    for k in range(3):
        cv2.imwrite(str(frames / f"{k:03d}.png"), np.full((12, 16, 3), 60 + 40 * k, np.uint8))
    bad = frames / "001.png"
    data = bad.read_bytes()
    bad.write_bytes({"empty": b"", "truncated": data[: len(data) // 2], "text": b"not an image\n",
                     "one-pixel": cv2.imencode(".png", np.zeros((1, 1, 3), np.uint8))[1].tobytes()}[kind])
    rc, err = run_cli(["simulate", frames, "--fps", "1000", "--out", tmp_path / "ev.h5"], capsys)
    assert rc == 1 and len(err) == 1 and "001.png" in err[0] and "internal error" not in err[0], err
    assert not (tmp_path / "ev.h5").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["frames"]


def test_a_seed_list_is_distinct_seeds_in_range():
    from common.argtypes import seed_list

    assert seed_list("0, 1,2") == (0, 1, 2) and seed_list("7") == (7,)
    for bad in ("0,,1", "1,1", "-1", "0,1.5", "", "a"):
        with pytest.raises(argparse.ArgumentTypeError):
            seed_list(bad)
