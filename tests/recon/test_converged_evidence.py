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


# The runs of `converged` alone (tools.field_curves with --set on the recipe file), by the tag in their
# file name: field_curves_{scene}_e4dgs_converged_{tag}_900s_2threads.json. `densify270` ran on the
# Xeon when the recipe's field was 4 x 128 (its command sets only densify.stop): the recipe's values
# then, beyond what the command sets, are written here. All three encoded positions with D3DGS's 10
# frequencies, before the recipe's 6.
BEFORE_FREQS = {"train.deform_field.position_freqs": "10"}
ALONE = {"densify270": {"train.deform_field.width": "128", **BEFORE_FREQS}, "width96": BEFORE_FREQS,
         "width64": BEFORE_FREQS}
ALONE_FILE = {"densify270": "densify270_900s_2threads", "width96": "width96_900s_2threads_zen3",
              "width64": "width64_900s_2threads_zen3"}


def evidence(scene, tag="densify270"):
    return json.loads((EVIDENCE / f"field_curves_{scene}_e4dgs_converged_{ALONE_FILE[tag]}.json").read_text())


def shipped_recipe() -> dict:
    return yaml.safe_load((REPO / "configs/recipes/e4dgs/converged.yaml").read_text())


def sets_of(command: str) -> dict[str, str]:
    args = shlex.split(command)
    assert args[args.index("--config") + 1] == "configs/recipes/e4dgs/converged.yaml"
    return dict(args[i + 1].split("=", 1) for i, a in enumerate(args) if a == "--set")


def alone_differences(command: str, then: dict[str, str]) -> dict[str, tuple[str, str]]:
    """{key: (what the run trained with, what the recipe ships)} where they differ."""
    recipe, out = shipped_recipe(), {}
    for key, value in {**then, **sets_of(command)}.items():
        node = recipe
        for part in key.split("."):
            node = node[part]
        if str(node) != value:
            out[key] = (value, str(node))
    return out


FREQS = {"train.deform_field.position_freqs": ("10", "6")}


@pytest.mark.parametrize("scene, tag, differs", [("hinge", "densify270", {"train.deform_field.width": ("128", "96"), **FREQS}),
                                                 ("lego", "densify270", {"train.deform_field.width": ("128", "96"), **FREQS}),
                                                 ("hinge", "width96", FREQS), ("lego", "width96", FREQS),
                                                 ("hinge", "width64", {"train.deform_field.width": ("64", "96"), **FREQS})])
def test_each_alone_run_differs_from_the_shipped_recipe_by_what_the_docs_say(scene, tag, differs):
    ev = evidence(scene, tag)
    assert sets_of(ev["command"]), "the runs set the changed value on the recipe's earlier settings"
    assert alone_differences(ev["command"], ALONE[tag]) == differs


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_xeon_alone_run_meets_the_goal_within_900_s(scene):
    """The Xeon, field in bf16, 4 x 128: both goals within 900 s (docs/results/learning_curves.md)."""
    whole, moving = GOALS[scene]
    ev = evidence(scene)
    assert "Xeon" in ev["cpu"]
    curve = ev["curves"]["mlp"]
    within = [p for p in curve if p["wall_s"] <= 900.5]
    assert within[-1].get("stopped") and within[-1]["wall_s"] >= 899     # the run's point at 900 s
    assert any(p["psnr"] >= whole for p in within)
    if moving is not None:
        assert any(p["psnr_dyn"] >= moving for p in within)


# -- the three recipes alternated in one process (tools.curves_alternated) ----------------------------
# "": the run with today's recipes; "freqs10_zen3": the same machine with `converged`'s position encoding
# at D3DGS's 10 frequencies (and the field's autograd layers); "width128_zen3": that and a 4 x 128 field;
# "densify375_xeon": the earlier run on a 2-core Intel Xeon, when `converged` had that field and
# densified until 375 of its schedule's 450 steps (docs/results/learning_curves.md).
RUNS = ["", "freqs10_zen3", "width128_zen3", "densify375_xeon"]


