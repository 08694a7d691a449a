"""Typed, frozen configuration dataclasses loaded strictly from YAML.

`load_config(cls, path)` reads a YAML mapping with `yaml.safe_load` and builds `cls` from it:
unknown keys, wrong types and invalid values raise `ConfigError` naming the file and the key's
dotted path (e.g. ``sim.yaml: noise.shot_rate_hz: expected a number, got 'fast'``). Dataclasses
validate their own values in `__post_init__` by raising `ConfigError` with the field name; the loader
prefixes it with the file and the path of the enclosing key.
"""
from __future__ import annotations

import copy
import math

import dataclasses
import os
import re
import types
import typing
from pathlib import Path
from typing import Any, Literal, Mapping, TypeVar, get_args, get_origin, get_type_hints

import yaml

T = TypeVar("T")
_YAML11_EXPONENT = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+")


class ConfigWarning(UserWarning):
    """A config value that is allowed but far outside the usual range (the message says why it matters)."""


class ConfigError(ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range."""


def check_positive(obj, *names: str) -> None:
    """ConfigError naming the first of `names` whose value on `obj` is not > 0."""
    for name in names:
        if not getattr(obj, name) > 0:
            raise ConfigError(f"{name}: expected a positive value, got {getattr(obj, name)!r}")


MAX_SHOWN = 80     # characters of a wrong value an error message shows (YAML anchors can expand without bound)


def shown(value: Any) -> str:
    """repr(value), cut to MAX_SHOWN characters with its full length said."""
    text = repr(value)
    return text if len(text) <= MAX_SHOWN else f"{text[:MAX_SHOWN]}... ({len(text):,} characters)"


def _describe(value: Any) -> str:
    return f"{shown(value)} ({type(value).__name__})"


def _convert(tp: Any, value: Any, path: str) -> Any:
    origin = get_origin(tp)
    if tp is Any:
        return value
    if origin is Literal:
        allowed = get_args(tp)
        if value not in allowed:
            raise ConfigError(f"{path}: expected one of {list(allowed)}, got {_describe(value)}")
        return value
    if origin in (typing.Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, path)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if len(errors) == 1 else f"{path}: no accepted type matches {_describe(value)}")
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, Mapping):
            raise ConfigError(f"{path}: expected a mapping, got {_describe(value)}")
        return from_dict(tp, value, path)
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{path}: expected a list, got {_describe(value)}")
        args = get_args(tp)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(args) != len(value):
                raise ConfigError(f"{path}: expected {len(args)} items, got {len(value)}")
            items = [_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value))]
        else:
            item_tp = args[0] if args else Any
            items = [_convert(item_tp, v, f"{path}[{i}]") for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{path}: expected a mapping, got {_describe(value)}")
        k_tp, v_tp = get_args(tp) or (Any, Any)
        return {_convert(k_tp, k, path): _convert(v_tp, v, f"{path}.{k}") for k, v in value.items()}
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true or false, got {_describe(value)}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: expected an integer, got {_describe(value)}")
        if not -2 ** 63 <= value < 2 ** 63:      # seeds, counts: what NumPy, HDF5 and torch store
            raise ConfigError(f"{path}: expected an integer within 64 bits, got one of {len(str(abs(value)))} digits")
        return value
    if tp is float:
        if isinstance(value, str) and _YAML11_EXPONENT.fullmatch(value.strip()):
            value = float(value)  # PyYAML (YAML 1.1) reads 1e-4 (no dot) as a string
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: expected a number, got {_describe(value)}")
        try:
            value = float(value)
        except OverflowError:                       # an integer beyond any float
            raise ConfigError(f"{path}: expected a finite number, got an integer of {len(str(value))} digits") from None
        if not math.isfinite(value):               # .inf / .nan: no quantity of a config is infinite
            raise ConfigError(f"{path}: expected a finite number, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {_describe(value)}")
        return value
    raise TypeError(f"{path}: unsupported config field type {tp!r}")


MAX_ITERATIONS = 10_000_000       # steps of any schedule: 200x the paper's 50,000 (days on any machine)
SEED_RANGE = (0, 2 ** 63 - 1, "a 64-bit seed")


def check_bounds(obj: Any) -> None:
    """ConfigError naming the first field outside its range in the class's `BOUNDS` ({field: (lo, hi,
    why)}, inclusive, None = open): every size, count and rate gets a range that follows from what it
    means, so a typo (fourier: 1000000) is refused before it allocates 24 GB."""
    for name, (lo, hi, why) in getattr(type(obj), "BOUNDS", {}).items():
        value = getattr(obj, name)
        if value is None or isinstance(value, bool):
            continue
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            span = f"{'-inf' if lo is None else f'{lo:g}'} .. {'inf' if hi is None else f'{hi:g}'}"
            raise ConfigError(f"{name}: expected {span} ({why}), got {shown(value)}")


def _field_default(field: dataclasses.Field) -> Any:
    if field.default is not dataclasses.MISSING:
        return field.default
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return dataclasses.MISSING


def from_dict(cls: type[T], data: Mapping[str, Any], path: str = "", base: Any = None) -> T:
    """Build dataclass `cls` from a mapping; unknown keys and bad values raise `ConfigError`.

    Keys the mapping leaves out take their values from `base` (an instance of cls) when given, else
    from the field defaults. A nested dataclass given as a partial mapping is filled from the
    enclosing field's default instance, so `train: {iterations: 10}` keeps what a method's own
    default TrainConfig sets, not only what TrainConfig's class defaults say.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path or '<top>'}: expected a mapping, got {_describe(data)}")
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    prefix = f"{path}." if path else ""
    for key in data:
        if key not in fields:
            raise ConfigError(f"{prefix}{key}: unknown key (known keys: {', '.join(sorted(fields))})")
    kwargs = {}
    for name, field in fields.items():
        default = getattr(base, name) if base is not None else _field_default(field)
        if name in data:
            value, tp = data[name], hints[name]
            if dataclasses.is_dataclass(tp) and isinstance(value, Mapping) and isinstance(default, tp):
                kwargs[name] = from_dict(tp, value, f"{prefix}{name}", base=default)
            else:
                kwargs[name] = _convert(tp, value, f"{prefix}{name}")
        elif default is dataclasses.MISSING:
            raise ConfigError(f"{prefix}{name}: required key is missing")
        elif base is not None:
            kwargs[name] = default
    try:
        obj = cls(**kwargs)
        check_bounds(obj)
        return obj
    except ConfigError as exc:
        raise ConfigError(f"{prefix}{exc}") from None


