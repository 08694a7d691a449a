"""`e4dgs verify`: re-derive a results folder's scores from the files on disk.

A row is OK only when every number a table shows follows from files the row cannot choose:
- its identity: the digests in `identity` make its `config_hash`, which names its training folder
  (`run_dir`), whose views folder is `views_dir`;
- its views: `views.json` has the digest the row holds and says it belongs to the row (training
  folder, method, scene folder, identity digest); its views are the scene's complete test split
  (the scene folder's transforms_test.json, checked against the scene's manifest), each render has
  the SHA-256 its entry holds, and each view's scores come out the same when computed again from
  that render and the scene's ground truth (LPIPS with the row's network, which must be the
  preset's, never the one views.json names);
- its means: PSNR, luma PSNR, SSIM, LPIPS, the dynamic-region scores, the dynamic fraction and the
  image counts are the means and counts of those views, and a score the views have is not missing
  from the row;
- its floor: `floor_psnr` (and luma, dynamic) recomputed the same way from the untrained model's
  kept views (`floor_views_dir`);
- its run: training seconds and iterations are the run folder's log (log.jsonl's last row), the
  method its run.json's, the label the preset's (bench.json).
An outside method's row (`e4dgs score`) keeps its views in `external/<name>/<scene>/views` and is
checked the same way, but for the identity, floor and run folder it does not have. The first thing
that fails is named. A row that cannot be checked (made before views were kept) is "unverifiable",
which fails the command unless allowed by key.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from benchmark.rows import read_results

TOLERANCE = 1e-9        # PSNR / SSIM: float64 on the same bytes, equal up to summation order
# LPIPS runs a float32 network whose sums follow torch's thread count (the bench scores in one-thread
# tasks): recomputed on another count it moves in the 8th digit (measured: 1.5e-8)
LPIPS_TOLERANCE = 1e-6
TIME_TOLERANCE_S = 1e-6

# row column -> the key of common.metrics.image.mean_scores it must equal
MEANS = {"psnr": "psnr", "psnr_luma": "psnr_luma", "ssim": "ssim", "lpips": "lpips", "psnr_dyn": "psnr_dyn",
         "psnr_luma_dyn": "psnr_luma_dyn", "ssim_dyn": "ssim_dyn", "lpips_dyn": "lpips_dyn",
         "dyn_fraction": "dyn_fraction", "n_test_images": "n_images", "n_dyn_images": "n_dyn_images"}
FLOOR_MEANS = {"floor_psnr": "psnr", "floor_psnr_luma": "psnr_luma", "floor_psnr_dyn": "psnr_dyn"}
OWNER = ("run_dir", "method", "data_scene", "config_hash")


def _tolerance(metric: str) -> float:
    return LPIPS_TOLERANCE if "lpips" in metric else TOLERANCE


@dataclass(frozen=True)
class Verdict:
    key: str
    status: str           # "ok" | "mismatch" | "unverifiable"
    detail: str = ""


class Mismatch(Exception):
    """What does not follow from the files (one line)."""


def scene_folder(row: dict, data_root: Path) -> Path:
    """The scene folder a row's views are of (its speed variant; another dataset's folder)."""
    root = data_root.parent / row["dataset"] if row.get("dataset") else data_root
    return root / (row.get("data_scene") or row["scene"])


def _ground_truth_digests(dataset) -> dict[str, str]:
    files = dataset.manifest.get("files") or {}
    return {k: v.get("sha256", v) if isinstance(v, dict) else v for k, v in files.items()}


def _sha(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


def _check_identity(row: dict) -> None:
    ident, digest, run_dir = row.get("identity"), row.get("config_hash"), str(row.get("run_dir") or "")
    if not isinstance(ident, dict) or _sha(ident) != digest:
        raise Mismatch(f"its identity digests do not make its config_hash {digest} (the row was edited)")
    if not run_dir.endswith(f"/{row.get('method')}-{digest}"):
        raise Mismatch(f"run_dir {run_dir!r} is not the training folder of method {row.get('method')!r} with "
                       f"identity {digest}")
    if row.get("views_dir") != f"{run_dir}/views":
        raise Mismatch(f"views_dir {row.get('views_dir')!r} is not its training folder's views ({run_dir}/views)")


def _recomputed_views(folder: Path, digest: str | None, row: dict, dataset, lpips_net: str | None,
                      floor: bool) -> tuple[dict, bool]:
    """(mean_scores of the views in `folder`, recomputed; whether LPIPS was recomputed). Mismatch names
    the first thing that does not follow."""
    from common.metrics.image import mean_scores, view_scores
    from recon.dataset_views import load_frame
    from recon.view_record import decode_png16, read_views, sha256

    try:
        doc, actual = read_views(folder)
    except ValueError as exc:
        raise Mismatch(str(exc)) from None
    if actual != digest:
        raise Mismatch(f"{folder / 'views.json'}: SHA-256 {actual[:12]}… is not the row's {str(digest)[:12]}… "
                       "(the per-view file was changed)")
    owner = {k: doc.get(k) for k in OWNER} | {"dataset": doc.get("dataset") or "", "floor": bool(doc.get("floor")),
                                              "external": bool(doc.get("external"))}
    wanted = {k: row.get(k) for k in OWNER} | {"dataset": row.get("dataset") or "", "floor": floor,
                                               "external": bool(row.get("external"))}
    if owner != wanted:
        bad = next(k for k in wanted if owner[k] != wanted[k])
        raise Mismatch(f"{folder / 'views.json'}: belongs to {bad} {owner[bad]!r}, the row's is {wanted[bad]!r} "
                       "(views borrowed from another row)")
    if doc.get("split", "test") != "test":
        raise Mismatch(f"{folder / 'views.json'}: split {doc.get('split')!r}, expected the test split")
    if not floor and doc.get("lpips_net") != row.get("lpips_net"):
        raise Mismatch(f"{folder / 'views.json'}: scored with LPIPS {doc.get('lpips_net')!r}, the row says "
                       f"{row.get('lpips_net')!r}")
    records = {r.stem: r for r in dataset.frames("test")}
    stems = [e.get("view") for e in doc["views"] if isinstance(e, dict)]
    if len(stems) != len(doc["views"]) or len(set(stems)) != len(stems) or set(stems) != set(records):
        missing, extra = sorted(set(records) - set(stems)), sorted(set(stems) - set(records), key=str)
        raise Mismatch(f"{folder / 'views.json'}: {len(stems)} views, the test split of {dataset.dir} has "
                       f"{len(records)}" + (f"; missing {', '.join(missing[:5])}" if missing else "")
                       + (f"; not test views: {', '.join(map(str, extra[:5]))}" if extra else "")
                       + ("; a view listed twice" if len(set(stems)) != len(stems) else ""))
    truth = _ground_truth_digests(dataset)
    recomputed = []
    for entry in doc["views"]:
        view = entry["view"]
        path = folder / str(entry.get("render"))
        if path.parent.resolve() != folder.resolve() and folder.resolve() not in path.resolve().parents:
            raise Mismatch(f"view {view}: render {entry.get('render')!r} lies outside {folder}")
        try:
            data = path.read_bytes()
        except OSError:
            raise Mismatch(f"view {view}: {path} is missing") from None
        if sha256(data) != entry.get("render_sha256"):
            raise Mismatch(f"view {view}: {path} has SHA-256 {sha256(data)[:12]}…, scored as "
                           f"{str(entry.get('render_sha256'))[:12]}… (the render was changed)")
        rec = records[view]
        try:
            pred = decode_png16(data, str(path))
        except ValueError as exc:
            raise Mismatch(f"view {view}: {exc}") from None
        gt_file = rec.gray_path if pred.shape[-1] == 1 and rec.gray_path is not None else rec.path
        rel = gt_file.relative_to(dataset.dir).as_posix()
        if rel not in truth or hashlib.sha256(gt_file.read_bytes()).hexdigest() != truth[rel]:
            raise Mismatch(f"view {view}: ground truth {gt_file} is not the one the scene's manifest lists")
        gt = load_frame(dataset, rec, pred.shape[-1])
        (scores,) = view_scores([(pred, gt)], lpips_net, [dataset.dynamic_mask(rec)])
        for name, value in scores.items():
            stored = entry.get(name)
            if not isinstance(stored, (int, float)) or not abs(stored - value) <= _tolerance(name):
                raise Mismatch(f"view {view}: {name} recomputed {value:.9g}, stored {stored}")
        recomputed.append(scores if lpips_net or floor else
                          {**scores, **{k: entry[k] for k in entry if "lpips" in k}})
    return mean_scores(recomputed), bool(lpips_net)


def _check_means(row: dict, means: dict, columns: dict[str, str], what: str) -> None:
    for column, name in columns.items():
        have, want = row.get(column), means.get(name)
        if want is None and have is None:
            continue
        if want is None or have is None or not isinstance(have, (int, float)) or not math.isfinite(have) \
                or abs(have - want) > _tolerance(name):
            raise Mismatch(f"row {column} {have} is not the {'count' if name.startswith('n_') else 'mean'} of its "
                           f"{what} ({want})")


def _check_run(row: dict, out_root: Path, preset: dict | None) -> None:
    run = out_root / row["run_dir"]
    try:
        info = json.loads((run / "run.json").read_text())
        log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines() if line.strip()]
    except (OSError, ValueError) as exc:
        raise Mismatch(f"{run}: its run.json / log.jsonl cannot be read ({exc})") from None
    if info.get("method") != row.get("method"):
        raise Mismatch(f"{run / 'run.json'}: method {info.get('method')!r}, the row says {row.get('method')!r}")
    last = log[-1] if log else {}
    if last.get("iteration") != row.get("iterations"):
        raise Mismatch(f"row iterations {row.get('iterations')} is not its run's ({last.get('iteration')}, "
                       f"{run / 'log.jsonl'})")
    if not isinstance(row.get("wall_s"), (int, float)) or abs(float(last.get("wall_s", math.nan)) - row["wall_s"]) \
            > TIME_TOLERANCE_S:
        raise Mismatch(f"row wall_s {row.get('wall_s')} is not its run's training seconds ({last.get('wall_s')}, "
                       f"{run / 'log.jsonl'})")
    cells = (preset or {}).get("cells")
    if isinstance(cells, dict) and row.get("cell") in cells:
        label = (cells[row["cell"]] or {}).get("label") or row["cell"]
        if row.get("label") != label:
            raise Mismatch(f"row label {row.get('label')!r} is not the preset's {label!r} for cell {row['cell']}")


def _lpips_net(row: dict, preset: dict | None) -> str | None:
    """The network the row's LPIPS must be recomputed with: the row's, which must be the preset's for a
    row scored with LPIPS (the views file never decides it)."""
    net = row.get("lpips_net")
    if row.get("lpips") is not None and not net:
        raise Mismatch(f"row lpips {row['lpips']} with no LPIPS network (lpips_net {net!r})")
    want = (preset or {}).get("lpips_net")
    if net and want and net != want:
        raise Mismatch(f"row scored with LPIPS {net!r}, the preset's network is {want!r}")
    if net is None and row.get("study") != "speed" and want:
        raise Mismatch(f"row has no LPIPS; the preset scores every row but the speed study's with {want!r}")
    return net


def verify_row(row: dict, out_root: Path, data_root: Path, lpips: bool = True, preset: dict | None = None) -> Verdict:
    """Whether one row's numbers follow from its files on disk (Verdict naming the first that does not).
    `preset`: the results folder's bench.json (its LPIPS network and cell labels)."""
    from scene_format.reader import SceneDataset

    key = row["key"]
    if not row.get("views_dir") or not row.get("views_sha256"):
        return Verdict(key, "unverifiable", "scored from outside renders without kept views (score them again "
                       "with `e4dgs score` to keep them)" if row.get("external")
                       else "made before scored views were kept (train it again to keep them)")
    external = bool(row.get("external"))
    try:
        if external:               # an outside method's renders: no training folder, its own views folder
            if row["views_dir"] != f"external/{row.get('cell')}/{row.get('data_scene')}/views":
                raise Mismatch(f"views_dir {row['views_dir']!r} is not external/{row.get('cell')}/"
                               f"{row.get('data_scene')}/views")
        else:
            _check_identity(row)
        net = _lpips_net(row, preset)
        try:
            dataset = SceneDataset(scene_folder(row, data_root))
        except (OSError, ValueError) as exc:
            raise Mismatch(f"its scene folder cannot be read: {exc}") from None
        means, recomputed_lpips = _recomputed_views(out_root / row["views_dir"], row["views_sha256"], row, dataset,
                                                    net if lpips else None, floor=False)
        _check_means(row, means, MEANS, "views")
        if row.get("floor_psnr") is not None or row.get("floor_views_dir"):
            if not row.get("floor_views_dir") or row["floor_views_dir"] != f"{row['run_dir']}/floor_views":
                raise Mismatch(f"floor_views_dir {row.get('floor_views_dir')!r} is not its training folder's "
                               "floor views: its floor_psnr cannot be recomputed")
            floor, _ = _recomputed_views(out_root / row["floor_views_dir"], row.get("floor_views_sha256"), row,
                                         dataset, None, floor=True)
            _check_means(row, floor, FLOOR_MEANS, "floor views")
        if not external:
            _check_run(row, out_root, preset)
    except Mismatch as exc:
        return Verdict(key, "mismatch", str(exc))
    return Verdict(key, "ok", f"{means['n_images']} views" + ("" if recomputed_lpips or not net
                                                              else " (LPIPS not recomputed)"))


