"""JSON Schemas of mission, campaign, pad and profile files, generated from the spec dataclasses.

The schema walks the frozen dataclasses' fields and type hints, as the loader
does, so the two cannot disagree on structure: every mapping is closed
(`additionalProperties: false`, so a misspelt key fails), fields without a
default are required, and tuples have their exact length. Value checks that
need code (ranges, known names, files that must exist) stay in the
dataclasses' `__post_init__`; a field's `metadata` can add schema keywords
(`schema`) or describe a free mapping as a partial override of a spec
(`schema_partial`). Draft-07, which editors (yaml-language-server) support
best. `schemas/*.schema.json` are this module's output (`preland schema KIND`).
"""

from __future__ import annotations

import dataclasses
import enum
import inspect
import json
import types
import typing
from typing import Any, get_args, get_origin, get_type_hints

DRAFT = "http://json-schema.org/draft-07/schema#"
_PRIMITIVES = {bool: "boolean", int: "integer", float: "number", str: "string"}


def _spec_classes() -> dict[str, type]:
    from ..campaign.spec import CampaignSpec
    from ..sensing.pad import PadSpec
    from ..sim.profile import ProfileSpec
    from .mission import MissionSpec

    return {"mission": MissionSpec, "campaign": CampaignSpec, "pad": PadSpec, "profile": ProfileSpec}


SCHEMA_KINDS = ("mission", "campaign", "pad", "profile")


def _description(cls: type) -> str:
    doc = inspect.getdoc(cls) or ""
    if not doc or doc.startswith(f"{cls.__name__}("):  # the dataclass's generated signature
        return ""
    return " ".join(doc.split())


class _Builder:
    def __init__(self) -> None:
        self.definitions: dict[str, dict[str, Any]] = {}

    def ref(self, cls: type, *, partial: bool) -> dict[str, Any]:
        name = cls.__name__ + ("Override" if partial else "")
        if name not in self.definitions:
            self.definitions[name] = {}  # reserve the name (recursive specs)
            self.definitions[name] = self.object(cls, partial=partial)
        return {"$ref": f"#/definitions/{name}"}

    def object(self, cls: type, *, partial: bool) -> dict[str, Any]:
        """A dataclass as a closed object; `partial`: every field optional (an override merged into it)."""
        hints = get_type_hints(cls, include_extras=True)
        properties: dict[str, Any] = {}
        required = []
        for spec_field in dataclasses.fields(cls):
            if not spec_field.init or spec_field.name == "source_path":
                continue
            schema = self.field(spec_field, hints[spec_field.name], partial=partial)
            properties[spec_field.name] = schema
            has_default = (spec_field.default is not dataclasses.MISSING
                           or spec_field.default_factory is not dataclasses.MISSING)
            if not has_default and not partial:
                required.append(spec_field.name)
        result: dict[str, Any] = {"type": "object"}
        description = _description(cls)
        if description:
            result["description"] = description + (" (any subset: merged into the mission's)" if partial else "")
        result["properties"] = properties
        if required:
            result["required"] = required
        result["additionalProperties"] = False
        return result

    def field(self, spec_field: dataclasses.Field, hint: Any, *, partial: bool) -> dict[str, Any]:
        like = spec_field.metadata.get("schema_partial")
        schema = self.ref(like, partial=True) if like is not None else self.type(hint, partial=partial)
        schema = {**schema, **spec_field.metadata.get("schema", {})}
        default = spec_field.default
        if default is not dataclasses.MISSING and not partial:
            plain = _json_default(default)
            if plain is not _NO_DEFAULT:
                schema = {**schema, "default": plain}
        return schema

    def type(self, hint: Any, *, partial: bool = False) -> dict[str, Any]:
        origin = get_origin(hint)
        if origin is typing.Annotated:
            return self.type(get_args(hint)[0], partial=partial)
        if origin in (typing.Union, types.UnionType):
            options = [option for option in get_args(hint) if option is not type(None)]
            nullable = len(options) < len(get_args(hint))
            schemas = [self.type(option, partial=partial) for option in options]
            if nullable:
                schemas.append({"type": "null"})
            if all(set(s) == {"type"} and isinstance(s["type"], str) for s in schemas):
                return {"type": [s["type"] for s in schemas]}
            return {"anyOf": schemas}
        if hint is Any:
            return {}
        if hint in _PRIMITIVES:
            return {"type": _PRIMITIVES[hint]}
        if origin is typing.Literal:
            return {"enum": list(get_args(hint))}
        if isinstance(hint, type) and issubclass(hint, enum.Enum):
            return {"enum": [member.value for member in hint]}
        if origin is tuple:
            args = get_args(hint)
            if len(args) == 2 and args[1] is Ellipsis:
                return {"type": "array", "items": self.type(args[0], partial=partial)}
            return {"type": "array", "items": [self.type(a, partial=partial) for a in args],
                    "minItems": len(args), "maxItems": len(args), "additionalItems": False}
        if origin is list:
            return {"type": "array", "items": self.type(get_args(hint)[0], partial=partial)}
        if origin is dict:
            _, value_type = get_args(hint)
            values = self.type(value_type, partial=partial)
            return {"type": "object", "additionalProperties": values} if values else {"type": "object"}
        if dataclasses.is_dataclass(hint):
            return self.ref(hint, partial=partial)
        raise TypeError(f"no JSON Schema for type {hint!r}")


_NO_DEFAULT = object()


def _json_default(value: Any) -> Any:
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, tuple) and all(isinstance(v, (bool, int, float, str)) for v in value):
        return list(value)
    return _NO_DEFAULT


def json_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of a `kind` file (mission, campaign, pad, profile); KeyError for another kind."""
    cls = _spec_classes()[kind]
    builder = _Builder()
    root = builder.object(cls, partial=False)
    schema: dict[str, Any] = {"$schema": DRAFT, "title": f"preland {kind} file", **root}
    if builder.definitions:
        schema["definitions"] = dict(sorted(builder.definitions.items()))
    return schema


def schema_text(kind: str) -> str:
    """The schema as the shipped `schemas/KIND.schema.json` holds it."""
    return json.dumps(json_schema(kind), indent=2) + "\n"
