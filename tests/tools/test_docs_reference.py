"""docs/reference/cli.md and configs.md are what the code says (tools/docs_reference.py)."""
from tools.docs_reference import main


def test_the_generated_reference_pages_are_up_to_date(capsys):
    assert main(["--check"]) == 0, capsys.readouterr().err


def test_a_changed_help_text_makes_the_check_fail(monkeypatch, capsys):
    import tools.docs_reference as dr

    real = dr.cli_page
    monkeypatch.setattr(dr, "cli_page", lambda: real().replace("e4dgs verify", "e4dgs verify-all"))
    assert main(["--check"]) == 1 and "docs/reference/cli.md" in capsys.readouterr().err


def test_a_config_field_without_a_word_fails_the_generator():
    from dataclasses import dataclass

    import pytest

    from tools.docs_reference import config_rows

    @dataclass(frozen=True)
    class Described:
        size: str = "x"  # what it is

    @dataclass(frozen=True)
    class Silent:
        size: str = "x"

    assert "what it is" in config_rows(Described)[0]
    with pytest.raises(ValueError, match="Silent.size: no description"):
        config_rows(Silent)
