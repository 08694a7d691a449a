"""common.progress: a job's position told through a file, with the time left at its rate."""
import json

from common import progress


def test_nothing_is_written_unless_someone_listens(tmp_path, monkeypatch):
    monkeypatch.delenv(progress.ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    progress.report(1, 10, "it")
    assert list(tmp_path.iterdir()) == []


def test_a_report_gives_position_and_time_left_at_the_rate_since_the_unit_began(tmp_path, monkeypatch):
    path = tmp_path / "job.log.progress"
    monkeypatch.setenv(progress.ENV, str(path))
    clock = iter([100.0, 100.5, 102.0, 110.0, 111.0, 112.0])
    monkeypatch.setattr(progress.time, "time", lambda: next(clock))
    progress._state.update(path=None)
    progress.report(0, 100, "it")                  # t = 100: the unit starts
    progress.report(5, 100, "it")                  # t = 100.5: within a second of the last write: skipped
    assert progress.read(path)["done"] == 0
    progress.report(10, 100, "it")                 # t = 102: 10 in 2 s -> 90 left take 18 s
    info = progress.read(path)
    assert (info["done"], info["total"]) == (10, 100) and progress.seconds_left(info) == 18.0
    assert progress.describe(info) == "10/100 it, ~18 s left"
    progress.report(40, 100, "it")                 # t = 110: 40 in 10 s -> 60 left take 15 s
    assert progress.seconds_left(progress.read(path)) == 15.0
    progress.report(1, 7, "timestamps")            # t = 111: a new unit starts its own rate
    info = progress.read(path)
    assert info["unit"] == "timestamps" and progress.seconds_left(info) is None
    assert progress.describe(info) == "1/7 timestamps"
    progress.report(7, 7, "timestamps")            # the last one is always written
    assert progress.describe(progress.read(path)) == "7/7 timestamps"
    assert [p.name for p in tmp_path.iterdir()] == ["job.log.progress"]      # no temporary debris


def test_durations_read_naturally():
    assert [progress._duration(s) for s in (0.2, 59, 95, 3000, 7200)] == ["1 s", "59 s", "2 min", "50 min", "2.0 h"]


def test_an_unreadable_report_is_no_report(tmp_path):
    (tmp_path / "a").write_text("{not json")
    (tmp_path / "b").write_text(json.dumps({"done": 1}))
    assert progress.read(tmp_path / "a") is None and progress.read(tmp_path / "b") is None
    assert progress.read(tmp_path / "missing") is None and progress.describe(None) == ""
