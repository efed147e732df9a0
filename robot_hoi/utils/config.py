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


def parse_override(item: str) -> tuple[list[str], Any]:
    """"dotted.key=value" -> (["dotted", "key"], value parsed as YAML)."""
    key, sep, raw = item.partition("=")
    key = key.strip()
    if not sep or not key:
        raise UserError(f"override {item!r}: expected dotted.key=value")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError as exc:
        raise UserError(f"override {item!r}: value is not valid YAML ({exc})") from None
    return key.split("."), value


def apply_overrides(obj: T, overrides: list[str], source: str = "overrides") -> T:
    """Return a copy of dataclass `obj` with "dotted.key=value" overrides applied (values parsed as YAML)."""
    data = dataclasses.asdict(obj)
    for item in overrides:
        parts, value = parse_override(item)
        node, owner = data, obj  # owner: the dataclass `node` was made from (its REMOVED_KEYS say why a key went)
        for depth, part in enumerate(parts):
            removed = getattr(owner, "REMOVED_KEYS", {})
            if isinstance(node, dict) and part not in node and part in removed:
                raise UserError(f"override {item!r}: {'.'.join(parts)} was removed: {removed[part]}")
            _check_key(node, parts[: depth + 1], f"override {item!r}")
            if depth == len(parts) - 1:
                node[part] = value
            else:
                node, owner = node[part], getattr(owner, part, None)
    return load_dataclass(type(obj), data, f"{source} + overrides")


def apply_changes(obj: T, changes: dict, source: str, prefix: tuple[str, ...] = ()) -> T:
    """Return a copy of dataclass `obj` with a nested mapping of changes merged in (merge_dicts); every key must
    exist in `obj`. Errors name `source` (e.g. a file) and the key, under `prefix` (e.g. ("env",))."""
    data = dataclasses.asdict(obj)
    _check_keys(data, changes, source, list(prefix))
    return load_dataclass(type(obj), merge_dicts(data, changes), source)


def merge_dicts(base: dict, changes: dict) -> dict:
    """`base` with `changes` on top: a mapping merges into a mapping key by key, anything else replaces."""
    out = dict(base)
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_dicts(out[key], value)
        else:
            out[key] = value
    return out


def read_yaml_chain(name: str | Path, folder: Path, kind: str, keys: set[str]) -> list[tuple[Path, dict]]:
    """A YAML file of `kind` ("recipe", "reward set") and the files its `base:` names, base first, each as
    (path, its mapping without `base`). `name` and each base are a name under `folder` or a .yaml/.yml path (a
    base's path relative to the file naming it); `base: null` or none ends the chain. Top-level keys other than
    `keys` and `base`, a missing file and a cycle raise UserError naming the file."""
    chain: list[tuple[Path, dict]] = []
    seen: list[Path] = []
    path = _named_yaml(str(name), folder, Path.cwd(), kind, None)
    while path is not None:
        if path in seen:
            cycle = " -> ".join(p.name for p in [*seen[seen.index(path):], path])
            raise UserError(f"{seen[-1]}: base {path.stem!r} makes a cycle ({cycle})")
        seen.append(path)
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise UserError(f"{path}: not valid YAML ({exc})") from None
        data = {} if data is None else data
        if not isinstance(data, dict):
            raise UserError(f"{path}: a {kind} is a mapping of keys, got {type(data).__name__}")
        unknown = sorted(set(data) - keys - {"base"})
        if unknown:
            raise UserError(f"{path}: unknown key(s) {', '.join(map(str, unknown))} (a {kind} has: base, "
                            f"{', '.join(sorted(keys))})")
        base = data.pop("base", None)
        chain.append((path, data))
        if base is not None and not isinstance(base, str):
            raise UserError(f"{path}: base: expected a {kind} name or YAML path, got {base!r}")
        path = None if base is None else _named_yaml(base, folder, path.parent, kind, path)
    return chain[::-1]


def _named_yaml(name: str, folder: Path, relative_to: Path, kind: str, named_by: Path | None) -> Path:
    path = relative_to / name if name.endswith((".yaml", ".yml")) else folder / f"{name}.yaml"
    if not path.is_file():
        names = ", ".join(sorted(p.stem for p in folder.glob("*.yaml")))
        where = f"{named_by}: base {name!r}" if named_by else str(path)
        raise UserError(f"{where}: no such {kind} (choose from {names} or a YAML path)")
    return path.resolve()


def _check_key(node: Any, parts: list[str], where: str) -> None:
    if not isinstance(node, dict) or parts[-1] not in node:
        known = ", ".join(sorted(node)) if isinstance(node, dict) else "(not a section)"
        raise UserError(f"{where}: unknown key {'.'.join(parts)!r} (known here: {known})")


def _check_keys(node: dict, changes: dict, source: str, prefix: list[str]) -> None:
    for key, value in changes.items():
        parts = [*prefix, str(key)]
        _check_key(node, parts, source)
        if isinstance(value, dict) and isinstance(node[key], dict):
            _check_keys(node[key], value, source, parts)


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
        moved = getattr(cls, "MOVED_KEYS", {})  # a dataclass's old spellings of keys: old -> its spelling now
        removed = getattr(cls, "REMOVED_KEYS", {})  # keys that are gone: name -> why, and what does it now
        for name in unknown:
            if name in moved:
                raise UserError(f"{source}: {prefix}{name} has moved: it is spelled {moved[name]} now")
            if name in removed:
                raise UserError(f"{source}: {prefix}{name} was removed: {removed[name]}")
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
