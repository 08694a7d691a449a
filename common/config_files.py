"""Where the shipped configs live, how a name finds one, and the old names that still work.

    configs/datasets/<preset>.yaml        dataset presets          (`e4dgs dataset --preset quick`)
    configs/sensors/<name>.yaml           event sensors             (`e4dgs simulate --config realistic`)
    configs/recipes/<method>/<name>.yaml  training recipes          (`e4dgs train --method e4dgs --config quick`)
    configs/bench/<preset>.yaml           leaderboard presets       (`e4dgs bench --preset quick`)

Folders named in `E4DGS_CONFIG_PATH` (separated by the path separator) are searched after the
shipped ones, with the same sub-folders: a lab's own presets, or the test suite's fixtures.

Names used before 0.2 (`configs/dataset_quick.yaml`, `configs/recon/bench/e4dgs_quick.yaml`,
`d3dgs_quick`, ...) keep working until 0.3: they resolve to the new file and print a deprecation
line naming it.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path

from common.config import ConfigWarning
from common.deprecations import CONFIG_NAMES, kept_until
from common.provenance import REPO

KINDS = ("datasets", "sensors", "recipes", "bench")

# old name (a path relative to the repository, or a bare name) -> (kind, new name): common.deprecations
DEPRECATED = CONFIG_NAMES


_WARNED: set[str] = set()       # old names already reported in this process (one line each)


class ShadowedName(ConfigWarning):
    """A config name found in more than one search folder (printed as one `warning:` line)."""


_SHADOWED: set[tuple[str, str]] = set()      # names already reported in this process


class DeprecatedName(ConfigWarning, FutureWarning):
    """An old config name that still resolves (printed as one `warning:` line by the command line)."""


def search_dirs(kind: str) -> list[Path]:
    """configs/<kind>/ of the toolkit, then <dir>/<kind>/ of every folder in E4DGS_CONFIG_PATH."""
    if kind not in KINDS:
        raise ValueError(f"unknown config kind {kind!r}")
    extra = [Path(p) for p in os.environ.get("E4DGS_CONFIG_PATH", "").split(os.pathsep) if p]
    return [REPO / "configs" / kind] + [d / kind for d in extra]


def shipped_names(kind: str) -> list[str]:
    """The names a `kind` config is found by (recipes as <method>/<name>), sorted, without repeats."""
    names = set()
    for d in search_dirs(kind):
        names |= {str(p.relative_to(d).with_suffix("")) for p in d.rglob("*.yaml")}
    return sorted(names)


def deprecated_key(given: str | os.PathLike) -> str | None:
    """The registry's key of an old name or path (absolute paths inside the checkout too), else None."""
    text = str(given)
    path = Path(text)
    if path.is_absolute():
        try:
            text = str(path.resolve().relative_to(REPO))
        except ValueError:
            return None
    text = text.removeprefix("./")
    if text in DEPRECATED:
        return text
    return text.removesuffix(".yaml") if "/" not in text and text.removesuffix(".yaml") in DEPRECATED else None


def deprecated_target(given: str | os.PathLike) -> tuple[str, str] | None:
    """(kind, new name) for an old name or path, else None."""
    key = deprecated_key(given)
    return DEPRECATED[key] if key is not None else None


def find(kind: str, name: str | os.PathLike, method: str | None = None) -> Path | None:
    """The file a config name means: an existing path as given; an old name (with a deprecation
    line); else <dir>/<name>.yaml in the search folders, for recipes also <dir>/<method>/<name>.yaml.
    None when nothing matches."""
    path = Path(name)
    if path.is_file():
        return path
    old = deprecated_target(name)
    if old is not None:
        new_kind, new = old
        found = find(new_kind, new)
        if found is not None and str(name) not in _WARNED:
            _WARNED.add(str(name))
            warnings.warn(f"config {str(name)!r} is an old name (kept until {kept_until('config', deprecated_key(name))}): "
                          f"use {new!r} ({_rel(found)})",
                          DeprecatedName, stacklevel=2)
        if found is not None:
            return found
    if path.is_absolute():
        return None
    stem = path.with_suffix("") if path.suffix in (".yaml", ".yml") else path
    if not path.suffix and len(path.parts) > 1 and (REPO / path.with_suffix(".yaml")).is_file():
        return REPO / path.with_suffix(".yaml")
    if (REPO / path).is_file():
        return REPO / path                               # a checkout path given from another folder
    matches = [c for d in search_dirs(kind)
               for c in ([d / method / f"{stem}.yaml"] if method and len(stem.parts) == 1 else []) + [d / f"{stem}.yaml"]
               if c.is_file()]
    if len(matches) > 1 and (kind, str(name)) not in _SHADOWED:
        _SHADOWED.add((kind, str(name)))
        warnings.warn(f"config {str(name)!r} names {len(matches)} files: {_rel(matches[0])} is used, "
                      f"{', '.join(_rel(m) for m in matches[1:])} is shadowed (the shipped configs come first, then "
                      "E4DGS_CONFIG_PATH in order); give a path to use another", ShadowedName, stacklevel=2)
    return matches[0] if matches else None


def _rel(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(REPO))
    except ValueError:
        return str(path)