def alternated(scene, which=""):
    name = f"alternated_curves_{scene}_e4dgs_{which + '_' if which else ''}2threads.json"
    return json.loads((EVIDENCE / name).read_text())


def differences(ran, shipped, where=""):
    """The keys where the config a run recorded differs from what the code and recipes resolve today."""
    if isinstance(shipped, dict) and isinstance(ran, dict):
        return [d for k in sorted(set(ran) | set(shipped))
                for d in differences(ran.get(k, "<absent>"), shipped.get(k, "<absent>"), f"{where}.{k}")]
    if isinstance(shipped, (list, tuple)) and isinstance(ran, (list, tuple)):
        return [] if list(ran) == list(shipped) else [f"{where[1:]}: ran {ran}, resolves to {shipped}"]
    return [] if ran == shipped else [f"{where[1:]}: ran {ran!r}, resolves to {shipped!r}"]


def differing_keys(ev):
    """{recipe: [keys where its recorded config differs from what it resolves to today]}."""
    from common.config import to_dict
    import recon
    from tools.field_curves import run_overrides

    out = {}
    for r in ev["runs"]:
        ran = json.loads(json.dumps(ev["configs"][r["name"]]))
        # recorded before the setting existed: the field then always encoded 10 frequencies
        ran["train"]["deform_field"].setdefault("position_freqs", 10)
        overrides = run_overrides("e4dgs", str(REPO / r["config"]), r["field"], r["scale"], {}, ran["train"]["snapshots"])
        shipped = to_dict(recon.resolve_config("e4dgs", str(REPO / r["config"]), overrides))
        out[r["name"]] = [d.split(":")[0] for d in differences(ran, shipped)]
    return out


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_alternated_runs_are_todays_recipes(scene):
    """Each curve was trained with exactly what its recipe resolves to today (snapshots aside)."""
    ev = alternated(scene)
    assert [r["name"] for r in ev["runs"]] == ["converged", "trajectory", "mlp"]
    assert ev["max_train_s"] == 900
    assert differing_keys(ev) == {"converged": [], "trajectory": [], "mlp": []}


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_earlier_runs_differ_only_in_converged_s_field_and_where_densification_ends(scene):
    """The runs the docs compare with: the same three recipes but for `converged`'s position encoding
    (10 frequencies) and then its width (4 x 128) on the Zen 3, and both and densify.stop on the Xeon."""
    freqs10 = alternated(scene, "freqs10_zen3")
    zen3, xeon = alternated(scene, "width128_zen3"), alternated(scene, "densify375_xeon")
    f, w = "train.deform_field.position_freqs", "train.deform_field.width"
    assert differing_keys(freqs10) == {"converged": [f], "trajectory": [], "mlp": []}
    assert differing_keys(zen3) == {"converged": [f, w], "trajectory": [], "mlp": []}
    assert differing_keys(xeon) == {"converged": [f, w, "train.densify.stop"], "trajectory": [], "mlp": []}
    for ev in (zen3, xeon):
        assert ev["configs"]["converged"]["train"]["deform_field"]["width"] == 128
    assert xeon["configs"]["converged"]["train"]["densify"]["stop"] > shipped_recipe()["train"]["densify"]["stop"]
    assert "Xeon" in xeon["cpu"] and zen3["cpu"].startswith("AMD EPYC")


def assert_converged_leads(last):
    """`converged` at 900 s ahead of both other recipes' last points by > 1.5 dB whole, > 0.9 moving."""
    for other in ("trajectory", "mlp"):
        assert last["converged"]["psnr"] > last[other]["psnr"] + 1.5, other
        assert last["converged"]["psnr_dyn"] > last[other]["psnr_dyn"] + 0.9, other


