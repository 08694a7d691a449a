"""`e4dgs bench`: the leaderboard harness."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common.argtypes import (DeprecatedOption, add_main_input, add_ray_arguments, float_in, int_in, name_list, ray_options,
                             seed_list)
from common.fileio import output_inside_input


def add_bench_parser(sub) -> None:
    p = sub.add_parser("bench", help="train every method on every scene of a preset and build the leaderboard",
                       description="Builds the dataset if missing, trains each job (resuming killed ones, reusing "
                                   "finished ones), scores held-out views, and writes runs/<preset>/results.jsonl, "
                                   "leaderboard.md/.csv, accuracy_vs_time.png/.md, blur.md and ablation.md.")
    p.add_argument("--preset", default="quick", help=f"{' | '.join(preset_names())}, or a bench YAML file (default quick)")
    p.add_argument("--scenes", type=name_list, default=None, help="comma-separated subset of the preset's scenes")
    p.add_argument("--cells", type=name_list, default=None, help="comma-separated subset of the preset's cells (quick: d3dgs_sharp, "
                                                 "d3dgs_blur, deblur_d3dgs, e2vid_d3dgs, e4dgs, e4dgs_rgb)")
    p.add_argument("--methods", dest="cells", type=name_list, action=DeprecatedOption, help=argparse.SUPPRESS,
                   instead="use --cells (it names the preset's cells)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a training config value of every cell, dotted keys (train.device=cuda); repeatable")
    p.add_argument("--studies", type=name_list, default="main,blur,ablation",
                   help="which studies to run: main, blur, ablation, speed (default main,blur,ablation; the speed "
                        "study runs only when named, as `make speed-study`)")
    p.add_argument("--seed-axes", type=name_list, default=None,
                   help="what each of --seeds varies, comma-separated among train (training's random draws), init "
                        "(the initial points) and noise (the events: seed k trains on the dataset's k-th noise "
                        "realisation, data/<dataset>@noise<k>); default: the preset's seed_axes (train,init)")
    p.add_argument("--ablation-seeds", type=seed_list, default=None,
                   help="comma-separated training seeds for the ablation, e.g. 0,1,2 (default: the preset's "
                        "ablation.seeds); --seeds is a count, these are the seeds themselves")
    p.add_argument("--seeds", type=int_in(1, 100, "training seeds per cell"), default=None,
                   help="train every main cell at seeds 0 .. N-1 (default: the preset's seeds, 1): the tables give the "
                        "mean and standard deviation over seeds and call differences within the spread ties")
    p.add_argument("--sensor", default=None, metavar="NAME",
                   help="the event sensor of the main table's event cells: a sensor in configs/sensors/ (davis346, "
                        "imx636, dvxplorer, ...); they train on data/<dataset>@<sensor> (generated when "
                        "missing); default: each scene's own sensor. Results go to runs/<preset>@<sensor> unless --out")
    p.add_argument("--reuse-older", action="store_true",
                   help="keep rows made by another code version or dataset (the same resolved config) instead of "
                        "training them again; the tables mark each with the version it came from")
    p.add_argument("--data", type=Path, default=None, help="dataset root (default data/<dataset>)")
    p.add_argument("--out", type=Path, default=None, help="results folder (default runs/<preset>)")
    p.add_argument("--report", action="store_true", help="only regenerate tables and plots from results.jsonl")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_ray_arguments(p, "each (scene, cell) job (and any missing scene's generation)")
    p.set_defaults(func=run_bench_cli)


def preset_names() -> list[str]:
    """The bench presets shipped in configs/bench/ (quick first)."""
    from benchmark.config import PRESET_DIR

    names = sorted(p.stem for p in PRESET_DIR.glob("*.yaml"))
    return sorted(names, key=lambda n: (n != "quick", n))


def report_header(name: str, cfg) -> str:
    return (f"# Leaderboard: `{name}` preset\n\n{cfg.description.strip()}\n\nMeasured on a 2-core CPU "
            f"(no GPU) unless the rows' versions say otherwise.")


def add_testviews_parser(sub) -> None:
    p = sub.add_parser("testviews", help="write the held-out views a method must render to be scored",
                       description="Writes testviews.json for a scene folder, or for every scene (and speed variant) "
                                   "of a dataset root: per view the camera, time, intrinsics, pose, image size, the "
                                   "file name its render must have and the ground truth it is scored against.")
    p.add_argument("data", type=Path, help="a dataset root (data/quick) or one scene folder (data/quick/hinge)")
    p.add_argument("--out", type=Path, default=None,
                   help="write <out>/<scene>/testviews.json (default runs/<dataset folder>/testviews; never into "
                        "the dataset, which `e4dgs check` verifies against its manifest)")
    p.set_defaults(func=run_testviews)


def run_testviews(args: argparse.Namespace) -> int:
    from benchmark.testviews import write_test_views

    from scene_format.verify import scene_dirs

    root = args.data.resolve() if not (args.data / "manifest.json").is_file() else args.data.resolve().parent
    out = args.out or Path("runs") / root.name / "testviews"
    inside = output_inside_input(out, {"the dataset": root}) if scene_dirs(args.data) else None
    if inside:
        raise SystemExit(f"error: --out {inside}")
    paths = write_test_views(args.data, out)
    print(f"testviews: wrote {len(paths)} file(s): " + ", ".join(str(p) for p in paths))
    return 0


def add_score_parser(sub) -> None:
    p = sub.add_parser("score", help="score a folder of renders from any method and add it to a leaderboard",
                       description="Scores <renders>/<scene>/cam<k>/<index>.png|.exr (the views of `e4dgs testviews`) "
                                   "by the leaderboard's protocol and appends the rows, marked external, to "
                                   "<out>/results.jsonl; the tables in <out> are written again. Optional "
                                   "<renders>/<scene>/snapshots/<seconds>/ give accuracy against training time.")
    p.add_argument("--data", type=Path, required=True, help="the dataset root the renders are of (data/quick)")
    add_main_input(p, "renders", "RENDERS", "folder of <scene>/ render folders", old_option="--renders")
    p.add_argument("--name", required=True, help="the method's cell name in the results (not one of the preset's)")
    p.add_argument("--inputs", required=True, choices=("events", "rgb", "events+rgb"),
                   help="what the method saw: events-only renders are gray, scored after the log gain / offset")
    p.add_argument("--label", default="", help="its name in the tables (default: --name)")
    p.add_argument("--train-seconds", type=float_in(0.0, 1e9, "seconds"), default=None, help="training wall-clock seconds per scene")
    p.add_argument("--out", type=Path, default=None, help="results folder (default runs/<dataset folder name>)")
    p.add_argument("--lpips", default=None, choices=("vgg", "alex", "none"),
                   help="LPIPS network (default: the preset's, from <out>/bench.json; else vgg)")
    p.set_defaults(func=run_score)


def run_score(args: argparse.Namespace) -> int:
    import json

    from benchmark.config import load_bench
    from benchmark.report import write_report
    from benchmark.score import append_rows, score_renders

    out = args.out or Path("runs") / args.data.resolve().name
    inside = output_inside_input(out, {"--data": args.data, "--renders": args.renders})
    if inside:
        raise SystemExit(f"error: --out {inside}")
    cfg = name = None
    if (out / "bench.json").exists():           # the preset the results belong to: its cells, labels, LPIPS
        name = json.loads((out / "bench.json").read_text()).get("preset")
        cfg = load_bench(name) if name else None
    lpips = args.lpips or (cfg.lpips_net if cfg is not None else "vgg")
    rows = score_renders(args.data, args.renders, args.name, args.inputs, args.train_seconds,
                         None if lpips == "none" else lpips,
                         tuple(cfg.snapshot_metrics) if cfg is not None else ("psnr", "ssim"), args.label,
                         out_root=out)
    all_rows = append_rows(out / "results.jsonl", rows, tuple(cfg.cells) if cfg is not None else ())
    if cfg is not None:
        all_rows = tabled_rows(cfg, all_rows, out, args.data)
    paths = write_report(all_rows, out, report_header(name, cfg) if cfg is not None else "", cfg)
    print(f"score: {len(rows)} row(s) added to {out / 'results.jsonl'}; wrote " + ", ".join(str(p) for p in paths))
    return 0


def add_verify_parser(sub) -> None:
    p = sub.add_parser("verify", help="recompute a results folder's scores from its kept renders and check them",
                       description="For every row of <results>/results.jsonl: checks the SHA-256 of its per-view file "
                                   "and of every scored render, recomputes each view's PSNR / SSIM / LPIPS (and the "
                                   "dynamic-region ones) from the render and the scene's ground truth, the row's "
                                   "means and counts from them, its floor from the untrained model's kept views, "
                                   "its training seconds, iterations and label from its run folder and preset; "
                                   "names the first thing that does not match. Exit 1 on a mismatch, and on a row "
                                   "that cannot be verified unless --allow-unverifiable names it.")
    p.add_argument("results", type=Path, help="a results folder (runs/quick)")
    p.add_argument("--data", type=Path, default=None,
                   help="the dataset root (default data/<dataset> of the preset in <results>/bench.json)")
    p.add_argument("--keys", type=name_list, default=None, help="comma-separated row keys (default: every row)")
    p.add_argument("--no-lpips", action="store_true", help="check LPIPS by the digests only (skips the network)")
    p.add_argument("--allow-unverifiable", type=name_list, default=[], metavar="KEYS",
                   help="comma-separated keys of rows that may lack kept views (scored from outside renders, or "
                        "made before views were kept) without failing the command")
    p.set_defaults(func=run_verify)


def run_verify(args: argparse.Namespace) -> int:
    import json

    from benchmark.verify import verify_results

    if not (args.results / "results.jsonl").is_file():
        raise SystemExit(f"error: {args.results}: no results.jsonl (a results folder of `e4dgs bench`)")
    data = args.data
    if data is None:
        bench = args.results / "bench.json"
        dataset = json.loads(bench.read_text()).get("dataset") if bench.is_file() else None
        if not dataset:
            raise SystemExit(f"error: {args.results}: no bench.json naming its dataset; give --data")
        data = Path("data") / dataset
    try:
        verdicts = verify_results(args.results, data, args.keys, lpips=not args.no_lpips)
    except ValueError as exc:
        raise SystemExit(f"error: {exc}") from None
    counts = {s: sum(v.status == s for v in verdicts) for s in ("ok", "mismatch", "unverifiable")}
    refused = [v.key for v in verdicts if v.status == "unverifiable" and v.key not in args.allow_unverifiable]
    print(f"verify: {counts['ok']} row(s) match their renders, {counts['mismatch']} do not, "
          f"{counts['unverifiable']} cannot be verified" + (f" (not allowed: {', '.join(refused[:5])}"
                                                           f"{' …' if len(refused) > 5 else ''}; "
                                                           "--allow-unverifiable KEYS accepts them)" if refused else ""))
    return 1 if counts["mismatch"] or refused else 0


def tabled_rows(cfg, rows: list[dict], out: Path, data_root: Path | None = None, reuse_older: bool = False) -> list[dict]:
    """The rows the tables show: the preset's current ones (benchmark.config.current_rows; with
    `reuse_older` also those of another code version or dataset, marked), saying how many rows
    results.jsonl keeps out of them."""
    from benchmark.grid import current_rows

    kept, stale = current_rows(cfg, rows, data_root, reuse_older)
    if stale:
        print(f"bench: {len(stale)} row(s) of {out / 'results.jsonl'} left out of the tables: made by another config, "
              f"code version or dataset than the preset's jobs now (e.g. {stale[0]['key']}; `--reuse-older` shows "
              "those of the same config, marked)", file=sys.stderr)
    return kept


def run_bench_cli(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from benchmark.config import load_bench
    from benchmark.report import write_report
    from benchmark.rows import read_results
    from benchmark.runner import run_bench
    from recon.api import parse_set
    from common.config import ConfigError

    try:
        cfg = load_bench(args.preset, parse_set(args.overrides) if args.overrides else None)
    except ConfigError as exc:
        raise SystemExit(f"error: {exc}") from None
    name = Path(args.preset).stem
    if args.ablation_seeds:
        cfg = replace(cfg, ablation=replace(cfg.ablation, seeds=args.ablation_seeds))
    if args.seeds is not None:
        cfg = replace(cfg, seeds=args.seeds)
    if args.seed_axes is not None:
        from benchmark.config import SEED_AXES

        if not args.seed_axes or any(a not in SEED_AXES for a in args.seed_axes):
            raise SystemExit(f"error: --seed-axes: expected names among {', '.join(SEED_AXES)}, got "
                             f"{','.join(args.seed_axes)!r}")
        cfg = replace(cfg, seed_axes=tuple(dict.fromkeys(args.seed_axes)))
    if args.sensor:
        from datagen.config import UNDER_SENSOR

        if not UNDER_SENSOR.match(f"{cfg.dataset}@{args.sensor}"):
            raise SystemExit(f"error: --sensor: expected the name of a sensor in configs/sensors/, got {args.sensor!r}")
        try:
            cfg = replace(cfg, sensor=args.sensor)
        except ConfigError as exc:
            raise SystemExit(f"error: --{exc}") from None
    out = args.out or Path("runs") / (f"{name}@{cfg.sensor}" if cfg.sensor else name)
    data_root = args.data or Path("data") / cfg.dataset
    inside = output_inside_input(out, {"--data": data_root})
    if inside:
        raise SystemExit(f"error: --out {inside}")
    scenes, cells = args.scenes, args.cells
    for s in scenes or []:
        if s not in cfg.scenes:
            raise SystemExit(f"error: --scenes: {s!r} is not in preset {name!r} ({', '.join(cfg.scenes)})")
    for c in cells or []:
        if c not in cfg.cells:
            raise SystemExit(f"error: --cells: {c!r} is not a cell of preset {name!r} ({', '.join(cfg.cells)})")
    header = report_header(name, cfg)
    if not args.report:
        studies = tuple(args.studies)
        unknown = [st for st in studies if st not in ("main", "blur", "ablation", "speed")]
        if unknown:
            raise SystemExit(f"error: --studies: {', '.join(map(repr, unknown))} is not a study (main, blur, ablation, speed)")
        # a refused job, dataset or results file is a typed error: e4dgs.cli prints it as one line
        run_bench(cfg, name, data_root, out, scenes, cells, studies, progress=not args.no_progress,
                  ray=ray_options(args), reuse_older=args.reuse_older)
    rows = tabled_rows(cfg, read_results(out / "results.jsonl"), out, data_root, args.reuse_older)
    paths = write_report(rows, out, header, cfg)
    print("bench: wrote " + ", ".join(str(p) for p in paths))
    failed = [r["key"] for r in rows if r.get("status") == "failed" and (not scenes or r.get("scene") in scenes)
              and (not cells or r.get("cell") in cells)]
    if failed:
        print(f"bench: {len(failed)} job(s) failed, marked 'failed' in the tables (their errors are in "
              f"{out / 'results.jsonl'}; the next run retries them): {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0
