"""tools.bench_render_options: the preset's own settings compared with themselves give no difference
(rendering and simulation are deterministic), and the variants are rendered and compared."""
import re


import bpy  # noqa: F401,E402  (a required dependency: a broken install fails here, not skips)


def test_render_options_table_on_the_tiny_preset(capsys):
    from tools.bench_render_options import main

    assert main(["--scene", "cubes", "--preset", "tiny", "--duration-ms", "20", "--samples", "1", "8",
                 "--shadows", "on", "off"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if re.match(r"\| \d+ \| (on|off) \|", line)]
    cells = [[c.strip() for c in r.strip("|").split("|")] for r in rows]
    own = cells[0]                                              # the preset's own settings first
    assert own[3] == "1.00x" and own[5] == "+0.00 %" and own[6] == "0.0 / 0.0" and own[7] == "0.00 %"
    asked = {(s, sh) for s in ("1", "8") for sh in ("on", "off")}
    assert {(c[0], c[1]) for c in cells[1:]} == asked - {(own[0], own[1])} and len(cells) == 1 + len(asked - {(own[0], own[1])})
    no_aa = next(c for c in cells if c[0] == "1" and c[1] == own[1])
    assert float(no_aa[5].split()[0]) > 0                       # aliased edges flicker: more events without AA
