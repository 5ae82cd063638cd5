"""Typed configuration: TOML tables loaded into frozen dataclasses.

Every parameter is a dataclass field declared with :func:`param`, which records
its unit, a one-line description and its bounds. :func:`build` turns a parsed
TOML table into the dataclass tree, and fails on the first unknown key, wrong
type or impossible value with a :class:`~gpusim.errors.ConfigError` that names
the file, the dotted key and the valid choices. :func:`apply_overrides`
implements ``--set a.b=c``; :func:`to_dict` exports a resolved config.

A field whose type is a *registry base* (a class with a ``registry`` dict of
name -> subclass and a ``kind`` field) is built by selecting the subclass named
by the table's ``kind`` key; unknown kinds fail with the list of valid ones.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal

from gpusim.errors import ConfigError


def param(default: Any = dataclasses.MISSING, *, unit: str = "", doc: str = "",
          min: float | None = None, max: float | None = None, gt: float | None = None) -> Any:
    """Declare a config field with its unit, description and inclusive/exclusive bounds."""
    meta = {"unit": unit, "doc": doc, "min": min, "max": max, "gt": gt}
    return dataclasses.field(default=default, metadata=meta)


def _fmt(value: Any) -> str:
    """A value as an error shows it; an empty string (``--param k=``) is said to be empty, not shown as ''."""
    if value == "":
        return "an empty value (give one after the '=')"
    return repr(value) if isinstance(value, str) else str(value)


class _Ctx:
    def __init__(self, where: str):
        self.where = where

    def fail(self, key: str, problem: str) -> typing.NoReturn:
        raise ConfigError(f"{self.where}: {key}: {problem}", key=key, problem=problem)


def _convert(value: Any, hint: Any, key: str, ctx: _Ctx) -> Any:
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Union or origin is types.UnionType:
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(value, inner[0], key, ctx)
    if origin is Literal:
        if value not in args:
            ctx.fail(key, f"{_fmt(value)} is not a valid choice (valid: {', '.join(map(str, args))})")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            ctx.fail(key, f"expected true or false, got {_fmt(value)}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            ctx.fail(key, f"expected an integer, got {_fmt(value)}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            ctx.fail(key, f"expected a number, got {_fmt(value)}")
        if not math.isfinite(value):
            ctx.fail(key, f"expected a finite number, got {value}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            ctx.fail(key, f"expected a string, got {_fmt(value)}")
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            ctx.fail(key, f"expected a list, got {_fmt(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{key}.{i}", ctx) for i, v in enumerate(value))
        if len(value) != len(args):
            ctx.fail(key, f"expected a list of {len(args)} values, got {len(value)}")
        return tuple(_convert(v, a, f"{key}.{i}", ctx) for i, (v, a) in enumerate(zip(value, args)))
    if dataclasses.is_dataclass(hint):
        return build(hint, value, ctx.where, key)
    raise TypeError(f"unsupported config type {hint!r} for {key}")  # programming error


def _check_bounds(value: Any, meta: typing.Mapping, key: str, ctx: _Ctx) -> None:
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return
    unit = f" {meta['unit']}" if meta.get("unit") not in (None, "", "1") else ""   # "1": dimensionless
    if meta.get("gt") is not None and not value > meta["gt"]:
        ctx.fail(key, f"must be > {meta['gt']}{unit}, got {value}")
    if meta.get("min") is not None and value < meta["min"]:
        ctx.fail(key, f"must be >= {meta['min']}{unit}, got {value}")
    if meta.get("max") is not None and value > meta["max"]:
        ctx.fail(key, f"must be <= {meta['max']}{unit}, got {value}")


def build(cls: type, data: Any, where: str, prefix: str = "") -> Any:
    """Build dataclass ``cls`` from a TOML table; ``where`` names the file for errors."""
    ctx = _Ctx(where)
    label = prefix or "(top level)"
    if not isinstance(data, dict):
        ctx.fail(label, f"expected a table, got {_fmt(data)}")
    registry = getattr(cls, "registry", None)
    if isinstance(registry, dict) and cls not in registry.values():
        kind = data.get("kind")
        if kind not in registry:
            ctx.fail(f"{prefix + '.' if prefix else ''}kind",
                     f"{_fmt(kind)} is not a known kind (valid: {', '.join(sorted(registry))})")
        cls = registry[kind]
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    dot = f"{prefix}." if prefix else ""
    unknown = [k for k in data if k not in fields]
    if unknown:
        ctx.fail(f"{dot}{unknown[0]}", f"unknown key (valid: {', '.join(fields)})")
    kwargs = {}
    for name, f in fields.items():
        key = f"{dot}{name}"
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                ctx.fail(key, "missing required key")
            continue
        value = _convert(data[name], hints[name], key, ctx)
        _check_bounds(value, f.metadata, key, ctx)
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except ValueError as exc:  # checks in __post_init__; a message "field: problem" names that field
        name, sep, problem = str(exc).partition(": ")
        if sep and name in fields:
            ctx.fail(f"{dot}{name}", problem)
        ctx.fail(prefix or cls.__name__, str(exc))


def parse_override(text: str, option: str = "--set", example: str = "camera.fov_y_deg=60",
                   form: str = "KEY=VALUE") -> tuple[list[str], Any]:
    """Parse ``a.b.c=value``; the value is read as a TOML value, else kept as a string.

    Errors name the command-line ``option`` the text came from and show ``example``.
    """
    if "=" not in text:
        raise ConfigError(f"{option} {text}: expected {form}, e.g. {option} {example}")
    key, raw = text.split("=", 1)
    parts = [p for p in key.strip().split(".")]
    if not key.strip() or any(not p for p in parts):
        raise ConfigError(f"{option} {text}: the key is empty or has an empty part")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    except RecursionError:
        raise ConfigError(f"{option} {key.strip()}=...: the value nests arrays or tables too deeply; "
                          f"flatten it") from None
    return parts, value


def apply_overrides(data: dict, overrides: typing.Iterable[str], option: str = "--set",
                    example: str = "camera.fov_y_deg=60") -> dict:
    """Apply ``--set`` overrides to a parsed TOML tree in place; numeric parts index lists.

    Errors name ``option`` (the command-line option the overrides came from).
    """
    for text in overrides:
        parts, value = parse_override(text, option, example)
        node: Any = data
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            where = ".".join(parts[: i + 1])
            if isinstance(node, list):
                if not part.isdigit() or int(part) >= len(node):
                    raise ConfigError(f"{option} {text}: '{where}' is not an index into a list of "
                                      f"{len(node)} entries (valid: 0..{len(node) - 1})")
                part = int(part)
            elif not isinstance(node, dict):
                raise ConfigError(f"{option} {text}: '{'.'.join(parts[:i])}' is a value, not a table")
            if last:
                node[part] = value
            else:
                if isinstance(node, dict) and part not in node:
                    node[part] = {}
                node = node[part]
    return data


def build_overridden(builder: typing.Callable[[dict, str], Any], table: dict, where: str,
                     overrides: typing.Sequence[str], option: str = "--set",
                     example: str = "camera.fov_y_deg=60", labels: typing.Sequence[str] | None = None) -> Any:
    """``builder(table, where)`` with command-line ``overrides`` applied (a copy; ``table`` is kept).

    A problem of the table itself names the file ``where``; one that only the
    overrides bring names the override that set the key at fault (``option
    KEY=VALUE``, or ``labels[i]`` for ``overrides[i]`` when given), or all of
    them when the problem has no single key.
    """
    data = apply_overrides(copy.deepcopy(table), overrides, option, example)
    try:
        return builder(data, where)
    except ConfigError as exc:
        if not overrides:
            raise
        builder(copy.deepcopy(table), where)       # the file's own problem: it names the file
        key = exc.key or ""
        labels = labels or [f"{option} {text}" for text in overrides]
        related = [label for text, label in zip(overrides, labels)
                   if (k := ".".join(parse_override(text)[0])) == key or key.startswith(k + ".")
                   or (key and k.startswith(key + "."))]
        blamed = related[-1:] or list(dict.fromkeys(labels))   # the last setting of a key is the one that counts
        problem = exc.problem.removeprefix(f"{where}: ")
        raise ConfigError(f"{' '.join(blamed)}: {key + ': ' if key else ''}{problem}",
                          key=exc.key, problem=exc.problem) from None


def load_toml(path: str | Path) -> dict:
    """Parse a TOML file; syntax errors become a one-line ConfigError."""
    path = Path(path)
    try:
        with open(path, "rb") as handle:
            return tomllib.load(handle)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file; check the path") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, not a TOML file; name the file") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start}); save the file as UTF-8") \
            from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML ({exc})") from None
    except RecursionError:
        raise ConfigError(f"{path}: arrays or tables nested too deeply for the TOML reader; flatten them") from None


def to_dict(obj: Any) -> Any:
    """A plain (JSON/TOML-ready) tree of a built config, tuples as lists."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (tuple, list)):
        return [to_dict(v) for v in obj]
    return obj


def type_name(hint: Any) -> str:
    """A parameter type as a user writes it: ``int``, ``float``, ``bool``, ``str``, ``float | None``,
    ``'peel' | 'sort-blend'``."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is Literal:
        return " | ".join(repr(a) for a in args)
    if origin is typing.Union or origin is types.UnionType:
        return " | ".join(type_name(a) for a in args)
    if hint is type(None):
        return "None"
    if origin is tuple:
        inner = ", ".join("..." if a is Ellipsis else type_name(a) for a in args)
        return f"tuple[{inner}]"
    return getattr(hint, "__name__", str(hint))


def describe(cls: type) -> list[dict]:
    """Name, type, default, unit and description of each parameter of ``cls``."""
    hints = typing.get_type_hints(cls)
    rows = []
    for f in dataclasses.fields(cls):
        default = None if f.default is dataclasses.MISSING else f.default
        rows.append({"name": f.name, "type": type_name(hints[f.name]),
                     "default": default, "unit": f.metadata.get("unit", ""),
                     "doc": f.metadata.get("doc", "")})
    return rows