def zen3_run_at_stop(ev) -> dict:
    """The last point of each curve of a run in turns on the Zen 3, after checking what every such
    run shares: an AMD EPYC without AVX-512, both fields measured faster in float32 at every start,
    `converged` and the paper's MLP stopped by the 900 s budget, `converged` leading both others."""
    assert ev["cpu"].startswith("AMD EPYC") and "avx512" not in ev["cpu"]
    assert {start["dtype"] for start in ev["precision"]["converged"] + ev["precision"]["mlp"]} == {"float32"}
    last = {name: curve[-1] for name, curve in ev["curves"].items()}
    for name in ("converged", "mlp"):
        assert last[name].get("stopped") and 900 <= last[name]["wall_s"] <= 901, name
    assert_converged_leads(last)
    return last


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_4x128_run_in_turns_says_what_the_docs_say(scene):
    """docs/results/learning_curves.md ("A 4 x 128 field in turns on an AMD EPYC Zen 3"): on a core
    without bf16 both fields ran in float32; `converged` leads both other recipes at
    900 s on every pixel and on the moving ones; lego passes its goal at ~770 s and its model at the
    stop is above it; hinge meets neither goal, stopping within 0.5 / 0.3 dB of them."""
    whole, moving = GOALS[scene]
    ev = alternated(scene, "width128_zen3")
    last = zen3_run_at_stop(ev)
    assert last["trajectory"]["iteration"] == 10800 and last["trajectory"]["wall_s"] < 900   # its whole schedule
    reached = ev["reached_s"]["converged"]
    if scene == "lego":
        assert reached["psnr"] is not None and 740 < reached["psnr"] < 800
        assert last["converged"]["psnr"] > whole                    # no densification since 60 % of the run
    else:
        assert reached["psnr"] is None and reached["psnr_dyn"] is None
        assert whole - 0.5 < last["converged"]["psnr"] < whole and moving - 0.3 < last["converged"]["psnr_dyn"] < moving


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_4x96_field_with_10_frequencies_in_turns_says_what_the_docs_say(scene):
    """docs/results/learning_curves.md ("A 4 x 96 field with 10 frequencies in turns on an AMD EPYC
    Zen 3"): float32 for both fields; `converged` leads both other recipes at 900 s;
    level per step with the 4 x 128 run in turns and ahead of it at 900 s; hinge 0.19 / 0.10 dB
    short of its goals; lego past its goal at ~660 s (~770 s with 4 x 128) and above it at the stop."""
    whole, moving = GOALS[scene]
    ev, w128 = alternated(scene, "freqs10_zen3"), alternated(scene, "width128_zen3")
    assert ev["configs"]["converged"]["train"]["deform_field"]["width"] == 96
    last = zen3_run_at_stop(ev)
    before = w128["curves"]["converged"]
    assert last["converged"]["iteration"] > before[-1]["iteration"] * 1.1          # more steps in the 900 s
    at, at_before = ({p["iteration"]: p for p in c} for c in (ev["curves"]["converged"], before))
    step = 7560 if scene == "hinge" else 7020                                       # the docs' step
    assert abs(at[step]["psnr"] - at_before[step]["psnr"]) < 0.1                   # level per step
    reached = ev["reached_s"]["converged"]
    if scene == "hinge":
        assert last["converged"]["psnr"] > before[-1]["psnr"] + 0.2 and last["converged"]["psnr_dyn"] > before[-1]["psnr_dyn"] + 0.1
        assert reached["psnr"] is None and reached["psnr_dyn"] is None
        assert whole - 0.25 < last["converged"]["psnr"] < whole and moving - 0.15 < last["converged"]["psnr_dyn"] < moving
        # a slower host than the 4 x 128 run's: the unchanged trajectories did not finish by 900 s this time
        assert last["trajectory"]["iteration"] < 10800 and last["trajectory"]["wall_s"] >= 900
    else:
        assert reached["psnr"] is not None and 640 < reached["psnr"] < 680
        assert reached["psnr"] < w128["reached_s"]["converged"]["psnr"] - 90
        assert last["converged"]["psnr"] > whole + 1.0 and last["converged"]["psnr"] > before[-1]["psnr"] + 0.2


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_earlier_run_says_what_the_docs_say(scene):
    """docs/results/learning_curves.md (the Xeon run in turns, densification to 5/6 of the run):
    `converged` leads both other recipes at 900 s on every pixel and on the moving ones; lego passes
    its goal before 900 s (its model at the stop, just after a densification, does not); hinge, on a
    slower host state, meets neither of its goals by 900 s."""
    whole, moving = GOALS[scene]
    ev = alternated(scene, "densify375_xeon")
    at_stop = {name: curve[-1] for name, curve in ev["curves"].items()}
    for name, last in at_stop.items():
        assert last.get("stopped") and 900 <= last["wall_s"] <= 901, name
    assert_converged_leads(at_stop)
    reached = ev["reached_s"]["converged"]
    if scene == "lego":
        assert reached["psnr"] is not None and 600 < reached["psnr"] < 700
        assert at_stop["converged"]["psnr"] < whole                 # the stop 3 steps after a densification
    else:
        assert reached["psnr"] is None and reached["psnr_dyn"] is None
        assert whole - 0.2 < at_stop["converged"]["psnr"] < whole and moving - 0.3 < at_stop["converged"]["psnr_dyn"] < moving


