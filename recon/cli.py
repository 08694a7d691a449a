"""`e4dgs train` and `e4dgs render`."""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from common.argtypes import add_main_input, float_in


def add_train_parser(sub) -> None:
    p = sub.add_parser("train", help="train a reconstruction method on a generated scene",
                       description="Train a registered method on one scene folder. A killed run resumes from its "
                                   "last checkpoint when started again with the same arguments.")
    add_main_input(p, "scene", "SCENE", "scene folder (e.g. data/quick/lego)", old_option="--scene")
    p.add_argument("--method", default="d3dgs", help="a registered method (default d3dgs; an unknown name lists them)")
    p.add_argument("--config", type=Path, default=None,
                   help="training recipe: a YAML file or a shipped recipe's name (`quick`: the leaderboard's recipe "
                        "of --method, configs/recipes/<method>/quick.yaml; `e4dgs/mlp`); default: the method's defaults")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config value, dotted keys (e.g. train.iterations=3000); repeatable")
    p.add_argument("--out", type=Path, default=None, help="output folder (default runs/<scene>/<method>)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (the log still records every evaluation)")
    p.set_defaults(func=run_train)


def run_train(args: argparse.Namespace) -> int:
    from recon.api import fit, parse_set

    # a refused config, scene or run is a typed error naming what is wrong: e4dgs.cli prints it as one line
    result = fit(args.scene, args.method, args.config, args.out, parse_set(args.overrides),
                 progress=not args.no_progress)
    model, psnr = result.model, result.last_test_psnr
    last = f", test PSNR {psnr[0]:.2f} dB" if psnr else ""
    print(f"train: {args.method} on {args.scene.name}: {model.meta.iteration} iterations, {len(model)} Gaussians"
          f"{last}, {result.train_s:.0f} s of training -> {result.run_dir / 'model.pt'}")
    return 0


def add_render_parser(sub) -> None:
    p = sub.add_parser("render", help="render a trained model from a camera at times in [0, 1]",
                       description="Render a trained model. --camera is a dataset camera index (posed along its "
                                   "recorded trajectory) or a JSON file {K: 3x3, c2w_opencv: 4x4, width, height}.")
    add_main_input(p, "model", "RUN", "training folder or model .pt file", old_option="--model")
    p.add_argument("--camera", default=None, help="camera index, or a JSON camera file")
    p.add_argument("--t", type=float_in(0.0, 1.0, "a normalised time"), nargs="+", default=None, help="normalised times in [0, 1]")
    p.add_argument("--test-views", type=Path, default=None, metavar="SCENE",
                   help="instead of --camera/--t: render every held-out view of this scene folder as "
                        "<out>/cam<k>/<index>.<format>, the layout `e4dgs score` reads")
    p.add_argument("--format", choices=("png", "exr"), default="png",
                   help="with --test-views: 8-bit PNG, or float32 EXR (exact; the same [0, 1] values)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.set_defaults(func=run_render)


def camera_from_json(path: Path):
    """A raster camera from a JSON file {K: 3x3, c2w_opencv: 4x4, width, height}; errors name the file and field."""
    from recon.render import camera_from_pose

    try:
        data = json.loads(path.read_text())
    except OSError as exc:
        raise SystemExit(f"error: --camera {path}: {exc.strerror}") from None
    except ValueError as exc:
        raise SystemExit(f"error: --camera {path}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise SystemExit(f"error: --camera {path}: expected a JSON object {{K, c2w_opencv, width, height}}")
    fields = {}
    for key, shape in (("K", (3, 3)), ("c2w_opencv", (4, 4))):
        try:
            fields[key] = np.asarray(data[key], np.float64)
        except KeyError:
            raise SystemExit(f"error: --camera {path}: missing field {key!r}") from None
        except (ValueError, TypeError):
            raise SystemExit(f"error: --camera {path}: {key}: expected a {shape[0]}x{shape[1]} array of numbers") from None
        if fields[key].shape != shape or not np.all(np.isfinite(fields[key])):
            raise SystemExit(f"error: --camera {path}: {key}: expected a finite {shape[0]}x{shape[1]} matrix, "
                             f"got shape {fields[key].shape}")
    for key in ("width", "height"):
        if not isinstance(data.get(key), int) or data[key] < 1:
            raise SystemExit(f"error: --camera {path}: {key}: expected a positive integer, got {data.get(key)!r}")
    if abs(np.linalg.det(fields["c2w_opencv"][:3, :3])) < 1e-9:
        raise SystemExit(f"error: --camera {path}: c2w_opencv: its rotation part is singular")
    try:
        return camera_from_pose(fields["K"], fields["c2w_opencv"], data["width"], data["height"])
    except ValueError as exc:
        raise SystemExit(f"error: --camera {path}: {exc}") from None


def render_test_views(model, scene_dir: Path, out: Path, fmt: str = "png") -> int:
    """Every held-out view of a scene rendered by `model`, saved as out/cam<k>/<index>.<fmt> (EXR: float32,
    the same sRGB-encoded values in [0, 1] as the PNG). Returns the number of views."""
    from common.imageio import write_exr, write_png
    from scene_format.reader import SceneDataset
    from recon.dataset_views import record_camera

    dataset = SceneDataset(scene_dir)
    if model.meta.scene and model.meta.scene != dataset.scene.name:
        raise ValueError(f"--test-views {scene_dir}: the model was trained on scene {model.meta.scene!r}, these are "
                         f"the views of {dataset.scene.name!r}; its renders would be scored against another scene")
    records = dataset.frames("test")
    for rec in records:
        img = model.render_numpy(record_camera(dataset, rec), rec.time)
        path = out / f"{rec.stem}.{fmt}"
        path.parent.mkdir(parents=True, exist_ok=True)
        img = img[..., 0] if img.shape[2] == 1 else img
        if fmt == "exr":
            write_exr(path, img)
        else:
            write_png(path, (img * 255 + 0.5).astype(np.uint8))
    return len(records)


def run_render(args: argparse.Namespace) -> int:
    from common.imageio import write_png
    from recon.model import load

    if args.out.exists() and not args.out.is_dir():
        raise SystemExit(f"error: --out {args.out}: an existing file; expected a folder for the images")
    model = load(args.model)            # a missing or unreadable model: one line from e4dgs.cli
    if args.test_views is not None:
        n = render_test_views(model, args.test_views, args.out, args.format)
        print(f"render: {n} test view(s) of {args.test_views} -> {args.out}")
        return 0
    if args.camera is None or not args.t:
        raise SystemExit("error: give --camera and --t, or --test-views SCENE")
    if args.camera.lstrip("-").isdigit() and args.camera.startswith("-"):
        raise SystemExit(f"error: --camera {args.camera}: a camera index is >= 0 (or give a JSON camera file)")
    names = [f"{t:.4f}" for t in args.t]
    if len(set(names)) != len(names):
        raise SystemExit("error: --t: two times give the same file name (times are written to 4 decimals); "
                         "give distinct times")
    camera = int(args.camera) if args.camera.isdigit() else camera_from_json(Path(args.camera))
    for t in args.t:
        img = model.render_numpy(camera, t)
        img = np.repeat(img, 3, axis=2) if img.shape[2] == 1 else img
        name = f"cam{args.camera}" if isinstance(camera, int) else Path(args.camera).stem
        path = write_png(args.out / f"{name}_t{t:.4f}.png", (img * 255 + 0.5).astype(np.uint8))
        print(f"render: {path}")
    return 0
