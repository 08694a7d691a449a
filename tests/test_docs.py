"""The docs agree with the shipped configs: a page that quotes a speed level, a leaderboard cell's
iterations or a speed-variant folder is checked against configs/bench/quick.yaml. Results pages
(docs/results/) record what was measured when, and are left out; every other page speaks of now."""
import re
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
LABELS = {"E2VID + D3DGS": "e2vid_d3dgs", "Deblur-D3DGS": "deblur_d3dgs", "sharp D3DGS": "d3dgs_sharp",
          "blurred D3DGS": "d3dgs_blur", "events-only E-4DGS": "e4dgs", "E-4DGS + RGB": "e4dgs_rgb"}


def quick() -> dict:
    return yaml.safe_load((ROOT / "configs" / "bench" / "quick.yaml").read_text())


def iterations(cfg: dict, scene: str, cell: str) -> int | None:
    return cfg.get("scene_overrides", {}).get(scene, {}).get(cell, {}).get("train.iterations")


def contradictions(text: str, cfg: dict) -> list[str]:
    """Every claim in `text` about the quick preset that its config contradicts."""
    levels = {k: float(v) for k, v in cfg["speed_levels"].items()}
    speeds = {float(s) for s in cfg.get("speed", {}).get("speeds", [])} | set(levels.values())
    bad = []
    for m in re.finditer(r"\b(mild|medium|strong)\b[^.\n]{0,40}?\bx(\d+(?:\.\d+)?)\b", text):
        if float(m.group(2)) != levels[m.group(1)]:
            bad.append(f"{m.group(0)!r}: the {m.group(1)} level is x{levels[m.group(1)]:g}")
    for m in re.finditer(r"\b(hinge|lego|garage)_x(\d+(?:\.\d+)?)\b", text):
        if float(m.group(2)) not in speeds:
            bad.append(f"{m.group(0)!r}: no speed variant x{m.group(2)} in the quick preset ({sorted(speeds)})")
    for m in re.finditer(r"\b(\w+): (\w+): \{train\.iterations: (\d+)", text):
        want = iterations(cfg, m.group(1), m.group(2))
        if want is not None and want != int(m.group(3)):
            bad.append(f"{m.group(0)!r}: quick.yaml says {want}")
    for label, cell in LABELS.items():
        for m in re.finditer(rf"{re.escape(label)} on (hinge|lego|garage) for ([\d,]+) iterations", text):
            want = iterations(cfg, m.group(1), cell)
            if want is not None and want != int(m.group(2).replace(",", "")):
                bad.append(f"{m.group(0)!r}: quick.yaml says {want}")
    return bad


def pages() -> list[Path]:
    docs = [p for p in (ROOT / "docs").rglob("*.md") if "results" not in p.relative_to(ROOT / "docs").parts
            and "evidence" not in p.parts]
    return [ROOT / "README.md"] + sorted(docs)


@pytest.mark.parametrize("page", pages(), ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_quotes_the_shipped_configs_as_they_are(page):
    assert contradictions(page.read_text(), quick()) == []


def test_the_checked_claims_are_there_to_check():
    """The architecture page's worked example and the README's leaderboard quote the preset: the
    check above has something to hold them to."""
    arch = (ROOT / "docs" / "design" / "architecture.md").read_text()
    assert re.search(r"E2VID \+ D3DGS on hinge for \d+ iterations", arch)
    assert re.search(r"hinge: e2vid_d3dgs: \{train\.iterations: \d+", arch)
    assert re.search(r"hinge_x\d", arch)
    readme = (ROOT / "README.md").read_text()
    assert re.search(r"mild[^.\n]{0,40}x\d", readme) or re.search(r"x\d+(\.\d+)? through a 2 ms", readme)


@pytest.mark.parametrize("planted, words", [
    ("`configs/bench/quick.yaml` trains E2VID + D3DGS on hinge for 220 iterations", "quick.yaml says 670"),
    ("(`scene_overrides: hinge: e2vid_d3dgs: {train.iterations: 221, ...}`)", "quick.yaml says 670"),
    ("its training folder is `hinge_x37.6/e2vid_d3dgs-...`", "no speed variant x37.6"),
    ("at the **mild speed level** (x31.6 through a 2 ms shutter)", "the mild level is x26.2"),
])
def test_a_planted_contradiction_is_caught(planted, words):
    cfg = quick()
    assert cfg["speed_levels"]["mild"] == 26.2 and iterations(cfg, "hinge", "e2vid_d3dgs") == 670
    found = contradictions(planted, cfg)
    assert len(found) == 1 and words in found[0], found


def missing_config_paths(text: str) -> list[str]:
    """`configs/....yaml` paths a page names that the repository does not have."""
    return sorted({p for p in re.findall(r"configs/[\w./-]+?\.yaml", text) if not (ROOT / p).is_file()})


@pytest.mark.parametrize("page", [ROOT / "README.md"] + sorted(
    p for p in (ROOT / "docs").rglob("*.md")), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_config_file_a_page_names_exists(page):
    """Results pages included: a user follows their paths too (old names work until 0.3, but the
    pages name the shipped files)."""
    assert missing_config_paths(page.read_text()) == []


def test_a_renamed_config_path_is_caught():
    assert missing_config_paths("see configs/recon/bench/d3dgs_quick.yaml and configs/datasets/quick.yaml") == [
        "configs/recon/bench/d3dgs_quick.yaml"]


def yaml_comments(path: Path) -> str:
    """The comment text of a YAML file (what follows '#' on each line), as prose."""
    return "\n".join(line.split("#", 1)[1] for line in path.read_text().splitlines() if "#" in line)


YAML_FILES = sorted((ROOT / "configs").rglob("*.yaml")) + sorted((ROOT / "blender_scenes").glob("*.yaml"))


@pytest.mark.parametrize("path", YAML_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_yaml_comments_hold_to_the_configs_too(path):
    """A config's comments are docs as well: the claims and paths the pages are held to, and a recipe's
    header stating its iterations states the value it sets."""
    text = yaml_comments(path)
    assert contradictions(text, quick()) == []
    assert missing_config_paths(text) == []
    if "recipes" in path.parts:
        header = "\n".join(ln for ln in path.read_text().splitlines()[:4] if ln.startswith("#"))
        # "N iterations" as the recipe's length (not "every N iterations" nor "written for N iterations")
        stated = re.search(r"(?<!every )(?<!written for )\b([\d,]+) iterations\b", header)
        set_to = (yaml.safe_load(path.read_text()) or {}).get("train", {}).get("iterations")
        if stated and set_to is not None:
            assert int(stated.group(1).replace(",", "")) == set_to, f"{path}: the header says {stated.group(0)}, " \
                                                                   f"train.iterations is {set_to}"


def test_a_recipe_header_that_disagrees_is_caught(tmp_path):
    recipe = tmp_path / "recipes" / "r.yaml"
    recipe.parent.mkdir()
    recipe.write_text("# E-4DGS for the quick benchmark: 450 iterations\ntrain:\n  iterations: 900\n")
    with pytest.raises(AssertionError, match="the header says 450 iterations"):
        test_yaml_comments_hold_to_the_configs_too(recipe)
