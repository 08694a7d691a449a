"""What a scene's generation measures from its geometry before it renders (the blur levels' exposures
and windows, the test views' dynamic masks, the render schedule), kept beside its checkpoint so a
resumed run does not measure it again: in a paper-preset room that measurement is 15-27 minutes per
start on one core (docs/design/dataset.md).

The cache is one atomic .npz (common.checkpoint.JobCheckpoint, no pickles) tied to the scene's config
fingerprint and this module's FORMAT; any mismatch or unreadable file is dropped and the geometry
measured again. Per plan (the scene, then its speed variants, keyed by their folder names):

    <plan>/blur__present                  0 / 1
    <plan>/blur__levels, n_frames, target_px (nan: declared by exposure), fit_factor   [L]
    <plan>/blur__manifest                 JSON text
    <plan>/blur__median__<level>          [C, J] float
    <plan>/win__<level>                   [W, 3] int (blurred frame j, first, last)
    dynamic__views [V, 2] int (camera, kept index); dynamic__masks [V, H, W] bool (shared by every plan)
    rendered [R] int; render_plan JSON text (shared)
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from common.checkpoint import JobCheckpoint
from datagen.blur_geometry import BlurReport, LevelChoice

FORMAT = "geometry-1"
FILE_NAME = ".generate.geometry.npz"


def _json_default(v):
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON: {type(v).__name__}")


def _blur_state(report: BlurReport | None, p: str) -> dict:
    if report is None:
        return {f"{p}blur__present": 0}
    state = {f"{p}blur__present": 1,
             f"{p}blur__levels": np.array([c.level for c in report.choices], dtype=str),
             f"{p}blur__n_frames": np.array([c.n_frames for c in report.choices], dtype=np.int64),
             f"{p}blur__target_px": np.array([np.nan if c.target_px is None else c.target_px for c in report.choices]),
             f"{p}blur__fit_factor": np.array([c.fit_factor for c in report.choices], dtype=np.float64),
             f"{p}blur__manifest": json.dumps(report.manifest, default=_json_default),
             f"{p}blur__window_levels": np.array(list(report.windows), dtype=str),
             f"{p}blur__median_levels": np.array(list(report.view_median_px), dtype=str)}
    for i, (level, wins) in enumerate(report.windows.items()):
        state[f"{p}win__{i}"] = np.array([(j, a, b) for j, (a, b) in wins.items()], dtype=np.int64).reshape(-1, 3)
    for i, med in enumerate(report.view_median_px.values()):
        state[f"{p}blur__median__{i}"] = np.asarray(med)
    return state


def _blur_from(state: dict, p: str) -> BlurReport | None:
    if not int(state[f"{p}blur__present"]):
        return None
    choices = [LevelChoice(str(level), None if np.isnan(t) else float(t), int(n), float(f))
               for level, n, t, f in zip(state[f"{p}blur__levels"], state[f"{p}blur__n_frames"],
                                         state[f"{p}blur__target_px"], state[f"{p}blur__fit_factor"])]
    windows = {str(level): {int(j): (int(a), int(b)) for j, a, b in state[f"{p}win__{i}"]}
               for i, level in enumerate(state[f"{p}blur__window_levels"])}
    medians = {str(level): state[f"{p}blur__median__{i}"] for i, level in enumerate(state[f"{p}blur__median_levels"])}
    return BlurReport(choices, windows, json.loads(str(state[f"{p}blur__manifest"])), medians)


def save(scene_dir: Path, fingerprint: str, plans) -> None:
    """Store what `plans` (datagen.scene_plan.ScenePlan: the scene first, then its variants) measured."""
    first = plans[0]
    views = sorted(first.dynamic)
    state = {"dynamic__views": np.array(views, dtype=np.int64).reshape(-1, 2),
             "dynamic__masks": np.array([first.dynamic[v] for v in views], dtype=bool),
             "rendered": np.asarray(first.rendered, dtype=np.int64),
             "render_plan": json.dumps(first.render_plan, default=_json_default)}
    for p in plans:
        state.update(_blur_state(p.blur, f"{p.dir.name}/"))
    JobCheckpoint(Path(scene_dir) / FILE_NAME, f"{FORMAT}:{fingerprint}").save(state)


def load(scene_dir: Path, fingerprint: str, plans) -> bool:
    """Restore the measurements into `plans` if a cache of this config is there (True), else False."""
    state = JobCheckpoint(Path(scene_dir) / FILE_NAME, f"{FORMAT}:{fingerprint}").load()
    if state is None or not all(f"{p.dir.name}/blur__present" in state for p in plans):
        return False
    views = [tuple(int(x) for x in v) for v in state["dynamic__views"]]
    masks = state["dynamic__masks"]
    rendered, render_plan = state["rendered"], json.loads(str(state["render_plan"]))
    for p in plans:
        p.blur = _blur_from(state, f"{p.dir.name}/")
        p.windows = p.blur.windows if p.blur is not None else {}
        p.dynamic = {v: masks[i] for i, v in enumerate(views)}
        p.rendered, p.render_plan = rendered, render_plan
    return True


def remove(scene_dir: Path) -> None:
    (Path(scene_dir) / FILE_NAME).unlink(missing_ok=True)
