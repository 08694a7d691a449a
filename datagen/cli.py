"""`e4dgs dataset`: generate a preset's scenes, one process per scene, several side by side."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from common.argtypes import add_ray_arguments, name_list, nonnegative_int, positive_int, ray_options


def add_dataset_parser(sub) -> None:
    p = sub.add_parser("dataset", help="generate the synthetic multi-view event dataset (Blender + simulator)",
                       description="Render, simulate and write every scene of a preset. Each scene runs in its own "
                                   "process; finished scenes are skipped and killed ones resume.")
    from datagen.config import PRESETS_DIR

    shipped = sorted(p.stem for p in PRESETS_DIR.glob("*.yaml"))
    p.add_argument("--preset", default="quick", help=f"{' | '.join(shipped)} (configs/datasets/), or a "
                                                     "preset YAML file (default quick)")
    p.add_argument("--scenes", type=name_list, default=None, help="comma-separated subset of the preset's scenes")
    p.add_argument("--out", type=Path, default=None, help="dataset root (default data/<preset>)")
    p.add_argument("--jobs", type=positive_int, default=1, help="scenes generated side by side (default 1)")
    p.add_argument("--checkpoint-every", type=positive_int, default=100, metavar="N", help="timestamps between checkpoints")
    p.add_argument("--scene-file", type=Path, action="append", default=None,
                   help="your own animated scene instead of the preset's: .blend, .glb/.gltf, .fbx, .obj, .usd*, .abc "
                        "(the preset's overrides apply; docs/guides/your_scene.md); "
                        "may be given several times")
    p.add_argument("--kind", choices=("object", "room"), default="object",
                   help="with --scene-file: cameras around the content (object) or inside it (room)")
    p.add_argument("--scene-config", type=Path, action="append", default=None,
                   help="a scene YAML (e.g. one with source: {file: ...}) instead of the preset's scenes; "
                        "may be given several times")
    p.add_argument("--retries", type=nonnegative_int, default=2, metavar="N",
                   help="starts again, from its last checkpoint, of a scene whose worker crashes (dies from a "
                        "signal) before the scene is reported failed (default 2; with --ray, --ray-retries)")
    add_ray_arguments(p, "each scene's generation")
    p.set_defaults(func=run_dataset)


def own_scene_args(files: list[Path], configs: list[Path], kind: str) -> dict[str, list[str]]:
    """--scene-file / --scene-config: each scene's name and its worker's arguments; one line for a
    YAML without a name, or two sources with one name (they would write one folder)."""
    from common.config import ConfigError, read_yaml_mapping
    from datagen.config import builtin_builder, file_scene_name, resolve_scene

    args: dict[str, list[str]] = {}

    def add(name: str, worker: list[str], source: Path) -> None:
        if name in args:
            raise SystemExit(f"error: {source}: scene name {name!r} is already taken by another --scene-file or "
                             "--scene-config (each scene needs its own folder; rename the file or set name:)")
        args[name] = worker

    for f in [*configs, *files]:
        if not Path(f).is_file():
            raise SystemExit(f"error: {f}: no such file" + ("" if not Path(f).exists() else " (a folder)"))
    for cfg in configs:
        name = read_yaml_mapping(cfg).get("name")
        if not isinstance(name, str) or not name:
            raise SystemExit(f"error: {cfg}: name: expected the scene's name")
        try:
            parsed = resolve_scene(name, scene_file=cfg)
            if not parsed.source.file:
                builtin_builder(parsed, cfg)
            else:                         # relative to the YAML's folder, as the worker reads it
                src = Path(parsed.source.file)
                src = src if src.is_absolute() else Path(cfg).parent / src
                if not src.is_file():
                    raise SystemExit(f"error: {cfg}: source.file: {src}: no such file")
        except ConfigError as exc:
            raise SystemExit(f"error: {exc}") from None
        add(name, ["--scene", name, "--scene-config", str(cfg)], cfg)
    for f in files:
        add(file_scene_name(f), ["--scene-file", str(f), "--kind", kind], f)
    return args


def run_dataset(args: argparse.Namespace) -> int:
    from datagen.build import generate_dataset, preset_scenes

    scene_args = None
    if args.scene_file or args.scene_config:
        if args.scenes is not None:
            raise SystemExit("error: --scenes picks the preset's scenes; it cannot be combined with --scene-file "
                             "or --scene-config")
        scene_args = own_scene_args(args.scene_file or [], args.scene_config or [], args.kind)
        scenes = list(scene_args)
    else:
        wanted = args.scenes
        scenes = preset_scenes(args.preset, wanted)      # a bad preset or scene: one line, before any work
    out = args.out or Path("data") / Path(str(args.preset)).stem.removeprefix("dataset_")
    failed = generate_dataset(args.preset, scenes, out, args.jobs, args.checkpoint_every, ray=ray_options(args),
                              scene_args=scene_args, retries=args.retries)
    done = [s for s in scenes if s not in failed]
    if done and out.is_dir():
        from datagen.summary import blur_table

        print("\nblur levels (median blur length over geometry; PSNR of blurred vs sharp frames):\n" + blur_table(out, done))
    if failed:
        print(f"dataset: failed: {', '.join(failed)} (the error lines above say why; a scene that was killed or "
              "crashed resumes where it stopped when run again, one refused for its input needs that input fixed)",
              file=sys.stderr)
        return 1
    return 0


def add_masks_parser(sub) -> None:
    p = sub.add_parser("masks", help="add dynamic-region masks to scenes generated before they existed",
                       description="Builds each scene in Blender from its scene.yaml (no rendering), casts a ray "
                                   "through every pixel of every test view and tracks the surface over the clip: "
                                   "dynamic/cam<k>/<index>.png in the scene and its speed variants. Scenes that have "
                                   "masks are skipped unless --force.")
    p.add_argument("path", type=Path, help="a scene folder, or a dataset root holding scene folders")
    p.add_argument("--force", action="store_true", help="compute them again")
    p.set_defaults(func=run_masks)


def no_dataset_at(path: Path) -> SystemExit:
    """The one line for a path that holds no generated scene: missing, a file, or a folder without any."""
    if not path.exists():
        return SystemExit(f"error: {path}: no such folder (expected a generated scene such as data/quick/hinge, "
                          "or a dataset root such as data/quick)")
    if not path.is_dir():
        return SystemExit(f"error: {path}: a file, not a folder (expected a generated scene or a dataset root)")
    return SystemExit(f"error: {path}: no manifest.json in it or in its sub-folders (not a generated dataset)")


def run_masks(args: argparse.Namespace) -> int:
    import json
    import subprocess

    from common.taskpool import child_env, die_with_parent
    from scene_format.config import read_scene_config
    from scene_format.verify import scene_dirs

    scenes = scene_dirs(args.path)
    if not scenes:
        raise no_dataset_at(args.path)
    for d in scenes:
        manifest = json.loads((d / "manifest.json").read_text())
        if manifest.get("speed"):           # a speed variant: its scene writes its masks
            continue
        if (d / "dynamic" / "masks.json").exists() and not args.force:
            print(f"{d}: has masks, skipped")
            continue
        cfg = read_scene_config(d / "scene.yaml")
        if cfg.source.file and not Path(cfg.source.file).is_file():     # the masks re-trace the scene's geometry
            raise SystemExit(f"error: {d}: its source file {cfg.source.file} is gone, and the dynamic masks are traced "
                             "from the scene's geometry; restore the file there, or generate the scene again")
        r = subprocess.run([sys.executable, "-m", "datagen.add_masks", str(d)], env=child_env(),
                           preexec_fn=die_with_parent)
        if r.returncode != 0:
            raise SystemExit(f"error: {d}: computing the dynamic masks failed (status {r.returncode})")
    return 0


def add_check_parser(sub) -> None:
    p = sub.add_parser("check", help="verify a dataset against its manifests (sizes, SHA-256, event files), or one event file",
                       description="Check every file a scene's manifest.json lists: present, same size and SHA-256, "
                                   "and event files readable and well-formed; or one event file (.h5, e.g. from "
                                   "`e4dgs import`): every event checked. Exit status 1 if anything differs.")
    p.add_argument("path", type=Path, help="a scene folder, a dataset root holding scene folders, or an event file")
    p.set_defaults(func=run_check)


def check_event_file(path: Path) -> int:
    """`e4dgs check FILE.h5`: the file's layout and every event (eventio.event_check), one line."""
    from simulator.event_file import EventFile
    from eventio.h5io import EventFileError

    if path.suffix != ".h5":
        raise SystemExit(f"error: {path}: a file, not a folder, and not an event file (.h5): expected a generated "
                         "scene, a dataset root or an event file; `e4dgs import` turns other recordings into one")
    try:
        with EventFile(path) as ev:
            span = f", {int(ev.times(0, 1)[0])} .. {int(ev.times(ev.n - 1, ev.n)[0])} us" if ev.n else ""
            print(f"{path}: OK ({ev.n} events, {ev.width}x{ev.height}{span})")
    except (EventFileError, ValueError) as exc:
        message = " ".join(str(exc).split())
        print(message if message.startswith(str(path)) else f"{path}: {message}")
        return 1
    return 0


