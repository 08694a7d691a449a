"""`e4dgs score`: score a folder of renders made by any code, by the leaderboard's protocol, and add
them to a preset's results as rows of an outside ("external") method.

    <renders>/<scene>/cam<k>/<index>.png|.exr            the final model's render of every test view
    <renders>/<scene>/snapshots/<seconds>/cam<k>/...    optional: renders after that many training seconds

<scene> is a scene of the dataset or one of its speed variants (hinge_x37.6: the row is hinge's, at
that speed). Everything is read and checked before anything is scored or written: a missing, extra,
unreadable, mis-sized, wrong-channel or non-finite render (or one outside [0, 1]) is refused with one
line naming the file. Methods that see RGB (`--inputs rgb`, `events+rgb`) are scored in colour
against the RGB ground truth; events-only methods (`--inputs events`) render gray, scored against
the gray ground truth after the per-image gain / offset on log intensity (the paper's protocol,
the same function as the bundled E-4DGS row). The rows are those `e4dgs bench` writes (PSNR,
luma PSNR, SSIM, LPIPS, snapshots against training seconds), marked `external`.
"""
from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np

from benchmark.testviews import RENDER_SUFFIXES, render_stem
from scene_format.reader import SceneDataset

INPUTS = {"rgb": ("rgb",), "events": ("events",), "events+rgb": ("events", "rgb")}
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")


class RenderError(ValueError):
    """A render (or the renders folder) that cannot be scored: the message names the file."""


def channels_for(inputs: tuple[str, ...]) -> int:
    """Channels a method's renders must have: colour if it sees RGB, gray if it sees events only."""
    return 3 if "rgb" in inputs else 1


def read_render(path: Path, width: int, height: int, channels: int) -> np.ndarray:
    """A render as float32 [H, W, channels] in [0, 1]; RenderError naming the file if it is not one."""
    import cv2

    from common.imageio import ImageReadError, read_exr

    if path.suffix.lower() == ".exr":
        try:
            img = read_exr(path)
        except ImageReadError as exc:
            raise RenderError(str(exc)) from None
    else:
        raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if raw is None:
            raise RenderError(f"{path}: cannot read as a PNG image (damaged or not an image)")
        if raw.dtype not in (np.uint8, np.uint16):
            raise RenderError(f"{path}: expected an 8- or 16-bit PNG, got {raw.dtype}")
        img = raw.astype(np.float32) / (255.0 if raw.dtype == np.uint8 else 65535.0)
        if img.ndim == 3:
            if img.shape[2] not in (3, 4):
                raise RenderError(f"{path}: {img.shape[2]} channels; expected {_want(channels)}")
            if img.shape[2] == 4:
                raise RenderError(f"{path}: has an alpha channel; expected {_want(channels)} without alpha")
            img = img[..., ::-1]                       # BGR -> RGB
    if img.shape[:2] != (height, width):
        raise RenderError(f"{path}: {img.shape[1]}x{img.shape[0]} pixels; the test view is {width}x{height}")
    img = img[..., None] if img.ndim == 2 else img
    if img.shape[2] != channels:
        raise RenderError(f"{path}: {_channels_word(img.shape[2])}; expected {_want(channels)}")
    if not np.all(np.isfinite(img)):
        raise RenderError(f"{path}: {int(np.sum(~np.isfinite(img)))} non-finite values (NaN or inf)")
    lo, hi = float(img.min()), float(img.max())
    if lo < 0.0 or hi > 1.0:
        raise RenderError(f"{path}: values from {lo:.4g} to {hi:.4g}; renders are sRGB-encoded intensities in [0, 1]")
    return np.ascontiguousarray(img, dtype=np.float32)


def _channels_word(n: int) -> str:
    return {1: "gray (1 channel)", 3: "colour (3 channels)"}.get(n, f"{n} channels")


def _want(channels: int) -> str:
    return ("colour (3 channels, RGB): the method sees RGB" if channels == 3 else
            "gray (1 channel): an events-only method is scored on gray (use --inputs rgb or events+rgb for colour)")


def render_files(folder: Path, stems: list[str]) -> dict[str, Path]:
    """stem -> its render file in `folder`; RenderError for a missing, doubled or extra file."""
    expected = set(stems)
    found: dict[str, Path] = {}
    if not folder.is_dir():
        raise RenderError(f"{folder}: no such folder (expected one render per test view, e.g. "
                          f"{folder / stems[0]}.png; `e4dgs testviews` lists them)")
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if rel.parts[0] == "snapshots" or p.is_dir():
            continue
        stem = str(rel.with_suffix("")).replace("\\", "/")
        if p.suffix.lower() not in RENDER_SUFFIXES or stem not in expected:
            raise RenderError(f"{p}: not a render of a test view (expected cam<k>/<index>.png or .exr for the "
                              f"{len(stems)} views of `e4dgs testviews`)")
        if stem in found:
            raise RenderError(f"{p}: a second render of view {stem} (also {found[stem].name})")
        found[stem] = p
    missing = [s for s in stems if s not in found]
    if missing:
        raise RenderError(f"{folder / missing[0]}.png: missing ({len(missing)} of {len(stems)} test views have no "
                          "render)")
    return found


