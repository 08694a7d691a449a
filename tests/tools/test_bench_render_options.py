"""tools.bench_render_options: the preset's own settings compared with themselves give no difference
(rendering and simulation are deterministic), and the variants are rendered and compared."""
import re

import pytest

pytest.importorskip("bpy")


def test_render_options_table_on_the_tiny_preset(capsys):
    from tools.bench_render_options import main

    assert main(["--scene", "cubes", "--preset", "tiny", "--duration-ms", "20", "--samples", "1", "8",
                 "--shadows", "on", "off"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if re.match(r"\| \d+ \| (on|off) \|", line)]
    cells = [[c.strip() for c in r.strip("|").split("|")] for r in rows]
    assert len(cells) == 4                                      # own (8, tiny's shadows) first, then 3 others
    own = cells[0]
    assert own[3] == "1.00x" and own[5] == "+0.00 %" and own[6] == "0.0 / 0.0" and own[7] == "0.00 %"
    assert {(c[0], c[1]) for c in cells} == {("1", "on"), ("8", "on"), ("1", "off"), ("8", "off")}