def test_the_narrower_field_lead_says_what_the_docs_say():
    """learning_curves.md ("A 4 x 96 field on the Zen 3"): the shipped recipe with width 96 and nothing
    else changed, alone on the Zen 3; at 900 s within 0.15 / 0.1 dB below hinge's goals and above the
    4 x 128 run's 900 s in turns; level with 4 x 128 at 7,560 steps."""
    ev = json.loads((EVIDENCE / "field_curves_hinge_e4dgs_converged_width96_900s_2threads_zen3.json").read_text())
    assert sets_of(ev["command"]) == {"train.deform_field.width": "96"} and ev["cpu"].startswith("AMD EPYC")
    whole, moving = GOALS["hinge"]
    curve, turns = ev["curves"]["mlp"], alternated("hinge", "width128_zen3")["curves"]["converged"]
    last = curve[-1]
    assert last.get("stopped") and 900 <= last["wall_s"] <= 901
    assert whole - 0.15 < last["psnr"] < whole and moving - 0.1 < last["psnr_dyn"] < moving
    assert last["psnr"] > turns[-1]["psnr"] + 0.25 and last["psnr_dyn"] > turns[-1]["psnr_dyn"] + 0.15
    at = {p["iteration"]: p for p in curve}
    assert abs(at[7560]["psnr"] - next(p["psnr"] for p in turns if p["iteration"] == 7560)) < 0.05
    lego = json.loads((EVIDENCE / "field_curves_lego_e4dgs_converged_width96_900s_2threads_zen3.json").read_text())
    assert sets_of(lego["command"]) == {"train.deform_field.width": "96"}
    lego_turns = alternated("lego", "width128_zen3")["curves"]["converged"]
    assert lego["curves"]["mlp"][-1]["psnr"] > GOALS["lego"][0] and abs(lego["curves"]["mlp"][-1]["psnr"] - lego_turns[-1]["psnr"]) < 0.1


def test_a_4x64_field_learns_less_per_step_than_4x96():
    """learning_curves.md ("A 4 x 64 field"): alone on the Zen 3, 4 x 64 is below 4 x 96 by > 0.3 /
    > 0.3 dB at 8,100 steps and below it at 900 s, whatever its steps cost."""
    narrow, w96 = evidence("hinge", "width64")["curves"]["mlp"], evidence("hinge", "width96")["curves"]["mlp"]
    at64, at96 = {p["iteration"]: p for p in narrow}, {p["iteration"]: p for p in w96}
    assert at64[8100]["psnr"] < at96[8100]["psnr"] - 0.3 and at64[8100]["psnr_dyn"] < at96[8100]["psnr_dyn"] - 0.3
    assert narrow[-1].get("stopped") and narrow[-1]["psnr"] < w96[-1]["psnr"] - 0.4
    assert narrow[-1]["iteration"] < w96[-1]["iteration"]      # and no more steps in the 900 s


@pytest.mark.parametrize("which", RUNS)
@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_turns_alternate(scene, which):
    """Every recipe took its turn in each pass (the slices' "round"), in order, before the next pass began."""
    ev = alternated(scene, which)
    order = [(s["round"], s["run"]) for s in ev["slices"]]
    assert order == sorted(order, key=lambda x: (x[0], ["converged", "trajectory", "mlp"].index(x[1])))
    assert {s["round"] for s in ev["slices"]} == set(range(1, 7))
    assert all(s["until_s"] == 150 * s["round"] for s in ev["slices"])


