"""The official JSON schemas of VDA 5050 2.0.0, one per MQTT topic, and a check of a message
against its topic's schema.

The schemas ship in the package, unmodified, with their licence (`schemas/2.0.0/README` names
the source tag and commit). Each is loaded once, with the validator of the draft it declares
(2020-12). Timestamps (`format: date-time`) are checked too: a master such as vda-5050-lib
drops a message whose timestamp is not RFC 3339, so a gateway must never send one.

Known gaps of the 2.0.0 schemas themselves, kept as published:
- `factsheet`: its member schemas are not under `properties`, so only the top-level required
  keys are checked;
- `instantActions`: items require `actionName`, where the text (and 2.1.0) says `actionType`;
- `state`: `actionStatus` lacks `PAUSED`, which the text has.
"""

from __future__ import annotations

import json
import re
from datetime import datetime
from functools import cache
from importlib.resources import files
from typing import Any, Final

from jsonschema import FormatChecker
from jsonschema.exceptions import ValidationError, best_match
from jsonschema.protocols import Validator
from jsonschema.validators import validator_for

from fleet.errors import UserError
from fleet.vda5050 import TOPICS

VERSION: Final = "2.0.0"

_RFC3339 = re.compile(r"\d{4}-\d\d-\d\d[Tt ]\d\d:\d\d:\d\d(\.\d+)?([Zz]|[+-]\d\d:\d\d)")
_FORMATS = FormatChecker(formats=())


@_FORMATS.checks("date-time")
def _is_date_time(value: object) -> bool:
    """RFC 3339 (ISO 8601 with a zone), as the schemas' `date-time` means; not a string is
    the `type` keyword's business."""
    if not isinstance(value, str):
        return True
    if _RFC3339.fullmatch(value) is None:
        return False
    try:
        datetime.fromisoformat(value.upper().replace(" ", "T"))
    except ValueError:  # a month 13, a 31 February
        return False
    return True


class InvalidMessage(UserError):
    """A VDA 5050 message that its topic's official schema rejects."""


def schema_text(topic: str) -> str:
    """The schema of `topic` as shipped (for a recording that carries its schemas)."""
    _check_topic(topic)
    return (files("fleet.vda5050") / "schemas" / VERSION / f"{topic}.json").read_text("utf-8")


def validate(topic: str, message: dict[str, Any]) -> None:
    """Raise InvalidMessage, naming the topic and where in the message, unless `message` is
    valid on `topic` by the official schema."""
    errors = list(_validator(topic).iter_errors(message))
    if not errors:
        return
    worst = best_match(errors)
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    raise InvalidMessage(
        f"invalid VDA 5050 {VERSION} {topic} message at {_json_path(worst)}: "
        f"{_brief(worst)}{more}"
    )


@cache
def _validator(topic: str) -> Validator:
    schema = json.loads(schema_text(topic))
    cls = validator_for(schema)
    cls.check_schema(schema)  # a broken schema file fails here, not as a bad message later
    return cls(schema, format_checker=_FORMATS)


def _check_topic(topic: str) -> None:
    if topic not in TOPICS:
        raise UserError(f"unknown VDA 5050 topic {topic!r} (known: {', '.join(TOPICS)})")


def _json_path(error: ValidationError) -> str:
    path = "$"
    for part in error.absolute_path:
        path += f"[{part}]" if isinstance(part, int) else f".{part}"
    return path


def _brief(error: ValidationError) -> str:
    """jsonschema's message, cut short where it echoes a whole object (a state is long)."""
    return error.message if len(error.message) <= 200 else f"{error.message[:200]}…"
