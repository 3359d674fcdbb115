"""The JSON schema of each message type, generated from its dataclass's type hints: what an
MCAP viewer shows of a msgpack channel."""

from __future__ import annotations

import types
import typing
from dataclasses import MISSING, fields
from typing import Any

from fleet.wire.protocol import Message


def _json_type(hint: Any) -> dict:
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        return {"anyOf": [_json_type(h) for h in typing.get_args(hint)]}
    if hint is type(None):
        return {"type": "null"}
    simple = {bool: "boolean", int: "integer", float: "number", str: "string", dict: "object"}
    if hint in simple:
        return {"type": simple[hint]}
    if origin is list:
        return {"type": "array", "items": _json_type(typing.get_args(hint)[0])}
    if origin is tuple:
        items = [_json_type(h) for h in typing.get_args(hint)]
        return {"type": "array", "prefixItems": items, "minItems": len(items),
                "maxItems": len(items)}
    raise TypeError(f"no JSON schema for {hint!r}")  # pragma: no cover


def json_schema(cls: type[Message]) -> dict:
    """The JSON schema of a message in its envelope (fleet/wire/protocol.py), msgpack-encoded."""
    hints = typing.get_type_hints(cls)
    body = {"type": "object", "additionalProperties": False,
            "properties": {f.name: _json_type(hints[f.name]) for f in fields(cls)},
            "required": [f.name for f in fields(cls)
                         if f.default is MISSING and f.default_factory is MISSING]}
    return {"title": cls.TYPE, "type": "object",
            "properties": {"v": {"const": 1}, "type": {"const": cls.TYPE},
                           "sender": {"type": "string"}, "seq": {"type": "integer"},
                           "t": {"type": "number"}, "body": body},
            "required": ["v", "type", "sender", "seq", "t", "body"]}
