"""The methods registry: every reconstruction method the toolkit can train, by name.

A method is a class with `name`, `config_cls` (its typed config dataclass, which has a `train:
TrainConfig` field), `inputs` (what it sees: "rgb", "events") and the hooks the shared trainer calls
(see `recon.method.Method`). The bundled methods add themselves with `@register`. A method in
another package is a plug-in: it names its class in the entry-point group `e4dgs.methods`

    [project.entry-points."e4dgs.methods"]
    my_method = "my_package.method:MyMethod"

and is then trained, rendered and benched like a bundled one (docs/guides/your_method.md).
"""
from __future__ import annotations

import importlib
from importlib.metadata import entry_points

METHODS: dict[str, type] = {}
ENTRY_POINT_GROUP = "e4dgs.methods"
INPUTS = ("rgb", "events")

# modules that register methods when imported
_MODULES = ("recon.methods.d3dgs", "recon.methods.e4dgs", "recon.methods.e2vid_d3dgs", "recon.methods.deblur_d3dgs")
_plugins_loaded = False


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


def _load_plugins() -> None:
    """Register every method named in the entry-point group (once per process)."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        where = f"method plug-in {ep.name!r} ({ep.value}, entry point group {ENTRY_POINT_GROUP})"
        try:
            cls = ep.load()
        except Exception as exc:  # noqa: BLE001 - any import failure of someone else's package, in one line
            raise PluginError(f"{where}: cannot be imported: {type(exc).__name__}: {exc}") from None
        check_method(cls, where)
        if cls.name != ep.name:
            raise PluginError(f"{where}: the entry point's name must be the method's name {cls.name!r}")
        register(cls)


def _load_all() -> None:
    for mod in _MODULES:
        importlib.import_module(mod)
    _load_plugins()


def get_method(name: str) -> type:
    _load_all()
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; registered methods: {', '.join(sorted(METHODS))}")
    return METHODS[name]


def method_names() -> list[str]:
    _load_all()
    return sorted(METHODS)
