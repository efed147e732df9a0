"""Strict dataclass configs: build nested dataclasses from YAML dicts and apply dotted CLI overrides.

A typo in a config key must fail loudly (a silently ignored key can waste a multi-day run), so unknown keys,
missing required keys and wrong types raise UserError naming the source and the dotted key.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from robot_hoi.errors import UserError

T = TypeVar("T")


def load_dataclass(cls: type[T], data: Any, source: str = "config") -> T:
    """Build `cls` (a dataclass, possibly nested) from a plain dict; `source` names the file in errors."""
    return _convert(cls, data, source, "")


def load_yaml_dataclass(cls: type[T], path: str | Path, overrides: list[str] | None = None) -> T:
    """Read a YAML file into `cls`, then apply dotted overrides like ["ppo.actor_lr=3e-4"]."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise UserError(f"{path}: config file not found") from None
    except yaml.YAMLError as exc:
        raise UserError(f"{path}: not valid YAML ({exc})") from None
    obj = load_dataclass(cls, {} if data is None else data, str(path))
    return apply_overrides(obj, overrides or [], source=str(path))


def apply_overrides(obj: T, overrides: list[str], source: str = "overrides") -> T:
    """Return a copy of dataclass `obj` with "dotted.key=value" overrides applied (values parsed as YAML)."""
    data = dataclasses.asdict(obj)
    for item in overrides:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise UserError(f"override {item!r}: expected dotted.key=value")
        try:
            value = yaml.safe_load(raw) if raw.strip() else None
        except yaml.YAMLError as exc:
            raise UserError(f"override {item!r}: value is not valid YAML ({exc})") from None
        node = data
        parts = key.split(".")
        for depth, part in enumerate(parts):
            if not isinstance(node, dict) or part not in node:
                where = ".".join(parts[: depth + 1])
                known = ", ".join(sorted(node)) if isinstance(node, dict) else "(not a section)"
                raise UserError(f"override {item!r}: unknown key {where!r} (known here: {known})")
            if depth == len(parts) - 1:
                node[part] = value
            else:
                node = node[part]
    return load_dataclass(type(obj), data, f"{source} + overrides")


def _convert(tp: Any, value: Any, source: str, key: str) -> Any:
    where = f"{source}: {key or '<root>'}"
    origin = typing.get_origin(tp)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return _convert_dataclass(tp, value, source, key)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(tp)
        if value is None:
            if type(None) in options:
                return None
            raise UserError(f"{where}: must not be null")
        errors = []
        for option in options:
            if option is type(None):
                continue
            try:
                return _convert(option, value, source, key)
            except UserError as exc:
                errors.append(str(exc))
        raise UserError(errors[0] if len(errors) == 1 else f"{where}: {value!r} matches none of {tp}")
    if origin in (list, tuple):
        if not isinstance(value, list | tuple):
            raise UserError(f"{where}: expected a list, got {value!r}")
        args = typing.get_args(tp)
        item_tp = args[0] if args else Any
        items = [_convert(item_tp, v, source, f"{key}[{i}]") for i, v in enumerate(value)]
        return items if origin is list else tuple(items)
    if origin is dict:
        if not isinstance(value, dict):
            raise UserError(f"{where}: expected a mapping, got {value!r}")
        key_tp, val_tp = typing.get_args(tp) or (Any, Any)
        return {
            _convert(key_tp, k, source, key): _convert(val_tp, v, source, f"{key}.{k}")
            for k, v in value.items()
        }
    if origin is typing.Literal:
        if value not in typing.get_args(tp):
            raise UserError(f"{where}: {value!r} is not one of {list(typing.get_args(tp))}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise UserError(f"{where}: expected true/false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise UserError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            # YAML 1.1 reads "3e-4" (no dot) as a string; accept it as the number it means.
            if isinstance(value, str):
                try:
                    return float(value)
                except ValueError:
                    pass
            raise UserError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise UserError(f"{where}: expected a string, got {value!r}")
        return value
    if tp is Path:
        if not isinstance(value, str | Path):
            raise UserError(f"{where}: expected a path, got {value!r}")
        return Path(value)
    if value is None and tp is type(None):
        return None
    raise UserError(f"{where}: unsupported config type {tp!r}")


def _convert_dataclass(cls: type, value: Any, source: str, key: str) -> Any:
    if isinstance(value, cls):
        value = dataclasses.asdict(value)
    if not isinstance(value, dict):
        raise UserError(f"{source}: {key or '<root>'}: expected a mapping, got {value!r}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(value) - set(fields))
    if unknown:
        prefix = f"{key}." if key else ""
        raise UserError(
            f"{source}: unknown key(s) {', '.join(prefix + str(u) for u in unknown)} "
            f"(known: {', '.join(sorted(fields))})"
        )
    kwargs = {}
    for name, field in fields.items():
        sub = f"{key}.{name}" if key else name
        if name in value:
            kwargs[name] = _convert(hints[name], value[name], source, sub)
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise UserError(f"{source}: missing required key {sub!r}")
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise UserError(f"{source}: {key or '<root>'}: {exc}") from None