def to_dict(obj: Any) -> Any:
    """Plain-Python (YAML-safe) view of a config dataclass."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [to_dict(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_dict(v) for k, v in obj.items()}
    return obj


class _StrictLoader(yaml.SafeLoader):
    """safe_load that refuses a key written twice in one mapping (YAML would keep the last silently);
    merge keys (`<<: *base`) work as in YAML, their keys overridden by the mapping's own."""


def _no_duplicates(loader: _StrictLoader, node: yaml.MappingNode, deep: bool = False) -> dict:
    seen: dict = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":     # `<<: *base`: merged keys may be overridden below
            continue
        key = loader.construct_object(key_node, deep=deep)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"key {key!r} appears twice (lines {seen[key] + 1} and {key_node.start_mark.line + 1})",
                key_node.start_mark)
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _no_duplicates)


MAX_YAML_VALUES = 1_000_000    # values of a config file once its aliases are expanded


def expanded_size(data: Any, limit: int = MAX_YAML_VALUES) -> int:
    """How many values `data` holds with every shared (aliased) list or mapping counted each time it is
    referenced, computed once per object (so a 500-byte alias bomb is measured, not walked); counting
    stops just past `limit`."""
    memo: dict[int, int] = {}

    def size(v: Any, depth: int) -> int:
        if not isinstance(v, (list, tuple, dict)):
            return 1
        if id(v) in memo:
            return memo[id(v)]
        if depth > 200:                   # a self-referencing alias: infinite
            return limit + 1
        memo[id(v)] = limit + 1           # a cycle back to v while it is being measured
        items = list(v.keys()) + list(v.values()) if isinstance(v, dict) else v
        total = 1
        for item in items:
            total += size(item, depth + 1)
            if total > limit:
                break
        memo[id(v)] = total
        return total
    return size(data, 0)