OWNED_FOLDERS = ("events", "exports", "ground_truth")   # where a stray file would be taken for data


def run_check(args: argparse.Namespace) -> int:
    import json

    from tqdm import tqdm

    from scene_format.verify import other_dirs, scene_dirs, unlisted_files, verify_scene

    if args.path.is_file():
        return check_event_file(args.path)
    scenes = scene_dirs(args.path)
    unfinished, others = other_dirs(args.path)
    if not scenes and not unfinished:
        raise no_dataset_at(args.path)
    failed = len(unfinished)
    for d in scenes:
        try:
            files = json.loads((d / "manifest.json").read_text()).get("files", {})
            n = len(files) if isinstance(files, dict) else 0
        except (ValueError, AttributeError):          # not JSON, or not a mapping: verify_scene says so
            n = 0
        with tqdm(total=n, desc=f"check {d.name}", unit="file", leave=False) as bar:
            problems = verify_scene(d, progress=lambda _: bar.update(1))
        if problems:
            failed += 1
            print(f"{d}: {len(problems)} problem(s)")
            for line in problems:
                print(f"  {line}")
        else:
            print(f"{d}: OK ({n} files match the manifest)")
        extra = unlisted_files(d)
        # in the folders the generator owns, a file it did not write is an error (a stray file there is
        # read as data: an export, an event file, a ground-truth map); elsewhere a note
        owned = [rel for rel in extra if rel.split("/")[0] in OWNED_FOLDERS]
        if owned:
            failed += 1
            print(f"{d}: {len(owned)} file(s) in the generator's folders that the manifest does not list: "
                  + ", ".join(owned[:5]) + (", ..." if len(owned) > 5 else "") + " (remove them, or generate the scene again)")
        extra = [rel for rel in extra if rel not in owned]
        if extra:   # not an error (a user may keep notes beside the data), but never passed over in silence
            print(f"{d}: note: {len(extra)} file(s) the manifest does not list, not verified: "
                  + ", ".join(extra[:5]) + (", ..." if len(extra) > 5 else ""))
    for d in unfinished:
        print(f"{d}: not a finished scene: no manifest.json (its generation did not finish; run the same "
              "`e4dgs dataset` again to resume it)")
    for d in others:
        print(f"{d}: skipped, not a scene folder (no manifest.json, scene.yaml, cameras.json or events/)")
    return 1 if failed else 0
