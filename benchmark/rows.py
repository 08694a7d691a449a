"""What the tables read from a results row beyond its scores: its cell's label, what its method sees
(`inputs`: "rgb", "events"), and the order of the cells (the preset's first, then outside methods)."""
from __future__ import annotations


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
