"""Check an MCAP log against docs/logging.md and the Foxglove schemas (a helper module
for the tests, not a test file).

:func:`validate_file` reads the file with the seeking reader (``mcap.reader.make_reader``,
CRCs checked), validates every ``foxglove.*`` message against the schema vendored in
``crates/popup-core/src/log/schemas`` and every other message against the schema record
stored in the file, and checks the encodings (``jsonschema`` schemas, ``json``
messages) and that each ``foxglove.*`` schema record is the vendored file byte for byte.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, Optional, Union

SCHEMA_DIR = Path(__file__).resolve().parents[1] / "crates" / "popup-core" / "src" / "log" / "schemas"
"""The vendored Foxglove JSON schemas (``foxglove.<Name>.json``)."""


class McapCheckError(AssertionError):
    """The file breaks docs/logging.md or a schema (the message says where)."""


def vendored_schema(name: str) -> bytes:
    """The vendored schema file of ``foxglove.<Name>`` (bytes, as embedded by the writer)."""
    path = SCHEMA_DIR / f"{name}.json"
    if not path.is_file():
        raise McapCheckError(f"no vendored schema for {name} (expected {path})")
    return path.read_bytes()


def _validator(schema: Dict[str, Any]) -> Any:
    """A validator of the draft the schema names (``$schema``), Draft 2020-12 if none."""
    from jsonschema import Draft202012Validator
    from jsonschema.validators import validator_for

    cls = validator_for(schema, default=Draft202012Validator)
    cls.check_schema(schema)
    return cls(schema)


def _check_schema_record(path: Path, schema: Any) -> Any:
    """Check one schema record; return the validator for its messages."""
    if schema is None:
        raise McapCheckError(f"{path}: a channel has no schema (schema id 0); every popup channel has a jsonschema")
    if schema.encoding != "jsonschema":
        raise McapCheckError(f"{path}: schema {schema.name!r} has encoding {schema.encoding!r}, expected 'jsonschema'")
    if schema.name.startswith("foxglove."):
        vendored = vendored_schema(schema.name)
        if schema.data != vendored:
            raise McapCheckError(f"{path}: schema record {schema.name!r} differs from the vendored {SCHEMA_DIR / (schema.name + '.json')}")
        return _validator(json.loads(vendored))
    return _validator(json.loads(schema.data))


def validate_file(path: Union[str, "os.PathLike[str]"]) -> Dict[str, int]:
    """Validate every message of an MCAP log; return the number of messages per topic.

    Raises :class:`McapCheckError` naming the file, topic, message and the schema
    violation; the MCAP reader's own errors (a CRC mismatch: ``CRCValidationError``)
    pass through.
    """
    from mcap.reader import make_reader

    p = Path(os.fspath(path))
    counts: Dict[str, int] = {}
    validators: Dict[int, Any] = {}
    with open(p, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        if summary is not None:
            for schema in summary.schemas.values():
                validators[schema.id] = _check_schema_record(p, schema)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.message_encoding != "json":
                raise McapCheckError(f"{p}: channel {channel.topic} has message_encoding {channel.message_encoding!r}, expected 'json'")
            sid = 0 if schema is None else schema.id
            if sid not in validators:
                validators[sid] = _check_schema_record(p, schema)
            _validate_message(p, channel.topic, message, validators[sid], counts.get(channel.topic, 0))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    return counts


def _validate_message(path: Path, topic: str, message: Any, validator: Any, index: int) -> None:
    try:
        data = json.loads(message.data)
    except ValueError as e:
        raise McapCheckError(f"{path}: {topic} message {index}: not JSON ({e})") from None
    from jsonschema.exceptions import best_match

    error: Optional[Any] = best_match(validator.iter_errors(data))
    if error is not None:
        at = "/".join(str(x) for x in error.path) or "(top level)"
        raise McapCheckError(f"{path}: {topic} message {index} (log_time {message.log_time} ns): at {at}: {error.message}")
