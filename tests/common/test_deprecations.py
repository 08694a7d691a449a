"""One registry of old names (common.deprecations): every old name a mechanism accepts is in it, and
the test fails once the toolkit's version reaches an entry's end, so its removal is not forgotten."""
import argparse
import re
from pathlib import Path

import pytest

import common
from common.deprecations import REGISTRY, registered

ROOT = Path(__file__).resolve().parents[2]


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(v) for v in re.findall(r"\d+", text)[:3])


@pytest.mark.parametrize("kind", ["module", "command", "option", "config", "bench preset"])
def test_no_old_name_outlives_its_release(kind):
    entries = registered(kind)
    assert entries, kind
    for old, d in entries.items():
        assert _version(common.__version__) < _version(d.ends), (
            f"{kind} {old!r} ends at {d.ends} and the toolkit is {common.__version__}: remove it (and its registry entry)")


def test_every_alias_module_is_registered():
    aliases = {f"simulator.{p.stem}" for p in (ROOT / "simulator").glob("*.py")
               if "alias(__name__" in p.read_text()}
    assert aliases and aliases == set(registered("module"))


def test_every_old_command_and_option_spelling_is_registered():
    from e4dgs.cli import RENAMED_COMMANDS, build_parser
    from common.argtypes import DeprecatedOption

    assert set(RENAMED_COMMANDS) == set(registered("command"))
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    found = {f"e4dgs {name} {opt}" for name, p in sub.choices.items() for a in p._actions
             if isinstance(a, DeprecatedOption) for opt in a.option_strings}
    assert found == set(registered("option")), found ^ set(registered("option"))


def test_the_version_is_written_once():
    """pyproject takes its version from common.__version__; CITATION.cff quotes it."""
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert 'dynamic = ["version"]' in pyproject and 'version = {attr = "common.__version__"}' in pyproject
    assert not re.search(r'^version = "', pyproject, re.M)
    cff = (ROOT / "CITATION.cff").read_text()
    assert all(v == common.__version__ for v in re.findall(r"^version: \"?([\d.]+)", cff, re.M))


def test_a_registered_name_past_its_end_fails(monkeypatch):
    monkeypatch.setattr(common, "__version__", "0.3.0")
    with pytest.raises(AssertionError, match="remove it"):
        test_no_old_name_outlives_its_release("module")
    assert len(REGISTRY) >= 11


def test_the_config_and_preset_mechanisms_read_the_registry():
    from benchmark.config import RENAMED_PRESETS
    from common.config_files import DEPRECATED

    assert set(DEPRECATED) == set(registered("config")) and set(RENAMED_PRESETS) == set(registered("bench preset"))
