"""tools.bench_adaptive's generator call: a generator killed by a signal (Blender's heap corruption on
long clips) is started again and resumes; one that exits with its own error is not."""
import json
import subprocess
from types import SimpleNamespace

import pytest

pytest.importorskip("bpy")


def _fake_runs(monkeypatch, codes, out, scene):
    import tools.bench_adaptive as ba

    calls = []

    def run(cmd, **kw):
        calls.append(cmd)
        code = codes[len(calls) - 1]
        if code == 0:
            (out / scene).mkdir(parents=True, exist_ok=True)
            (out / scene / "manifest.json").write_text(json.dumps({"scene": scene}))
        return SimpleNamespace(returncode=code, stderr="free(): corrupted unsorted chunks" if code else "")

    monkeypatch.setattr(subprocess, "run", run)
    return ba, calls


def test_a_crashed_generator_is_started_again_and_the_same_command_resumes(monkeypatch, tmp_path, capsys):
    from datagen.config import PRESETS_DIR

    out = tmp_path / "fixed"
    ba, calls = _fake_runs(monkeypatch, [-6, -11, 0], out, "cubes")
    assert ba.generate(PRESETS_DIR / "dataset_tiny.yaml", "cubes", {}, out) == {"scene": "cubes"}
    assert len(calls) == 3 and calls[0] == calls[1] == calls[2]          # the same out folder: it resumes
    assert capsys.readouterr().out.count("resuming from its checkpoint") == 2


def test_a_generator_that_keeps_crashing_or_fails_by_itself_is_reported(monkeypatch, tmp_path):
    from datagen.config import PRESETS_DIR

    preset = PRESETS_DIR / "dataset_tiny.yaml"
    ba, calls = _fake_runs(monkeypatch, [-6] * 5, tmp_path / "a", "cubes")
    with pytest.raises(SystemExit, match="cubes: generation failed"):
        ba.generate(preset, "cubes", {}, tmp_path / "a")
    assert len(calls) == ba.RETRIES + 1
    ba, calls = _fake_runs(monkeypatch, [2, 0], tmp_path / "b", "cubes")
    with pytest.raises(SystemExit, match="cubes: generation failed"):
        ba.generate(preset, "cubes", {}, tmp_path / "b")
    assert len(calls) == 1                                               # bad input would fail again
