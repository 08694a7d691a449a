"""Results rows (`results.jsonl`, one JSON object per job): their types, checked where rows are read
and written, and what the tables read from a row beyond its scores: its cell's label, what its method
sees (`inputs`: "rgb", "events"), and the order of the cells (the preset's first, then outside methods).

A row is a mapping, not a class, so that rows written by older versions and by `e4dgs score` for
outside methods keep every field they carry; its known fields are typed here (ROW_TYPES) and a row
whose field has the wrong type is refused naming the file, the line and the field.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from common.fileio import write_text_atomic

NUMBER = (int, float)
OPTIONAL_NUMBER = (int, float, type(None))
# field -> the JSON types it may hold; every row has the identity fields, a row not failed the scores
ROW_TYPES: dict[str, tuple[type, ...]] = {
    "key": (str,), "study": (str,), "scene": (str,), "cell": (str,), "method": (str,), "label": (str,),
    "variant": (str,), "dataset": (str,), "data_scene": (str,), "run_dir": (str,), "config_hash": (str,),
    "status": (str,), "error": (str,), "device": (str,), "backend": (str,), "precision": (str,), "cpu": (str,), "inputs": (list,), "overrides": (dict,), "data": (dict,),
    "seed": (int, type(None)), "speed": OPTIONAL_NUMBER,
    "psnr": NUMBER, "ssim": NUMBER, "psnr_luma": OPTIONAL_NUMBER, "lpips": OPTIONAL_NUMBER,
    "floor_psnr": OPTIONAL_NUMBER, "floor_psnr_luma": OPTIONAL_NUMBER, "floor_psnr_dyn": OPTIONAL_NUMBER,
    "psnr_dyn": OPTIONAL_NUMBER, "psnr_luma_dyn": OPTIONAL_NUMBER, "ssim_dyn": OPTIONAL_NUMBER,
    "lpips_dyn": OPTIONAL_NUMBER, "dyn_fraction": OPTIONAL_NUMBER, "n_dyn_images": (int,),
    "iterations": (int, type(None)), "n_gaussians": (int, type(None)), "n_test_images": (int,), "channels": (int, type(None)),
    "wall_s": OPTIONAL_NUMBER, "train_elapsed_s": OPTIONAL_NUMBER, "eval_s": OPTIONAL_NUMBER, "snapshots": (list,),
}
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
    """The rows of a results.jsonl ([] when it does not exist), each checked (check_row)."""
    if not path.exists():
        return []
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if line.strip():
            try:
                row = json.loads(line)
            except json.JSONDecodeError as exc:
                raise ValueError(f"{path}:{n}: not a JSON row ({exc.msg})") from None
            rows.append(check_row(row, f"{path}:{n}"))
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