def verify_results(out_root: Path, data_root: Path, keys: list[str] | None = None, lpips: bool = True,
                   log: Callable[[str], None] = print) -> list[Verdict]:
    """Verdicts for every row of out_root/results.jsonl (or those of `keys`), one per scored-views
    folder (rows that reuse another's share its verdict, when they agree with it on every column the
    verdict checked). ValueError when there is nothing to verify."""
    rows = [r for r in read_results(out_root / "results.jsonl") if r.get("status") != "failed"
            and (not keys or r["key"] in keys)]
    if keys:
        unknown = sorted(set(keys) - {r["key"] for r in rows})
        if unknown:
            raise ValueError(f"{out_root / 'results.jsonl'}: no row {', '.join(unknown)}")
    if not rows:
        raise ValueError(f"{out_root / 'results.jsonl'}: no scored rows to verify")
    try:
        preset = json.loads((out_root / "bench.json").read_text())
        preset = preset if isinstance(preset, dict) else None
    except (OSError, ValueError):
        preset = None
    checked = set(MEANS) | set(FLOOR_MEANS) | {"views_dir", "views_sha256", "floor_views_dir", "floor_views_sha256",
                                                "identity", "config_hash", "run_dir", "lpips_net", "wall_s",
                                                "iterations", "label", "method", "data_scene", "dataset"}
    seen: dict[str, Verdict] = {}
    out = []
    for row in rows:
        ident = json.dumps({k: row.get(k) for k in sorted(checked)}, sort_keys=True, default=str)
        v = seen.get(ident) if row.get("views_dir") else None
        v = Verdict(row["key"], v.status, v.detail) if v else verify_row(row, out_root, data_root, lpips, preset)
        seen[ident] = v
        log(f"verify {v.key}: {v.status}" + (f": {v.detail}" if v.detail else ""))
        out.append(v)
    return out
