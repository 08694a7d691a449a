"""`e4dgs bench`: the leaderboard harness."""
from __future__ import annotations

import argparse
from pathlib import Path

from common.argtypes import add_ray_arguments, ray_options


def add_bench_parser(sub) -> None:
    p = sub.add_parser("bench", help="train every method on every scene of a preset and build the leaderboard",
                       description="Builds the dataset if missing, trains each job (resuming killed ones, reusing "
                                   "finished ones), scores held-out views, and writes runs/<preset>/results.jsonl, "
                                   "leaderboard.md/.csv, accuracy_vs_time.png/.md, blur.md and ablation.md.")
    p.add_argument("--preset", default="quick", help="quick | paper, or a bench YAML file (default quick)")
    p.add_argument("--scenes", default=None, help="comma-separated subset of the preset's scenes")
    p.add_argument("--methods", default=None, help="comma-separated subset of the preset's cells (quick: d3dgs_sharp, "
                                                   "d3dgs_blur, deblur_d3dgs, e2vid_d3dgs, e4dgs, e4dgs_rgb)")
    p.add_argument("--studies", default="main,blur,ablation",
                   help="which studies to run: main, blur, ablation, speed (default main,blur,ablation; the speed "
                        "study runs only when named, as `make speed-study`)")
    p.add_argument("--ablation-seeds", default=None,
                   help="comma-separated training seeds for the ablation (default: the preset's ablation.seeds)")
    p.add_argument("--data", type=Path, default=None, help="dataset root (default data/<dataset>)")
    p.add_argument("--out", type=Path, default=None, help="results folder (default runs/<preset>)")
    p.add_argument("--report", action="store_true", help="only regenerate tables and plots from results.jsonl")
    p.add_argument("--no-progress", action="store_true")
    add_ray_arguments(p, "each (scene, cell) job (and any missing scene's generation)")
    p.set_defaults(func=run_bench_cli)


def run_bench_cli(args: argparse.Namespace) -> int:
    from benchmark.config import load_bench
    from benchmark.report import write_report
    from benchmark.runner import read_results, run_bench
    from common.config import ConfigError

    try:
        cfg = load_bench(args.preset)
    except ConfigError as exc:
        raise SystemExit(f"error: {exc}") from None
    name = Path(args.preset).stem
    if args.ablation_seeds:
        from dataclasses import replace
        try:
            seeds = tuple(int(s) for s in args.ablation_seeds.split(",") if s.strip())
            cfg = replace(cfg, ablation=replace(cfg.ablation, seeds=seeds))
        except (ValueError, ConfigError) as exc:
            raise SystemExit(f"error: --ablation-seeds: expected distinct integers >= 0 separated by commas "
                             f"({exc})") from None
    out = args.out or Path("runs") / name
    split = lambda s: [x.strip() for x in s.split(",") if x.strip()] if s else None  # noqa: E731
    scenes, cells = split(args.scenes), split(args.methods)
    for s in scenes or []:
        if s not in cfg.scenes:
            raise SystemExit(f"error: --scenes: {s!r} is not in preset {name!r} ({', '.join(cfg.scenes)})")
    for c in cells or []:
        if c not in cfg.cells:
            raise SystemExit(f"error: --methods: {c!r} is not a cell of preset {name!r} ({', '.join(cfg.cells)})")
    header = (f"# Leaderboard: `{name}` preset\n\n{cfg.description.strip()}\n\nMeasured on a 2-core CPU "
              f"(no GPU) unless the rows' versions say otherwise.")
    if not args.report:
        studies = tuple(split(args.studies) or ())
        unknown = [st for st in studies if st not in ("main", "blur", "ablation", "speed")]
        if unknown:
            raise SystemExit(f"error: --studies: {', '.join(map(repr, unknown))} is not a study (main, blur, ablation, speed)")
        try:
            run_bench(cfg, name, args.data or Path("data") / cfg.dataset, out, scenes, cells, studies,
                      progress=not args.no_progress, ray=ray_options(args))
        except (ConfigError, FileNotFoundError, ValueError, RuntimeError) as exc:
            raise SystemExit(f"error: {exc}") from None
    try:
        rows = read_results(out / "results.jsonl")
        paths = write_report(rows, out, header, cfg)
    except ValueError as exc:
        raise SystemExit(f"error: {exc}") from None
    print("bench: wrote " + ", ".join(str(p) for p in paths))
    return 0