def snapshot_folders(scene_folder: Path) -> list[tuple[float, Path]]:
    """(training seconds, folder) of <scene>/snapshots/<seconds>/, sorted by seconds."""
    root = scene_folder / "snapshots"
    if not root.exists():
        return []
    out = []
    for p in sorted(root.iterdir()):
        try:
            seconds = float(p.name)
        except ValueError:
            seconds = float("nan")
        if not p.is_dir() or not (seconds >= 0 and np.isfinite(seconds)):
            raise RenderError(f"{p}: expected a folder named by training seconds (e.g. snapshots/30/)")
        out.append((seconds, p))
    return sorted(out)


def load_pairs(dataset: SceneDataset, files: dict[str, Path], inputs: tuple[str, ...],
               images: dict[Path, np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
    """(scored prediction, ground truth) per test view, in the benchmark's order, after the protocol's
    correction (events only: the log-intensity gain / offset; otherwise none)."""
    from common.color_correction import correct_colors
    from recon.scoring import Scorer
    from recon.dataset_views import load_frame

    channels = channels_for(inputs)
    scorer = Scorer(dataset, channels, None if "rgb" in inputs else (lambda p, g: correct_colors(p, g)[0]))
    pairs = []
    for rec in dataset.frames("test"):
        pred = images[files[render_stem(rec)]]          # read and checked once, by score_renders
        gt = load_frame(dataset, rec, channels)
        pairs.append((scorer.correct(pred, gt), gt))
    return pairs


def _scene_folders(data_root: Path, renders: Path) -> list[tuple[Path, SceneDataset]]:
    """(render folder, its dataset scene) for every sub-folder of `renders`; RenderError for a folder
    that is not a scene of the dataset, or a stray file."""
    from scene_format.reader import DatasetError

    if not renders.is_dir():
        raise RenderError(f"{renders}: no such folder (expected <renders>/<scene>/cam<k>/<index>.png)")
    out = []
    for p in sorted(renders.iterdir()):
        if not p.is_dir():
            raise RenderError(f"{p}: not a scene folder (expected only <scene>/ folders in {renders})")
        try:
            out.append((p, SceneDataset(data_root / p.name)))
        except DatasetError:
            raise RenderError(f"{p}: {p.name!r} is not a scene of the dataset {data_root}") from None
    if not out:
        raise RenderError(f"{renders}: no scene folders (expected <renders>/<scene>/cam<k>/<index>.png)")
    return out


def _digest(files) -> str:
    import hashlib

    h = hashlib.sha256()
    for p in files:
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def score_renders(data_root: Path, renders: Path, name: str, inputs: str, train_seconds: float | None = None,
                  lpips_net: str | None = "vgg", snapshot_metrics=("psnr", "ssim"), label: str = "",
                  log=print, out_root: Path | None = None) -> list[dict]:
    """Results rows of an outside method's renders, one per scene folder under `renders`. Every file
    is checked before anything is scored (RenderError names the first bad one). With `out_root` (the
    results folder), the scored predictions are kept there as any bench row's are
    (`external/<name>/<scene>/views`, recon.view_record) and the final scores are those of the kept
    16-bit images, so `e4dgs verify` can re-derive them."""
    from benchmark.job_run import data_stats, versions
    from benchmark.rows import ResultRow
    from common.metrics.image import score_pairs
    from common.provenance import git_commit
    from scene_format.naming import split_variant

    if inputs not in INPUTS:
        raise RenderError(f"--inputs: expected one of {', '.join(INPUTS)}, got {inputs!r}")
    if not NAME.fullmatch(name):
        raise RenderError(f"--name: {name!r}: expected 1-64 letters, digits, '_', '.', '+' or '-'")
    if train_seconds is not None and not (np.isfinite(train_seconds) and train_seconds > 0):
        raise RenderError(f"--train-seconds: expected a positive number of seconds, got {train_seconds!r}")
    seen = INPUTS[inputs]
    channels = channels_for(seen)
    plan = []                               # (scene folder, dataset, final files, [(seconds, files)])
    for folder, ds in _scene_folders(data_root, renders):
        stems = [render_stem(r) for r in ds.frames("test")]
        snaps = [(s, render_files(f, stems)) for s, f in snapshot_folders(folder)]
        plan.append((folder, ds, render_files(folder, stems), snaps))
    images: dict[Path, np.ndarray] = {}
    for folder, ds, files, snaps in plan:   # read every image once, before scoring anything
        intr = ds.intrinsics
        for f in [*files.values(), *(p for _, fs in snaps for p in fs.values())]:
            images[f] = read_render(f, intr.width, intr.height, channels)
    rows = []
    for folder, ds, files, snaps in plan:
        t0 = time.time()
        scene, speed = split_variant(ds.dir.name)
        masks = [ds.dynamic_mask(r) for r in ds.frames("test")]
        masks = masks if any(m is not None for m in masks) else None
        identity = {"key": f"main/{scene}/{name}", "study": "main", "scene": scene, "cell": name, "variant": "",
                    "seed": None, "method": name, "label": label or name, "inputs": list(seen), "config": "",
                    "overrides": {}, "speed": speed, "data_scene": ds.dir.name, "dataset": "",
                    "config_hash": _digest(sorted(files.values())), "run_dir": str(folder)}
        pairs = load_pairs(ds, files, seen, images)
        kept = {}
        if out_root is None:
            final = score_pairs(pairs, lpips_net=lpips_net, masks=masks)
        else:
            final, kept = _keep_views(pairs, ds, masks, lpips_net, identity, out_root, name)
        snapshots = []
        for seconds, fs in snaps:
            s = score_pairs(load_pairs(ds, fs, seen, images), lpips_net=None)
            snapshots.append({"wall_s": seconds, **{k: s[k] for k in snapshot_metrics if k in s}})
        if train_seconds is not None and not any(abs(p["wall_s"] - train_seconds) < 1e-9 for p in snapshots):
            snapshots.append({"wall_s": train_seconds, **{k: final[k] for k in ("psnr", "ssim", "lpips") if k in final}})
        rows.append(ResultRow.of(
            identity, final, None, external=True, data=data_stats(ds), iterations=None, n_gaussians=None,
            channels=channels, device="", backend="", precision="", wall_s=train_seconds, train_elapsed_s=None,
            eval_s=round(time.time() - t0, 1), snapshots=sorted(snapshots, key=lambda p: p["wall_s"]),
            versions=versions(), git_commit=git_commit(), lpips_net=lpips_net, scored_unix=int(time.time()),
            **kept).to_dict())
        log(f"score: {name} on {ds.dir.name}: PSNR {final['psnr']:.2f} SSIM {final['ssim']:.3f}"
            + (f" LPIPS {final['lpips']:.3f}" if final.get("lpips") is not None else ""))
    return rows


EXTERNAL_DIR = "external"      # <results>/external/<name>/<scene>/views: an outside method's kept views


def _keep_views(pairs, ds: SceneDataset, masks, lpips_net: str | None, identity: dict, out_root: Path,
                name: str) -> tuple[dict, dict]:
    """(scores of the quantized predictions, the row's views columns): the predictions kept as 16-bit
    PNGs with views.json in the results folder, owned by the row (its key as run folder)."""
    from common.metrics.image import mean_scores, view_scores
    from recon.view_record import quantized, write_views

    rel = f"{EXTERNAL_DIR}/{name}/{ds.dir.name}/views"
    preds = [quantized(p) for p, _ in pairs]
    views = view_scores([(p, gt) for p, (_, gt) in zip(preds, pairs)], lpips_net, masks)
    means = mean_scores(views)
    digest = write_views(Path(out_root) / rel, [r.stem for r in ds.frames("test")], preds, views, means,
                         {"scene": ds.scene.name, "split": "test", "lpips_net": lpips_net, "method": name,
                          "run_dir": identity["run_dir"], "data_scene": ds.dir.name, "dataset": "",
                          "config_hash": identity["config_hash"], "external": True})
    return means, {"views_dir": rel, "views_sha256": digest}


def append_rows(results: Path, new_rows: list[dict], cells: tuple[str, ...] = ()) -> list[dict]:
    """results.jsonl with `new_rows` added (a row with the same key replaced), written atomically;
    refuses a name that is one of the preset's own cells."""
    from benchmark.rows import read_results, write_results

    clash = sorted({r["cell"] for r in new_rows} & set(cells))
    if clash:
        raise RenderError(f"--name: {clash[0]!r} is a cell of the preset; give the outside method another name")
    keys = {r["key"] for r in new_rows}
    rows = [r for r in read_results(results) if r["key"] not in keys] + new_rows
    results.parent.mkdir(parents=True, exist_ok=True)
    write_results(results, rows)
    return rows
