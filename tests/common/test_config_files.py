"""The config layout (configs/<kind>/...), name lookup, E4DGS_CONFIG_PATH and the names of before 0.2."""
import warnings
from pathlib import Path

import pytest

from common.config_files import ShadowedName, DEPRECATED, DeprecatedName, _WARNED, find, search_dirs, shipped_names

REPO = Path(__file__).resolve().parents[2]


def test_every_kind_has_its_folder_and_the_leaderboard_recipes_are_the_quick_ones():
    for kind in ("datasets", "sensors", "recipes", "bench"):
        assert search_dirs(kind)[0] == REPO / "configs" / kind and search_dirs(kind)[0].is_dir()
    assert {"tiny", "quick", "quick_realistic", "paper"} <= set(shipped_names("datasets"))
    assert {"ideal", "realistic"} <= set(shipped_names("sensors"))
    import yaml

    quick = yaml.safe_load((REPO / "configs/bench/quick.yaml").read_text())
    for name, cell in quick["cells"].items():      # the leaderboard's recipe is `<method>/quick`, found by name
        assert cell["config"] == f"{cell['method']}/quick", name
        assert find("recipes", "quick", cell["method"]) == REPO / f"configs/recipes/{cell['method']}/quick.yaml"


def test_nothing_but_the_four_kinds_sits_in_configs():
    top = sorted(p.name for p in (REPO / "configs").iterdir())
    assert top == ["bench", "datasets", "recipes", "sensors"], top


def test_test_fixtures_are_not_shipped():
    assert "tiny_motion" not in {p.stem for p in (REPO / "configs").rglob("*.yaml")}
    assert (REPO / "tests/fixtures/configs/datasets/tiny_motion.yaml").is_file()


@pytest.mark.parametrize("old", sorted(DEPRECATED))
def test_an_old_name_resolves_to_its_new_file_with_a_deprecation_line(old, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)           # from any folder
    _WARNED.discard(old)
    kind, new = DEPRECATED[old]
    with pytest.warns(DeprecatedName, match=rf"{old!r} is an old name .*use {new!r}"):
        found = find(kind, old)
    assert found is not None and found.resolve() == find(kind, new).resolve()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        find(kind, old)                   # one line per name and process


def test_the_config_path_adds_folders_after_the_shipped_ones(tmp_path, monkeypatch):
    (tmp_path / "datasets").mkdir()
    (tmp_path / "datasets" / "mine.yaml").write_text("scenes: [cubes]\n")
    (tmp_path / "datasets" / "quick.yaml").write_text("scenes: [cubes]\n")      # never shadows a shipped one
    monkeypatch.setenv("E4DGS_CONFIG_PATH", str(tmp_path))
    assert find("datasets", "mine") == tmp_path / "datasets" / "mine.yaml"
    with pytest.warns(ShadowedName, match=r"'quick' names 2 files: configs/datasets/quick.yaml is used, .*datasets/"
                                          r"quick.yaml is shadowed"):
        assert find("datasets", "quick") == REPO / "configs/datasets/quick.yaml"
    assert "mine" in shipped_names("datasets")


def test_a_users_sensor_shadowed_by_a_shipped_one_is_named_on_the_command_line(tmp_path, monkeypatch, capsys):
    from e4dgs.cli import main
    from common.config_files import _SHADOWED
    from common.imageio import write_png
    import numpy as np

    _SHADOWED.clear()
    (tmp_path / "sensors").mkdir()
    (tmp_path / "sensors" / "ideal.yaml").write_text("pos_threshold: 0.5\nneg_threshold: 0.5\n")
    monkeypatch.setenv("E4DGS_CONFIG_PATH", str(tmp_path))
    frames = tmp_path / "frames"
    frames.mkdir()
    for k in range(3):
        write_png(frames / f"{k:03d}.png", np.full((4, 5, 3), 0.2 + 0.2 * k))
    assert main(["simulate", str(frames), "--fps", "1000", "--out", str(tmp_path / "e.h5"), "--config", "ideal"]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("warning:")]
    assert len(err) == 1 and "configs/sensors/ideal.yaml is used" in err[0] and str(tmp_path) in err[0], err


def test_an_old_command_line_config_name_prints_one_deprecation_line(tmp_path, capsys):
    from e4dgs.cli import main

    _WARNED.discard("configs/sim_realistic.yaml")
    frames = tmp_path / "frames"
    frames.mkdir()
    from common.imageio import write_png
    import numpy as np

    for k in range(3):
        write_png(frames / f"{k:03d}.png", np.full((4, 5, 3), 0.2 + 0.2 * k))
    assert main(["simulate", str(frames), "--fps", "1000", "--out", str(tmp_path / "e.h5"),
                 "--config", str(REPO / "configs/sim_realistic.yaml")]) == 0
    err = capsys.readouterr().err
    assert err.count("warning: config") == 1 and "use 'realistic' (configs/sensors/realistic.yaml)" in err


def test_an_empty_config_file_is_an_error_not_every_default(tmp_path, monkeypatch):
    """An empty `datasets/empty.yaml` on the search path once started all eight scenes at full size."""
    import pytest

    from common.config import ConfigError
    from datagen.config import load_preset

    (tmp_path / "datasets").mkdir()
    (tmp_path / "datasets" / "empty.yaml").write_text("# nothing yet\n")
    monkeypatch.setenv("E4DGS_CONFIG_PATH", str(tmp_path))
    with pytest.raises(ConfigError, match=r"empty.yaml: empty config file"):
        load_preset("empty")
    (tmp_path / "datasets" / "empty.yaml").write_text("{}\n")        # every default, said so
    assert len(load_preset("empty").scenes) == 8
