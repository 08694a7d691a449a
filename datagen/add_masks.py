"""Add dynamic-region masks (datagen.dynamic) to scenes generated before they existed, without
rendering again: the scene is built in Blender from its scene.yaml, every test view's pixels are
cast into it and tracked over the clip, and the masks go into the scene and its speed variants.
New scenes get them from `e4dgs dataset` (the same datagen.scene_plan.measure_dynamic, on the same plan).

    python -m datagen.add_masks data/quick/hinge          # `e4dgs masks data/quick` runs this per scene
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from datagen import render as R
from scene_format.reader import SceneDataset
from datagen.dynamic import write_masks
from datagen.scene_folder import test_masks
from datagen.scene_plan import make_plan, measure_dynamic


def add_masks(scene_dir: Path) -> list[Path]:
    """Masks for the scene at scene_dir (a scene, not a speed variant) and its variants beside it;
    returns the folders written."""
    ds = SceneDataset(scene_dir)
    cfg = ds.config
    import numpy as np

    poses = np.stack([c.c2w for c in ds.cameras]) if cfg.source.cameras else None     # as filmed
    plan = make_plan(cfg, scene_dir.parent, ds.manifest.get("preset", "custom"), folder=scene_dir.name, poses=poses)
    R.build_scene(cfg, plan.intr)
    measure_dynamic(plan)
    written = []
    for p in plan.plans:
        if (p.dir / "manifest.json").exists():
            write_masks(p.dir, test_masks(p))
            written.append(p.dir)
    return written


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene_dir", type=Path)
    args = ap.parse_args(argv)
    for d in add_masks(args.scene_dir):
        print(f"masks: {d / 'dynamic'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
