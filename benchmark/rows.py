"""Results rows (`results.jsonl`, one JSON object per job): their types, checked where rows are read
and written, and what the tables read from a row beyond its scores: its cell's label, what its method
sees (`inputs`: "rgb", "events"), and the order of the cells (the preset's first, then outside methods).

A row is stored as a mapping (rows written by older versions and by `e4dgs score` for outside
methods keep every field they carry), built through one typed class, `ResultRow`, which both the
bench (benchmark.job_run) and `e4dgs score` (benchmark.score) fill: its fields are the known columns,
and their JSON types (ROW_TYPES), checked where rows are read and written, are derived from it, so a
new column is one edit. A row whose field has the wrong type is refused naming the file, the line
and the field.
"""
from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.fileio import write_text_atomic

NUMBER = (int, float)
OPTIONAL_NUMBER = (int, float, type(None))


class _Absent:
    """The value of a column a row does not have (left out of the stored row; null is a value)."""
    def __repr__(self) -> str:
        return "ABSENT"


ABSENT: Any = _Absent()


@dataclass
class ResultRow:
    """One results row. Identity (which job), then scores (test views; `*_dyn` over the moving pixels,
    present where the scene has masks), the untrained floor, the data, the run, provenance."""
    key: str
    study: str
    scene: str
    cell: str
    method: str
    label: str
    inputs: list
    variant: str
    seed: int | None
    config: str
    overrides: dict
    speed: float | None
    data_scene: str
    dataset: str
    config_hash: str
    run_dir: str
    psnr: float
    ssim: float
    psnr_luma: float | None
    lpips: float | None
    floor_psnr: float | None
    floor_psnr_luma: float | None
    data: dict
    n_test_images: int
    iterations: int | None
    n_gaussians: int | None
    channels: int | None
    device: str
    backend: str
    precision: str
    wall_s: float | None
    train_elapsed_s: float | None
    eval_s: float | None
    snapshots: list
    versions: dict
    git_commit: str | None
    lpips_net: str | None
    psnr_dyn: float | None = ABSENT
    psnr_luma_dyn: float | None = ABSENT
    ssim_dyn: float | None = ABSENT
    lpips_dyn: float | None = ABSENT
    dyn_fraction: float | None = ABSENT
    n_dyn_images: int = ABSENT
    floor_psnr_dyn: float | None = ABSENT
    cpu: str = ABSENT                 # the bench's runs: the CPU they trained on
    gpu: str | None = ABSENT          # the GPU's model (null on the CPU)
    identity: dict = ABSENT           # the digests its config_hash is made of (benchmark.grid.Job.identity_parts)
    code_version: str = ABSENT        # identity["code"]: common.provenance.code_version
    recipe: dict = ABSENT             # the resolved fields that decide a result (benchmark.job_run.recipe_of)
    views_sha256: str = ABSENT        # SHA-256 of its views.json (per-view scores, render digests)
    views_dir: str = ABSENT           # that file's folder, relative to the results folder
    floor_views_sha256: str = ABSENT  # the untrained model's views.json (its floor scores), and its folder
    floor_views_dir: str = ABSENT
    masks: str = ABSENT               # the dynamic masks it was scored with (scene_format.manifest.masks_digest)
    external: bool | None = ABSENT           # `e4dgs score`: an outside method's renders
    scored_unix: int | None = ABSENT
    scored_as: str | None = ABSENT           # a reused row: the key of the row it was scored as
    status: str = ABSENT              # "failed" (with `error`)
    error: str = ABSENT

    def to_dict(self) -> dict[str, Any]:
        """The row as stored: every column it has (ABSENT ones left out)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if getattr(self, f.name) is not ABSENT}

    @classmethod
    def of(cls, identity: dict[str, Any], final: dict[str, Any], floor: dict[str, Any] | None, **columns) -> "ResultRow":
        """A scored row: the job's identity, the test views' scores `final` (common.metrics.image.score_pairs:
        psnr, psnr_luma, ssim, lpips, the `*_dyn` scores where masked, n_images), the untrained model's
        `floor` scores (None: no floor) and the other columns by name."""
        scores = {k: final.get(k) for k in ("psnr", "psnr_luma", "ssim", "lpips")}
        dyn = {k: final[k] for k in DYN_KEYS if k in final}
        floors = ({"floor_psnr": floor["psnr"], "floor_psnr_luma": floor["psnr_luma"],
                   **({"floor_psnr_dyn": floor["psnr_dyn"]} if "psnr_dyn" in floor else {})}
                  if floor is not None else {"floor_psnr": None, "floor_psnr_luma": None})
        return cls(**identity, **scores, **dyn, **floors, n_test_images=final["n_images"], **columns)


DYN_KEYS = ("psnr_dyn", "psnr_luma_dyn", "ssim_dyn", "lpips_dyn", "dyn_fraction", "n_dyn_images")


def _json_types(annotation) -> tuple[type, ...]:
    """The JSON types a column of this annotation may hold (a float column also takes an integer)."""
    args = typing.get_args(annotation) if isinstance(annotation, types.UnionType) else (annotation,)
    out = []
    for a in args:
        out += [int, float] if a is float else [a]
    return tuple(dict.fromkeys(out))


# column -> the JSON types it may hold, derived from ResultRow; every row has the identity columns,
# a row not failed the scores
ROW_TYPES: dict[str, tuple[type, ...]] = {name: _json_types(t) for name, t in
                                          typing.get_type_hints(ResultRow).items()}
IDENTITY = ("key", "study", "scene", "cell")
SCORES = ("psnr", "ssim")
SNAPSHOT_TYPES = {"iteration": NUMBER, "wall_s": NUMBER, "psnr": NUMBER, "ssim": NUMBER, "lpips": OPTIONAL_NUMBER}


def _type_names(types: tuple[type, ...]) -> str:
    names = {int: "a number", float: "a number", str: "a string", list: "a list", dict: "a mapping", type(None): "null"}
    return " or ".join(dict.fromkeys(names[t] for t in types))


def _check_fields(obj: dict, types: dict[str, tuple[type, ...]], where: str) -> None:
    for name, value in obj.items():
        allowed = types.get(name)
        if allowed is None:
            continue
        ok = isinstance(value, allowed) and not (isinstance(value, bool) and bool not in allowed)
        if ok and isinstance(value, float) and math.isnan(value) and name in SCORES:
            ok = False
        if not ok:
            raise ValueError(f"{where}: {name}: expected {_type_names(allowed)}, got {value!r}")


def check_row(row, where: str) -> dict:
    """`row` if it is a results row (identity fields; scores unless it failed; every known field of its
    type), else ValueError naming `where` (file:line) and the field."""
    if not isinstance(row, dict):
        raise ValueError(f"{where}: expected a JSON object (a results row), got {type(row).__name__}")
    needed = IDENTITY + (() if row.get("status") == "failed" else SCORES)
    missing = [k for k in needed if k not in row]
    if missing:
        raise ValueError(f"{where}: missing {', '.join(missing)} (a results row has {', '.join(needed)})")
    _check_fields(row, ROW_TYPES, where)
    for i, snap in enumerate(row.get("snapshots") or ()):
        if not isinstance(snap, dict):
            raise ValueError(f"{where}: snapshots[{i}]: expected a mapping, got {snap!r}")
        _check_fields(snap, SNAPSHOT_TYPES, f"{where}: snapshots[{i}]")
    return row


def read_results(path: Path) -> list[dict]:
    """The rows of a results.jsonl ([] when it does not exist), each checked (check_row); ValueError
    naming the line of a key that appears twice."""
    if not path.exists():
        return []
    rows, first = [], {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            try:
                row = json.loads(line)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{path}:{n}: not a JSON row ({exc.msg})") from None
            row = check_row(row, f"{path}:{n}")
            if row["key"] in first:         # one row per job: a second would count as another seed
                raise ValueError(f"{path}:{n}: row {row['key']} again (first on line {first[row['key']]}): a "
                                 "results file holds one row per job (two results files joined?)")
            first[row["key"]] = n
            rows.append(row)
    return rows


def write_results(path: Path, rows: list[dict]) -> None:
    """results.jsonl, atomically, every row checked first (nothing is written when one is wrong)."""
    for n, row in enumerate(rows, 1):
        check_row(row, f"{path}: row {n} to write ({row.get('key', '?') if isinstance(row, dict) else '?'})")
    write_text_atomic(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in rows))


def describe_rows(rows: list[dict], labels: dict[str, str] | None = None) -> list[dict]:
    """Rows with `label` and `inputs` filled in where a row lacks them (rows written before they
    existed): the label from `labels` (the preset's) or the cell's name, the inputs from the method."""
    from recon.methods import get_method

    out = []
    for r in rows:
        extra = {}
        if not r.get("label"):
            extra["label"] = (labels or {}).get(r["cell"], r["cell"])
        if not r.get("inputs"):
            try:
                extra["inputs"] = list(get_method(r.get("method", r["cell"])).inputs)
            except ValueError:             # a method no longer installed: its row still shows
                extra["inputs"] = []
        out.append({**r, **extra} if extra else r)
    return out


def cell_order(rows: list[dict], order: list[str] | tuple[str, ...] = ()) -> list[str]:
    """Cells of the rows: the preset's order first, then the others (outside methods scored with
    `e4dgs score`) in the order they were added."""
    seen = [c for c in order]
    for r in rows:
        if r["cell"] not in seen:
            seen.append(r["cell"])
    return [c for c in seen if any(r["cell"] == c for r in rows)]


def labels_of(rows: list[dict]) -> dict[str, str]:
    """cell -> its label: the first row's that gives one (a failed job's row may carry none)."""
    out: dict[str, str] = {}
    for r in rows:
        if r.get("label") and r["label"] != r["cell"]:
            out.setdefault(r["cell"], r["label"])
    return {**{r["cell"]: r["cell"] for r in rows}, **out}


def sees_rgb(row: dict) -> bool:
    return "rgb" in (row.get("inputs") or ())


def sees_events(row: dict) -> bool:
    return "events" in (row.get("inputs") or ())
