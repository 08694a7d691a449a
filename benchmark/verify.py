"""`e4dgs verify`: re-derive a results folder's scores from the files on disk.

For every bench row that kept its scored views (recon.view_record), the views file must have the
digest the row holds, every render the SHA-256 its entry holds, every view's scores must come out
the same when computed again from that render and the scene's ground truth (the scene folder's test
frame, itself checked against the scene's manifest), and the row's means must be the means of those
views. The first view that fails is named. Rows scored from outside renders (`e4dgs score`) and
rows from before views were kept are reported as not verifiable, not as failures.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from benchmark.rows import read_results

TOLERANCE = 1e-9        # PSNR / SSIM: float64 on the same bytes, equal up to summation order
# LPIPS runs a float32 network whose sums follow torch's thread count (the bench scores in one-thread
# tasks): recomputed on another count it moves in the 8th digit (measured: 1.5e-8)
LPIPS_TOLERANCE = 1e-6


def _tolerance(metric: str) -> float:
    return LPIPS_TOLERANCE if metric.startswith("lpips") else TOLERANCE


@dataclass(frozen=True)
class Verdict:
    key: str
    status: str           # "ok" | "mismatch" | "unverifiable"
    detail: str = ""


def scene_folder(row: dict, data_root: Path) -> Path:
    """The scene folder a row's views are of (its speed variant; another dataset's folder)."""
    root = data_root.parent / row["dataset"] if row.get("dataset") else data_root
    return root / (row.get("data_scene") or row["scene"])


def _ground_truth_digests(dataset) -> dict[str, str]:
    files = dataset.manifest.get("files") or {}
    return {k: v.get("sha256", v) if isinstance(v, dict) else v for k, v in files.items()}


def verify_row(row: dict, out_root: Path, data_root: Path, lpips: bool = True) -> Verdict:
    """Whether one row's scores follow from its views on disk (Verdict naming the first that does not)."""
    from common.metrics.image import mean_scores, view_scores
    from recon.dataset_views import load_frame
    from recon.view_record import decode_png16, read_views, sha256
    from scene_format.reader import SceneDataset

    key = row["key"]
    if not row.get("views_dir") or not row.get("views_sha256"):
        return Verdict(key, "unverifiable", "scored from outside renders" if row.get("external")
                       else "made before scored views were kept (train it again to keep them)")
    folder = out_root / row["views_dir"]
    try:
        doc, digest = read_views(folder)
    except ValueError as exc:
        return Verdict(key, "mismatch", str(exc))
    if digest != row["views_sha256"]:
        return Verdict(key, "mismatch", f"{folder / 'views.json'}: SHA-256 {digest[:12]}… is not the row's "
                                        f"{row['views_sha256'][:12]}… (the per-view file was changed)")
    dataset = SceneDataset(scene_folder(row, data_root))
    records = {r.stem: r for r in dataset.frames(doc.get("split", "test"))}
    truth = _ground_truth_digests(dataset)
    lpips_net = doc.get("lpips_net") if lpips else None
    recomputed = []
    for entry in doc["views"]:
        view = entry["view"]
        path = folder / entry["render"]
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            return Verdict(key, "mismatch", f"view {view}: {path} is missing")
        if sha256(data) != entry["render_sha256"]:
            return Verdict(key, "mismatch", f"view {view}: {path} has SHA-256 {sha256(data)[:12]}…, scored as "
                                            f"{entry['render_sha256'][:12]}… (the render was changed)")
        rec = records.get(view)
        if rec is None:
            return Verdict(key, "mismatch", f"view {view}: not a {doc.get('split', 'test')} view of {dataset.dir}")
        pred = decode_png16(data, str(path))
        gt_file = rec.gray_path if pred.shape[-1] == 1 and rec.gray_path is not None else rec.path
        rel = gt_file.relative_to(dataset.dir).as_posix()
        if rel in truth and hashlib.sha256(gt_file.read_bytes()).hexdigest() != truth[rel]:
            return Verdict(key, "mismatch", f"view {view}: ground truth {gt_file} differs from the scene's manifest")
        gt = load_frame(dataset, rec, pred.shape[-1])
        (scores,) = view_scores([(pred, gt)], lpips_net, [dataset.dynamic_mask(rec)])
        for name, value in scores.items():
            if name not in entry or abs(entry[name] - value) > _tolerance(name):
                return Verdict(key, "mismatch", f"view {view}: {name} recomputed {value:.9g}, stored "
                                                f"{entry.get(name, 'nothing')}")
        recomputed.append(scores if lpips_net else {**scores, **{k: entry[k] for k in entry if "lpips" in k}})
    means = mean_scores(recomputed)
    for name in ("psnr", "psnr_luma", "ssim", "lpips", "psnr_dyn", "ssim_dyn", "lpips_dyn"):
        if row.get(name) is not None and not abs(means.get(name, float("nan")) - row[name]) <= _tolerance(name):
            return Verdict(key, "mismatch", f"row {name} {row[name]:.9g} is not the mean of its views "
                                            f"({means.get(name, float('nan')):.9g})")
    return Verdict(key, "ok", f"{len(recomputed)} views" + ("" if lpips_net or not doc.get("lpips_net")
                                                          else " (LPIPS not recomputed)"))


def verify_results(out_root: Path, data_root: Path, keys: list[str] | None = None, lpips: bool = True,
                   log: Callable[[str], None] = print) -> list[Verdict]:
    """Verdicts for every row of out_root/results.jsonl (or those of `keys`), one per scored-views
    folder (rows that reuse another's share its verdict)."""
    rows = [r for r in read_results(out_root / "results.jsonl") if r.get("status") != "failed"
            and (not keys or r["key"] in keys)]
    if keys:
        unknown = sorted(set(keys) - {r["key"] for r in rows})
        if unknown:
            raise ValueError(f"{out_root / 'results.jsonl'}: no row {', '.join(unknown)}")
    seen: dict[tuple, Verdict] = {}
    out = []
    for row in rows:
        ident = (row.get("views_dir"), row.get("views_sha256"), json.dumps([row.get(k) for k in ("psnr", "ssim", "lpips")]))
        v = seen.get(ident) if row.get("views_dir") else None
        v = Verdict(row["key"], v.status, v.detail) if v else verify_row(row, out_root, data_root, lpips)
        seen[ident] = v
        log(f"verify {v.key}: {v.status}" + (f": {v.detail}" if v.detail else ""))
        out.append(v)
    return out
