"""What the viewer opens: a generated scene folder (a dataset) or a training folder (a run, with the
scene it was trained on when that folder is still there).

    src = open_source("runs/quick/hinge/e4dgs")      # the run folder e4dgs-<hash>, found by its prefix
    src.model, src.dataset, src.label
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from scene_format.reader import DatasetError, SceneDataset
from recon.model import DynamicGaussians, load


class ViewerError(ValueError):
    """A path the viewer cannot show (one line naming it and what was expected)."""


@dataclass
class Source:
    path: Path
    label: str                                # shown in the page: "e4dgs (hinge_x37.6)" or "dataset hinge"
    dataset: SceneDataset | None = None
    model: DynamicGaussians | None = None
    note: str = ""                            # why a run has no dataset beside it, if it has none


def _is_run(p: Path) -> bool:
    return p.is_dir() and (p / "model.pt").is_file()


def resolve_run_prefix(p: Path) -> Path:
    """`runs/quick/hinge/e4dgs` names the run folder `e4dgs-<fingerprint>` when it is the only one."""
    parent = p.parent
    if not parent.is_dir():
        return p
    matches = sorted(c for c in parent.iterdir() if c.name.startswith(p.name + "-") and _is_run(c))
    if len(matches) == 1:
        return matches[0]
    if len(matches) > 1:
        raise ViewerError(f"{p}: several runs match ({', '.join(m.name for m in matches)}); give one of them")
    return p


def _run_dataset(run: Path) -> tuple[SceneDataset | None, str]:
    info = run / "run.json"
    try:
        scene_dir = json.loads(info.read_text()).get("scene_dir")
    except (OSError, ValueError):
        return None, f"{info}: missing or unreadable, so the scene it was trained on is unknown"
    if not scene_dir:
        return None, f"{info}: names no scene_dir"
    try:
        return SceneDataset(scene_dir), ""
    except DatasetError as exc:
        return None, f"its scene is not readable ({exc})"


def open_source(path: str | Path) -> Source:
    """The dataset or run at `path`; ViewerError (one line) for anything else."""
    p = Path(path)
    if not p.exists():
        p = resolve_run_prefix(p)
    if not p.exists():
        raise ViewerError(f"{p}: no such folder (expected a dataset scene such as data/quick/hinge or a run such "
                          "as runs/quick/hinge/e4dgs-<hash>)")
    if p.is_dir() and (p / "manifest.json").is_file():
        try:
            ds = SceneDataset(p)
        except DatasetError as exc:
            raise ViewerError(str(exc)) from None
        return Source(p, f"dataset {p.name}", dataset=ds)
    if _is_run(p):
        try:
            model = load(p)
        except (OSError, ValueError) as exc:
            raise ViewerError(str(exc)) from None
        ds, note = _run_dataset(p)
        scene = ds.dir.name if ds is not None else (model.meta.scene or "?")
        return Source(p, f"{model.meta.method} ({scene}, {len(model):,} Gaussians)", dataset=ds, model=model, note=note)
    if p.is_dir():
        runs = sorted(c.name for c in p.iterdir() if _is_run(c))
        if runs:
            raise ViewerError(f"{p}: a folder of runs, not a run: give one of {', '.join(runs)}")
    raise ViewerError(f"{p}: neither a dataset scene (a folder with manifest.json, made by `e4dgs dataset`) nor a "
                      "trained run (a folder with model.pt, made by `e4dgs train` or `e4dgs bench`)")
