"""Every old name the toolkit still accepts, in one registry with the release each one ends at.

    from common.deprecations import REGISTRY, ENDS, kept_until
    kept_until("module", "simulator.h5io")      # "0.3"

Kinds: `module` (an old import path, an alias of the new module), `command` (an old `e4dgs`
subcommand), `option` (an old option spelling, stored into the new one), `config` (an old config file
name or path, resolved by common.config_files) and `bench preset` (benchmark.config). Each mechanism
reads its names and its deprecation line's release from here; tests/common/test_deprecations.py fails once the
toolkit's version reaches an entry's end, so its removal is not forgotten, and fails on an old name
a mechanism accepts that is not registered.
"""
from __future__ import annotations

from dataclasses import dataclass

ENDS = "0.3"          # the release the names deprecated in 0.2 are removed in


@dataclass(frozen=True)
class Deprecated:
    kind: str         # module | command | option | config | bench preset
    old: str
    new: str
    since: str = "0.2"
    ends: str = ENDS


_MOVED_TO_EVENTIO = ("events", "event_check", "h5io", "evt_codec", "vendor_formats", "rosbag_io", "ros_messages",
                     "export", "formats")
# old option spelling -> what replaces it, for each command that had one (common.argtypes.add_main_input)
_OPTIONS = {"e4dgs bench --methods": "--cells", "e4dgs simulate --frames": "FRAMES (first argument)",
            "e4dgs train --scene": "SCENE (first argument)", "e4dgs render --model": "MODEL (first argument)",
            "e4dgs e2vid --events": "EVENTS (first argument)", "e4dgs score --renders": "RENDERS (first argument)"}

# old config name or path -> (kind, new name) (common.config_files resolves them)
_RECIPES_OLD = {f"configs/recon/bench/{m}_quick.yaml": f"{m}/quick"
                for m in ("d3dgs", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")}
_RECIPES_OLD |= {f"bench/{m}_quick": f"{m}/quick" for m in ("d3dgs", "deblur_d3dgs", "e2vid_d3dgs", "e4dgs", "e4dgs_rgb")}
_RECIPES_OLD |= {"configs/recon/d3dgs_quick.yaml": "d3dgs/mlp", "configs/recon/e4dgs_quick.yaml": "e4dgs/mlp",
                 "d3dgs_quick": "d3dgs/mlp", "e4dgs_quick": "e4dgs/mlp"}
CONFIG_NAMES: dict[str, tuple[str, str]] = {
    **{f"configs/dataset_{p}.yaml": ("datasets", p) for p in ("tiny", "quick", "quick_realistic", "paper")},
    **{f"configs/sim_{p}.yaml": ("sensors", p) for p in ("ideal", "realistic")},
    **{old: ("recipes", new) for old, new in _RECIPES_OLD.items()},
}
# old bench preset -> (preset, overrides of every cell) (benchmark.config)
BENCH_PRESETS = {"paper_gpu": ("paper", {"train.device": "cuda", "train.backend": "gsplat"})}

REGISTRY: tuple[Deprecated, ...] = (
    *(Deprecated("module", f"simulator.{m}", f"eventio.{m}") for m in _MOVED_TO_EVENTIO),
    Deprecated("module", "simulator.event_pictures", "eventio.representations"),
    Deprecated("command", "view", "draw-events"),
    *(Deprecated("option", old, new) for old, new in _OPTIONS.items()),
    *(Deprecated("config", old, f"{kind}/{new}") for old, (kind, new) in CONFIG_NAMES.items()),
    *(Deprecated("bench preset", old, new) for old, (new, _) in BENCH_PRESETS.items()),
)


def registered(kind: str) -> dict[str, Deprecated]:
    """{old name: entry} of one kind."""
    return {d.old: d for d in REGISTRY if d.kind == kind}


def kept_until(kind: str, old: str) -> str:
    """The release an old name ends at; KeyError for a name that is not registered."""
    return registered(kind)[old].ends


def renamed_commands() -> dict[str, str]:
    """{old command: new command}."""
    return {d.old: d.new for d in REGISTRY if d.kind == "command"}
