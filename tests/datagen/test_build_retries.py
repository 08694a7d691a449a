"""`e4dgs dataset` without Ray starts a crashed scene worker again (it resumes from its checkpoint) and
does not retry one that exits with its own error. The worker is replaced by a small script that
counts its starts and crashes or exits as told."""
import signal
import sys

import pytest

import datagen.build as build


def fake_worker(monkeypatch, tmp_path, behaviour: str):
    """Each start appends a line to tmp_path/<scene>.starts, then acts by `behaviour`:
    'abort-once' dies from SIGABRT on its first start only, 'abort' always, 'exit1' exits with status 1."""
    script = (
        "import os, signal, sys\n"
        "scene, behaviour, root = sys.argv[1], sys.argv[2], sys.argv[3]\n"
        "path = os.path.join(root, scene + '.starts')\n"
        "n = len(open(path).readlines()) if os.path.exists(path) else 0\n"
        "open(path, 'a').write('start\\n')\n"
        "if behaviour == 'exit1': sys.exit(1)\n"
        "if behaviour == 'abort' or (behaviour == 'abort-once' and n == 0): os.kill(os.getpid(), signal.SIGABRT)\n"
    )

    def cmd(preset, scene, out, checkpoint_every, extra=None):
        return [sys.executable, "-c", script, scene, behaviour, str(tmp_path)]

    monkeypatch.setattr(build, "_worker_cmd", cmd)


def starts(tmp_path, scene="s") -> int:
    return len((tmp_path / f"{scene}.starts").read_text().splitlines())


def run(tmp_path, retries=2):
    lines = []
    failed = build.generate_dataset("tiny", None, tmp_path / "out", log=lines.append,
                                    scene_args={"s": ["--scene", "s"]}, retries=retries)
    return failed, lines


def test_a_crashed_worker_is_started_again_and_the_scene_finishes(monkeypatch, tmp_path):
    fake_worker(monkeypatch, tmp_path, "abort-once")
    failed, lines = run(tmp_path)
    assert failed == [] and starts(tmp_path) == 2
    assert any(f"signal {int(signal.SIGABRT)}" in line and "restart 1 of 2" in line for line in lines)


def test_a_worker_that_always_crashes_fails_after_its_retries(monkeypatch, tmp_path):
    fake_worker(monkeypatch, tmp_path, "abort")
    failed, _ = run(tmp_path, retries=2)
    assert failed == ["s"] and starts(tmp_path) == 3


def test_no_retries_reports_the_first_crash(monkeypatch, tmp_path):
    fake_worker(monkeypatch, tmp_path, "abort")
    failed, _ = run(tmp_path, retries=0)
    assert failed == ["s"] and starts(tmp_path) == 1


def test_a_worker_that_exits_with_its_own_error_is_not_retried(monkeypatch, tmp_path):
    fake_worker(monkeypatch, tmp_path, "exit1")
    failed, lines = run(tmp_path)
    assert failed == ["s"] and starts(tmp_path) == 1
    assert not any("restart" in line for line in lines)


def test_retries_must_not_be_negative(tmp_path):
    with pytest.raises(ValueError, match="retries"):
        build.generate_dataset("tiny", None, tmp_path, scene_args={"s": []}, retries=-1)


def test_crashed_tells_signals_from_exit_statuses():
    assert build.crashed(-int(signal.SIGABRT)) and build.crashed(-int(signal.SIGKILL))
    assert not build.crashed(1) and not build.crashed(2)
