"""The methods registry: every reconstruction method the toolkit can train, by name.

A method is a class with `name`, `config_cls` (its typed config dataclass, which has a `train:
TrainConfig` field) and the hooks the shared trainer calls (see `recon.method.Method`). Later
modules add themselves with `@register`.
"""
from __future__ import annotations

import importlib

METHODS: dict[str, type] = {}

# modules that register methods when imported
_MODULES = ("recon.methods.d3dgs", "recon.methods.e4dgs", "recon.methods.e2vid_d3dgs", "recon.methods.deblur_d3dgs")


def register(cls: type) -> type:
    if cls.name in METHODS and METHODS[cls.name] is not cls:
        raise ValueError(f"method {cls.name!r} is registered twice")
    METHODS[cls.name] = cls
    return cls


def _load_all() -> None:
    for mod in _MODULES:
        importlib.import_module(mod)


def get_method(name: str) -> type:
    _load_all()
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; registered methods: {', '.join(sorted(METHODS))}")
    return METHODS[name]


def method_names() -> list[str]:
    _load_all()
    return sorted(METHODS)
