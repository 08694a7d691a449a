"""argparse value types that range-check at parse time (argparse then names the option and exits 2)."""
from __future__ import annotations

import argparse
import math


def _number(kind, text: str):
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'an integer' if kind is int else 'a number'}, got {text!r}") from None
    if kind is float and not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


MAX_COUNT = 10 ** 9       # no count, size or duration an option takes means anything beyond a billion
MAX_NUMBER = 1e9


def positive_int(text: str) -> int:
    value = _number(int, text)
    if not 1 <= value <= MAX_COUNT:
        raise argparse.ArgumentTypeError(f"expected an integer in 1 .. {MAX_COUNT:,}, got {text!r}")
    return value


def nonnegative_int(text: str) -> int:
    value = _number(int, text)
    if not 0 <= value <= MAX_COUNT:
        raise argparse.ArgumentTypeError(f"expected an integer in 0 .. {MAX_COUNT:,}, got {text!r}")
    return value


def _ranged(kind, lo, hi, what: str):
    """An argparse type: a finite `kind` (int or float) in lo .. hi; `what` says what it counts."""
    word = "an integer" if kind is int else "a number"
    shown = (lambda v: f"{v:,}") if kind is int else (lambda v: f"{v:g}")

    def parse(text: str):
        value = _number(kind, text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected {word} in {shown(lo)} .. {shown(hi)}"
                                             f"{f' ({what})' if what else ''}, got {text!r}")
        return value
    parse.__name__ = f"{kind.__name__}_in_{lo:g}_{hi:g}"
    parse.bounds = (lo, hi)
    return parse


def int_in(lo: int, hi: int, what: str = ""):
    """An argparse type: an integer in lo .. hi."""
    return _ranged(int, lo, hi, what)


def float_in(lo: float, hi: float, what: str = ""):
    """An argparse type: a finite number in [lo, hi]."""
    return _ranged(float, lo, hi, what)


port_int = int_in(0, 65535, "a TCP port; 0 picks a free one")


SEED_MAX = 2 ** 63 - 1      # what the generators take and HDF5 / JSON store as a 64-bit integer


def seed_int(text: str) -> int:
    """A random seed: an integer in 0 .. 2^63 - 1."""
    value = _number(int, text)
    if not 0 <= value <= SEED_MAX:
        raise argparse.ArgumentTypeError(f"expected an integer seed in 0 .. {SEED_MAX}, got {text!r}")
    return value


seed_int.bounds = (0, SEED_MAX)


def seed_list(text: str) -> tuple[int, ...]:
    """Comma-separated distinct seeds (each an integer in 0 .. 2^63 - 1): '0,1,2' -> (0, 1, 2)."""
    items = [x.strip() for x in text.split(",")]
    if not all(items):
        raise argparse.ArgumentTypeError(f"expected distinct integer seeds separated by commas, got {text!r}")
    seeds = tuple(seed_int(x) for x in items)
    if len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"a seed given twice in {text!r}")
    return seeds


seed_list.bounds = (0, SEED_MAX)


def name_list(text: str) -> list[str]:
    """A comma-separated list of names (scenes, cells, studies): at least one, none blank."""
    names = [x.strip() for x in text.split(",")]
    if not any(names):
        raise argparse.ArgumentTypeError(f"expected one or more comma-separated names, got {text!r}")
    if not all(names):
        raise argparse.ArgumentTypeError(f"a blank name between commas in {text!r}")
    return names


def positive_float(text: str) -> float:
    value = _number(float, text)
    if not 0 < value <= MAX_NUMBER:
        raise argparse.ArgumentTypeError(f"expected a positive number up to {MAX_NUMBER:g}, got {text!r}")
    return value


positive_int.bounds, nonnegative_int.bounds, positive_float.bounds = (1, MAX_COUNT), (0, MAX_COUNT), (0.0, MAX_NUMBER)


def add_ray_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """--ray [ADDRESS], --ray-retries, --ray-cpus, --ray-local-cpus: run `what` as Ray tasks."""
    g = p.add_argument_group("Ray (optional: pip install 'e4dgs-toolkit[ray]')")
    g.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help=f"run {what} as Ray tasks: on the cluster at ADDRESS ('auto', 'ray://host:10001'), or on a "
                        "Ray started on this machine when no address is given. Data and output folders must be "
                        "paths every node sees.")
    g.add_argument("--ray-retries", type=nonnegative_int, default=2, metavar="N",
                   help="re-runs of a task that fails or whose worker dies, before it is reported failed (default 2)")
    g.add_argument("--ray-cpus", type=positive_float, default=1.0, metavar="N",
                   help="CPUs each task asks for (its threads; default 1)")
    g.add_argument("--ray-local-cpus", type=positive_int, default=None, metavar="N",
                   help="CPUs of the Ray started on this machine (default: all)")


def ray_options(args: argparse.Namespace):
    """The common.taskpool.RayOptions the --ray arguments ask for, or None without --ray."""
    if args.ray is None:
        return None
    from common.taskpool import RayOptions

    return RayOptions(address=args.ray, retries=args.ray_retries, local_cpus=args.ray_local_cpus,
                      cpus_per_task=args.ray_cpus)


# ---- one pattern for every command: the main input is the first positional argument ----------------

class DeprecatedOption(argparse.Action):
    """An option spelling kept for one release (0.2 -> 0.3): stores into the new option's dest and
    prints one `warning:` line naming the new spelling."""

    def __init__(self, option_strings, dest, instead: str = "", **kwargs):
        self.instead = instead
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        import sys

        from common.deprecations import ENDS

        print(f"warning: {option_string} is deprecated (kept until {ENDS}): {self.instead}", file=sys.stderr)
        setattr(namespace, self.dest, values)


class CommandParser(argparse.ArgumentParser):
    """A subcommand's parser: its main input (`add_main_input`) is required as the first positional
    argument or by its old option spelling, and is named when missing."""

    main_inputs: list[tuple[str, str]]

    def parse_known_args(self, args=None, namespace=None):
        ns, extras = super().parse_known_args(args, namespace)
        for dest, metavar in getattr(self, "main_inputs", []):
            old = getattr(ns, f"_{dest}_option", None)
            if hasattr(ns, f"_{dest}_option"):
                delattr(ns, f"_{dest}_option")
            if old is not None:
                if getattr(ns, dest, None) is not None:
                    self.error(f"{metavar} given twice (as the first argument and by its old option)")
                setattr(ns, dest, old)
            if getattr(ns, dest, None) is None:
                self.error(f"the following arguments are required: {metavar}")
        return ns, extras


def add_main_input(p: argparse.ArgumentParser, dest: str, metavar: str, help: str, old_option: str | None = None,
                   type=None) -> None:
    """The command's main input as its first positional argument (`e4dgs train data/quick/lego`); an
    earlier option spelling (`--scene`) keeps working for one release with a deprecation line."""
    from pathlib import Path

    type = type or Path
    p.add_argument(dest, nargs="?", type=type, metavar=metavar, help=help)
    if old_option:
        p.add_argument(old_option, dest=f"_{dest}_option", type=type, action=DeprecatedOption, help=argparse.SUPPRESS,
                       instead=f"give the {metavar} as the first argument")
    if not hasattr(p, "main_inputs"):
        p.main_inputs = []
    p.main_inputs.append((dest, metavar))
