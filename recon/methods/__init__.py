"""The methods registry: every reconstruction method the toolkit can train, by name.

A method is a class with `name`, `config_cls` (its typed config dataclass, which has a `train:
TrainConfig` field), `inputs` (what it sees: "rgb", "events") and the hooks the shared trainer calls
(see `recon.method.Method`). Every method, bundled or not, is named in the entry-point group
`e4dgs.methods` (the bundled ones in this project's pyproject.toml, BUNDLED below when the package's
metadata is absent, e.g. a checkout not installed); a plug-in in another package does the same

    [project.entry-points."e4dgs.methods"]
    my_method = "my_package.method:MyMethod"

and is then trained, rendered and benched like a bundled one (docs/guides/your_method.md). A method is
loaded when it is first asked for by name, so a plug-in that fails to import fails only for itself.
"""
from __future__ import annotations

import importlib
from importlib.metadata import entry_points

METHODS: dict[str, type] = {}
ENTRY_POINT_GROUP = "e4dgs.methods"
INPUTS = ("rgb", "events")

# the bundled methods' entry points (pyproject.toml declares the same; a test holds them equal)
BUNDLED = {"d3dgs": "recon.methods.d3dgs:D3DGS", "deblur_d3dgs": "recon.methods.deblur_d3dgs:DeblurD3DGS",
           "e2vid_d3dgs": "recon.methods.e2vid_d3dgs:E2VIDD3DGS", "e4dgs": "recon.methods.e4dgs:E4DGS",
           "e4dgs_rgb": "recon.methods.e4dgs:E4DGSRGB"}


class PluginError(ValueError):
    """A method plug-in cannot be loaded or does not describe a method."""


def check_method(cls: type, where: str) -> None:
    """PluginError (naming `where`) unless `cls` is a Method subclass with a name, a config class and inputs."""
    from recon.method import Method

    if not (isinstance(cls, type) and issubclass(cls, Method)):
        raise PluginError(f"{where}: expected a subclass of recon.method.Method, got {cls!r}")
    if not cls.name or not isinstance(cls.name, str):
        raise PluginError(f"{where}: {cls.__name__}.name is empty")
    if not hasattr(cls.config_cls, "__dataclass_fields__") or "train" not in cls.config_cls.__dataclass_fields__:
        raise PluginError(f"{where}: {cls.__name__}.config_cls must be a dataclass with a `train: TrainConfig` field")
    bad = [i for i in cls.inputs if i not in INPUTS]
    if not cls.inputs or bad:
        raise PluginError(f"{where}: {cls.__name__}.inputs must name what the method sees, some of "
                          f"{', '.join(INPUTS)}; got {tuple(cls.inputs)!r}")


def register(cls: type) -> type:
    if cls.name in METHODS and METHODS[cls.name] is not cls:
        raise ValueError(f"method {cls.name!r} is registered twice ({METHODS[cls.name].__module__} and {cls.__module__})")
    METHODS[cls.name] = cls
    return cls


class _Bundled:
    """An entry point of a bundled method, for a checkout whose package metadata is absent."""

    def __init__(self, name: str, value: str):
        self.name, self.value = name, value

    def load(self):
        module, _, attr = self.value.partition(":")
        return getattr(importlib.import_module(module), attr)


def _entry_points() -> dict:
    """{method name: entry point}: the group's, and the bundled ones its metadata lacks."""
    found = {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
    return {**{n: _Bundled(n, v) for n, v in BUNDLED.items() if n not in found}, **found}


def _load(name: str, ep) -> type:
    """Load, check and register the method of one entry point; PluginError naming it."""
    bundled = ep.value in BUNDLED.values()
    where = (f"method {name!r} ({ep.value})" if bundled
             else f"method plug-in {name!r} ({ep.value}, entry point group {ENTRY_POINT_GROUP})")
    try:
        cls = ep.load()
    except Exception as exc:  # noqa: BLE001 - any import failure of someone else's package, in one line
        raise PluginError(f"{where}: cannot be imported: {type(exc).__name__}: {exc}") from None
    check_method(cls, where)
    if cls.name != name:
        raise PluginError(f"{where}: the entry point's name must be the method's name {cls.name!r}")
    return register(cls)


def get_method(name: str) -> type:
    """The method class of `name`, loaded on first use; ValueError for an unknown name, PluginError for
    one whose entry point cannot be loaded (other methods are not affected)."""
    if name not in METHODS:
        ep = _entry_points().get(name)
        if ep is None:
            raise ValueError(f"unknown method {name!r}; registered methods: {', '.join(method_names())}")
        _load(name, ep)
    return METHODS[name]


def method_names() -> list[str]:
    """Every method's name: the entry points' and any registered in this process (none loaded)."""
    return sorted(set(_entry_points()) | set(METHODS))
