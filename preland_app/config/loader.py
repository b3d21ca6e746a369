"""YAML -> frozen dataclasses, strictly: unknown keys, missing fields and wrong types are errors.

Every error is a `SpecError` naming the file, the dotted field path and the
problem. Dataclasses validate their own values in `__post_init__` by raising
`SpecValueError(field, problem)`; the loader adds the path.
"""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from pathlib import Path
from collections.abc import Callable
from typing import Any, TypeVar, get_args, get_origin, get_type_hints

import yaml

from ..errors import SpecError, SpecValueError

T = TypeVar("T")

_MISSING = object()


def read_yaml_mapping(path: str | Path) -> dict[str, Any]:
    """Read a YAML file whose top level must be a mapping."""
    path_text = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(path=path_text, field="", problem="file not found") from None
    except OSError as error:
        raise SpecError(path=path_text, field="", problem=f"cannot read file ({error.strerror})") from None
    except UnicodeDecodeError as error:
        raise SpecError(path=path_text, field="", problem=not_utf8_problem(error)) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark is not None else "somewhere"
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        if isinstance(error, yaml.reader.ReaderError):  # a control character: most likely a binary file
            where = f"offset {error.position}"
            code = error.character if isinstance(error.character, int) else ord(error.character)
            problem = f"character #x{code:04x} is not allowed in YAML text (is it a binary file?)"
        raise SpecError(path=path_text, field="", problem=f"malformed YAML at {where}: {problem}") from None
    if not isinstance(data, dict):
        kind = "empty" if data is None else type(data).__name__
        raise SpecError(path=path_text, field="", problem=f"expected a mapping at the top level, got {kind}")
    return data


def not_utf8_problem(error: UnicodeDecodeError) -> str:
    """The one-line problem for a file that is not UTF-8 text (a binary file, another encoding)."""
    byte = error.object[error.start:error.start + 1]
    return f"not a UTF-8 text file (byte 0x{byte.hex()} at offset {error.start}): is it a binary file?"


def _join(prefix: str, name: str | int) -> str:
    if isinstance(name, int):
        return f"{prefix}[{name}]"
    return f"{prefix}.{name}" if prefix else name


def _type_name(tp: Any) -> str:
    origin = get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    if origin in (list, tuple):
        return "a list"
    if origin is dict:
        return "a mapping"
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return "one of " + ", ".join(str(m.value) for m in tp)
    return str(tp)


def convert(value: Any, tp: Any, *, path: str, field: str) -> Any:
    """Convert a YAML value to type `tp`, or raise SpecError at `field`."""
    origin = get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        options = get_args(tp)
        if value is None and type(None) in options:
            return None
        errors = []
        for option in options:
            if option is type(None):
                continue
            try:
                return convert(value, option, path=path, field=field)
            except SpecError as error:
                errors.append(error)
        raise errors[0]
    if tp is Any:
        return value
    if origin is typing.Literal:
        choices = get_args(tp)
        if value in choices and any(type(value) is type(choice) for choice in choices):
            return value
        raise SpecError(path=path, field=field, problem=f"expected one of {', '.join(map(repr, choices))}, got {value!r}")
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise SpecError(path=path, field=field, problem=f"expected true or false, got {value!r}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise SpecError(path=path, field=field, problem=f"expected an integer, got {value!r}")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise SpecError(path=path, field=field, problem=f"expected a number, got {value!r}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise SpecError(path=path, field=field, problem=f"expected a string, got {value!r}")
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        for member in tp:
            if value == member.value or (isinstance(value, str) and value.lower() == str(member.value).lower()):
                return member
        raise SpecError(path=path, field=field, problem=f"expected {_type_name(tp)}, got {value!r}")
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, list):
            raise SpecError(path=path, field=field, problem=f"expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(v, args[0], path=path, field=_join(field, i)) for i, v in enumerate(value))
        if len(value) != len(args):
            raise SpecError(path=path, field=field, problem=f"expected a list of {len(args)} values, got {len(value)}")
        return tuple(convert(v, a, path=path, field=_join(field, i)) for i, (v, a) in enumerate(zip(value, args)))
    if origin is list:
        (item_type,) = get_args(tp)
        if not isinstance(value, list):
            raise SpecError(path=path, field=field, problem=f"expected a list, got {value!r}")
        return [convert(v, item_type, path=path, field=_join(field, i)) for i, v in enumerate(value)]
    if origin is dict:
        key_type, value_type = get_args(tp)
        if not isinstance(value, dict):
            raise SpecError(path=path, field=field, problem=f"expected a mapping, got {value!r}")
        return {
            convert(k, key_type, path=path, field=field): convert(v, value_type, path=path, field=_join(field, str(k)))
            for k, v in value.items()
        }
    if dataclasses.is_dataclass(tp):
        return build(tp, value, path=path, field=field)
    raise SpecError(path=path, field=field, problem=f"unsupported type {tp!r}")


def build(cls: type[T], data: Any, *, path: str, field: str = "") -> T:
    """Build dataclass `cls` from a mapping; strict about keys and types."""
    if not isinstance(data, dict):
        raise SpecError(path=path, field=field or "(top level)", problem=f"expected a mapping, got {data!r}")
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = [k for k in data if k not in fields]
    if unknown:
        known = ", ".join(sorted(fields))
        raise SpecError(path=path, field=_join(field, str(unknown[0])), problem=f"unknown key (expected one of: {known})")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        if name in data:
            kwargs[name] = convert(data[name], hints[name], path=path, field=_join(field, name))
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise SpecError(path=path, field=_join(field, name), problem="missing required field")
    try:
        return cls(**kwargs)
    except SpecValueError as error:
        raise SpecError(path=path, field=_join(field, error.field), problem=error.problem) from None


def to_plain(value: Any, *, keep: Callable[[Any, dataclasses.Field], bool] | None = None,
             float_digits: int | None = None) -> Any:
    """A spec (frozen dataclasses, tuples, dicts, enums) as plain JSON/YAML data: dataclasses as dicts of the
    fields `keep(instance, field)` admits (all but `source_path` by default), enums as their values, floats
    rounded to `float_digits` when given. The one walker from specs to data: spec hashes, written profiles."""
    if keep is None:
        keep = _not_source_path
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_plain(getattr(value, f.name), keep=keep, float_digits=float_digits)
                for f in dataclasses.fields(value) if keep(value, f)}
    if isinstance(value, (list, tuple)):
        return [to_plain(v, keep=keep, float_digits=float_digits) for v in value]
    if isinstance(value, dict):
        return {str(k): to_plain(v, keep=keep, float_digits=float_digits) for k, v in value.items()}
    if isinstance(value, enum.Enum):
        return value.value
    if float_digits is not None and isinstance(value, float):
        return round(value, float_digits)
    return value


def _not_source_path(_value: Any, spec_field: dataclasses.Field) -> bool:
    return spec_field.name != "source_path"


def load_spec_file(cls: type[T], path: str | Path) -> T:
    """Load a YAML file into dataclass `cls`, recording where it came from in its `source_path` field."""
    path_text = str(path)
    data = read_yaml_mapping(path)
    if "source_path" in data:
        raise SpecError(path=path_text, field="source_path", problem="unknown key")
    return dataclasses.replace(build(cls, data, path=path_text), source_path=path_text)


def deep_merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """`override` merged into `base` (nested mappings merged, anything else replaced)."""
    merged = dict(base)
    for key, value in override.items():
        if isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = deep_merge(merged[key], value)
        else:
            merged[key] = value
    return merged
