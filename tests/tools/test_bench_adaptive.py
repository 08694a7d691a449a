"""tools.bench_adaptive's generator call (datagen.build.generate_dataset): a generator killed by a
signal (Blender's heap corruption on long clips) is started again with the same command, so it
resumes from its checkpoint; one that exits with its own error is not."""
import json
import subprocess

import pytest

import bpy  # noqa: F401,E402  (a required dependency: a broken install fails here, not skips)


def _fake_workers(monkeypatch, codes, out, scene):
    """Popen replaced by workers that exit with `codes` in turn; a 0 writes the scene's manifest."""
    import tools.bench_adaptive as ba

    calls = []

    class Worker:
        def __init__(self, cmd, **kw):
            calls.append(cmd)
            self.returncode = codes[len(calls) - 1]
            if self.returncode == 0:
                (out / scene).mkdir(parents=True, exist_ok=True)
                (out / scene / "manifest.json").write_text(json.dumps({"scene": scene}))

        def poll(self):
            return self.returncode

    monkeypatch.setattr(subprocess, "Popen", Worker)
    return ba, calls


def test_a_crashed_generator_is_started_again_and_the_same_command_resumes(monkeypatch, tmp_path, capsys):
    from datagen.config import PRESETS_DIR

    out = tmp_path / "fixed"
    ba, calls = _fake_workers(monkeypatch, [-6, -11, 0], out, "cubes")
    assert ba.generate(PRESETS_DIR / "tiny.yaml", "cubes", {}, out) == {"scene": "cubes"}
    assert len(calls) == 3 and calls[0] == calls[1] == calls[2]          # the same out folder: it resumes
    assert str(out) in calls[0]
    assert capsys.readouterr().out.count("starting it again from its last checkpoint") == 2


def test_a_generator_that_keeps_crashing_or_fails_by_itself_is_reported(monkeypatch, tmp_path):
    from datagen.config import PRESETS_DIR

    preset = PRESETS_DIR / "tiny.yaml"
    ba, calls = _fake_workers(monkeypatch, [-6] * 5, tmp_path / "a", "cubes")
    with pytest.raises(SystemExit, match="cubes: generation failed"):
        ba.generate(preset, "cubes", {}, tmp_path / "a")
    assert len(calls) == ba.RETRIES + 1
    ba, calls = _fake_workers(monkeypatch, [2, 0], tmp_path / "b", "cubes")
    with pytest.raises(SystemExit, match="cubes: generation failed"):
        ba.generate(preset, "cubes", {}, tmp_path / "b")
    assert len(calls) == 1                                               # bad input would fail again