def read_yaml_mapping(path: Path) -> dict:
    """The mapping at the top of a YAML file; ConfigError naming the file otherwise: an empty file (or
    one of comments only: a config that says nothing would silently mean every default, e.g. all
    eight scenes at full size) and a key given twice in one mapping included."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file (a YAML config is UTF-8 text)") from None
    try:
        data = yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {' '.join(str(exc).split())}") from None
    n = expanded_size(data)
    if n > MAX_YAML_VALUES:
        raise ConfigError(f"{path}: its aliases (*name) expand to {n:,} values, more than any config holds "
                          f"({MAX_YAML_VALUES:,}): an alias bomb, or aliases nested too deep")
    if data is None:
        raise ConfigError(f"{path}: empty config file (expected a mapping of settings; write `{{}}` for every "
                          "default)")
    if not isinstance(data, Mapping):
        raise ConfigError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return dict(data)


def load_config(cls: type[T], path: str | os.PathLike, overrides: Mapping[str, Any] | None = None) -> T:
    """Load `cls` from the YAML file at `path` (strict); `overrides` are applied on top of it."""
    path = Path(path)
    data = read_yaml_mapping(path)
    data.update(overrides or {})
    try:
        return from_dict(cls, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


def dump_config(obj: Any) -> str:
    """YAML text of a (resolved) config, keys in declaration order."""
    return yaml.safe_dump(to_dict(obj), sort_keys=False)


def replace_checked(obj: T, **changes: Any) -> T:
    """`dataclasses.replace` that goes through the strict converter (types checked, unknown keys named)."""
    data = to_dict(obj)
    for key in changes:
        if key not in data:
            raise ConfigError(f"{key}: unknown key (known keys: {', '.join(sorted(data))})")
    data.update(changes)
    return from_dict(type(obj), data)


def set_dotted(data: dict, key: str, value: Any) -> None:
    """data[a][b][c] = value for key 'a.b.c' (creating mappings on the way)."""
    parts = key.split(".")
    node = data
    for part in parts[:-1]:
        nxt = node.setdefault(part, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"{key}: {part} is not a mapping")
        node = nxt
    node[parts[-1]] = value


def parse_set(items: list[str]) -> dict[str, Any]:
    """`--set key=value` items -> {dotted key: YAML-parsed value}."""
    out = {}
    for item in items:
        if "=" not in item:
            raise ConfigError(f"--set {item!r}: expected key=value")
        key, value = item.split("=", 1)
        try:
            out[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            raise ConfigError(f"--set {key.strip()}: the value {shown(value)} is not valid YAML "
                              f"({' '.join(str(exc).split())})") from None
    return out


def build_config(cls: type[T], config: Any = None, overrides: Mapping[str, Any] | None = None,
                 overrides_source: str = "--set") -> T:
    """A typed config from None (defaults), a YAML path, a mapping or an instance, with
    dotted-key overrides applied on top. Unknown keys raise ConfigError naming the key and where it
    came from: the file (or "<config>"), or `overrides_source` when the config is valid without the
    overrides and only they make it wrong."""
    source = overrides_source if config is None else "<config>"
    if config is None:
        data: dict = {}
    elif isinstance(config, (str, Path)):
        source = str(config)
        data = read_yaml_mapping(Path(config))
    elif isinstance(config, Mapping):
        data = dict(config)
    elif isinstance(config, cls):
        data = to_dict(config)
    else:
        raise TypeError(f"config must be None, a YAML path, a mapping or a {cls.__name__}, got {type(config).__name__}")
    if overrides and config is not None:
        try:
            from_dict(cls, copy.deepcopy(data))          # the file alone: its own errors are its own
        except ConfigError as exc:
            raise ConfigError(f"{source}: {exc}") from None
        source = overrides_source
    for key, value in (overrides or {}).items():
        set_dotted(data, key, value)
    try:
        return from_dict(cls, data)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
