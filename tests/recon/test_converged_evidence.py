"""The `converged` recipe's 900 s figures (README, docs/results/learning_curves.md) were measured with
the settings it ships, and they meet the goal they are cited for: fails when the recipe changes
without its curves being measured again."""
import json
import shlex
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
EVIDENCE = REPO / "docs" / "evidence"
# scene: (whole-image goal dB, moving-pixel goal dB or None) within 900 s of training
GOALS = {"hinge": (36.0, 25.5), "lego": (33.5, None)}


def evidence(scene):
    return json.loads((EVIDENCE / f"field_curves_{scene}_e4dgs_converged_init5k_warm75_900s_2threads.json").read_text())


def sets_of(command: str) -> dict[str, str]:
    args = shlex.split(command)
    assert args[args.index("--config") + 1] == "configs/recipes/e4dgs/converged.yaml"
    return dict(args[i + 1].split("=", 1) for i, a in enumerate(args) if a == "--set")


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_evidence_was_made_with_the_shipped_recipe(scene):
    recipe = yaml.safe_load((REPO / "configs/recipes/e4dgs/converged.yaml").read_text())
    sets = sets_of(evidence(scene)["command"])
    assert sets, "the runs set the two changed values on the recipe's earlier settings"
    for key, value in sets.items():
        node = recipe
        for part in key.split("."):
            node = node[part]
        assert str(node) == value, f"{key}: the recipe ships {node}, the evidence ran {value}"


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_evidence_meets_the_goal_within_900_s(scene):
    whole, moving = GOALS[scene]
    curve = evidence(scene)["curves"]["mlp"]
    within = [p for p in curve if p["wall_s"] <= 900.5]
    assert within[-1].get("stopped") and within[-1]["wall_s"] >= 899     # the run's point at 900 s
    assert any(p["psnr"] >= whole for p in within)
    if moving is not None:
        assert any(p["psnr_dyn"] >= moving for p in within)
