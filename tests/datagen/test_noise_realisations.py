"""A dataset's noise realisations (`<preset>@noise<k>`, `sensor_seed`): the same frames and poses,
other events where the sensor is noisy; the benchmark's `noise` seed axis trains on them."""
import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from benchmark.config import BenchConfig, CellSpec
from benchmark.grid import jobs
from common.config import build_config
from datagen.config import load_preset, resolve_scene
from datagen.scene_folder import config_fingerprint

ROOT = Path(__file__).resolve().parents[2]


def test_a_realisation_is_its_preset_with_the_sensor_seed_and_another_fingerprint():
    base, noisy = load_preset("tiny"), load_preset("tiny@noise3")
    assert noisy.scenes == base.scenes and noisy.overrides == {**base.overrides, "sensor_seed": 3}
    a, b = (resolve_scene("cubes", p.scene("cubes")) for p in (base, noisy))
    assert a.sensor_seed is None and a.event_seed == a.seed and b.event_seed == 3
    assert config_fingerprint(a) != config_fingerprint(b)


def _generate(out: Path, preset: str) -> Path:
    r = subprocess.run([sys.executable, "-m", "datagen.generate", "--scene", "cubes", "--preset", preset,
                        "--out", str(out), "--no-progress"], capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return out / "cubes"


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*.exr")):
        h.update(p.read_bytes())
    return h.hexdigest()


def test_a_noisy_sensors_realisations_share_every_frame_and_differ_in_their_events(tmp_path):
    from eventio.h5io import read_events

    preset = yaml.safe_load((ROOT / "configs" / "datasets" / "tiny.yaml").read_text())
    preset["overrides"]["sensor"] = yaml.safe_load((ROOT / "configs" / "sensors" / "realistic.yaml").read_text())
    preset["overrides"].pop("blur", None)
    (tmp_path / "noisy.yaml").write_text(yaml.safe_dump(preset))
    first = _generate(tmp_path / "a", str(tmp_path / "noisy.yaml"))
    second = _generate(tmp_path / "b", f"{tmp_path / 'noisy.yaml'}@noise1")
    assert _digest(first / "frames") == _digest(second / "frames") != ""
    assert (first / "cameras.json").read_bytes() == (second / "cameras.json").read_bytes()
    a, b = read_events(first / "events" / "cam0.h5"), read_events(second / "events" / "cam0.h5")
    assert len(a) > 0 and len(b) > 0
    assert len(a) != len(b) or not np.array_equal(a.events, b.events)


def test_the_noise_axis_trains_seed_k_on_the_kth_realisation():
    cells = {"e4dgs": CellSpec("e4dgs")}
    cfg = build_config(BenchConfig, {"dataset": "tiny", "scenes": ["cubes"], "cells": cells, "seeds": 3,
                                     "seed_axes": ["train", "init", "noise"]})
    main = [j for j in jobs(cfg, Path("data") / "tiny") if j.study == "main"]
    assert [(j.seed, j.dataset) for j in main] == [(None, ""), (1, "tiny@noise1"), (2, "tiny@noise2")]
    assert main[2].data_dir == Path("data") / "tiny@noise2" / "cubes"
    assert main[2].overrides == {"train.seed": 2, "train.init.seed": 2}