def test_six_frequencies_learn_more_per_step_than_ten_on_hinge():
    """learning_curves.md ("Six frequencies for the position encoding"): the 6-frequency run is ahead of
    the 10-frequency run alone at every step they share from the 1/2-size stage on, by > 0.1 dB whole
    and moving; 8 frequencies gain as much on the whole image."""
    ev = json.loads((EVIDENCE / "position_freqs_hinge_e4dgs_converged_1thread_zen3.json").read_text())
    assert sets_of(ev["command"]) == {"train.deform_field.position_freqs": "N"} and ev["cpu"].startswith("AMD EPYC")
    ten = {p["iteration"]: p for p in evidence("hinge", "width96")["curves"]["mlp"]}
    for freqs in ("6", "8"):
        at = {p["iteration"]: p for p in ev["curves"][freqs]}
        for step in (4320, 5400, 6480):
            assert at[step]["psnr"] > ten[step]["psnr"] + 0.1, (freqs, step)
            if freqs == "6":
                assert at[step]["psnr_dyn"] > ten[step]["psnr_dyn"] + 0.1, step


@pytest.mark.parametrize("scene", sorted(GOALS))
def test_the_shipped_recipe_in_turns_meets_the_goals(scene):
    """docs/results/learning_curves.md ("... the shipped recipe in turns on an AMD EPYC Zen 3") and the
    README: 6 frequencies and the written-out backward; `converged` leads both other recipes at 900 s and
    meets its goals within 900 s, by thin margins on hinge; ahead of the 10-frequency run per step and at
    900 s. Training is deterministic: the trajectories score exactly what they scored in that run, the
    paper's MLP too until its deformation starts, and within rounding's drift after (it runs the
    written-out backward now)."""
    whole, moving = GOALS[scene]
    ev, before = alternated(scene), alternated(scene, "freqs10_zen3")
    field = ev["configs"]["converged"]["train"]["deform_field"]
    assert (field["width"], field["position_freqs"]) == (96, 6)
    last = zen3_run_at_stop(ev)
    reached = ev["reached_s"]["converged"]
    assert reached["psnr"] is not None and reached["psnr"] <= 900
    assert last["converged"]["psnr"] >= whole
    at, at_before = ({p["iteration"]: p for p in e["curves"]["converged"]} for e in (ev, before))
    for name in ("trajectory", "mlp"):
        now, then = ({p["iteration"]: p["psnr"] for p in e["curves"][name] if not p.get("stopped")} for e in (ev, before))
        shared = set(now) & set(then)
        assert len(shared) >= 8, name
        for i in shared:
            static = name == "trajectory" or i < 3600       # the MLP recipe deforms from 1/3 of its run on
            assert abs(now[i] - then[i]) < (1e-9 if static else 0.05), (name, i)
    if scene == "hinge":
        assert 860 < reached["psnr"] < 880 and 795 < reached["psnr_dyn"] < 815
        assert 0 < last["converged"]["psnr"] - whole < 0.1 and 0 < last["converged"]["psnr_dyn"] - moving < 0.1
        for step in (7560, 8100):
            assert at[step]["psnr"] > at_before[step]["psnr"] + 0.1, step
        assert last["converged"]["iteration"] > before["curves"]["converged"][-1]["iteration"]
        assert last["converged"]["psnr"] > before["curves"]["converged"][-1]["psnr"] + 0.2
    else:
        assert 630 < reached["psnr"] < 660 and last["converged"]["psnr"] > whole + 1.5
        for step in (7020, 8100):
            assert at[step]["psnr"] > at_before[step]["psnr"] + 0.3 and at[step]["psnr_dyn"] > at_before[step]["psnr_dyn"] + 0.3
        assert last["converged"]["psnr"] > before["curves"]["converged"][-1]["psnr"] + 0.3
