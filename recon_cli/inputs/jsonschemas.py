"""JSON documents checked against their schemas in ``schemas/`` (the scan store's and the run
folders' files): the first, most relevant violation as one
:class:`~recon_cli.errors.MetadataError` naming the file, the key path and what was expected,
never the text, list or object the file holds there (a number out of its range is named);
and the check that a stored pose is a rigid transform."""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np

from recon_cli.errors import MetadataError
from recon_cli.paths import SCHEMA_DIR

#: how far a pose's rotation part may be from a rotation (entries of R^T R - I)
RIGID_TOLERANCE = 1e-3


@functools.cache
def _validator(name: str):

    schema = json.loads((SCHEMA_DIR / name).read_text())
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def check(data: Any, schema: str, path: Path, what: str, hint: str | None = None) -> None:
    """Raise a MetadataError naming the key of the first (most relevant) schema violation."""

    if not isinstance(data, dict):
        kind = {list: "a list", str: "a string", int: "a number", float: "a number", bool: "a boolean",
                type(None): "null"}.get(type(data), type(data).__name__)
        raise MetadataError(f"{path}: {what} holds {kind}, not a JSON object", path=str(path),
                            hint=hint or f"see schemas/{schema} for what {what} holds")
    fmt = data.get("format")
    newest = _validator(schema).schema["properties"].get("format", {}).get("maximum")
    if newest is not None and isinstance(fmt, int) and not isinstance(fmt, bool) and fmt > newest:
        raise MetadataError(f"{path}: {what} has format {fmt}, this recon reads format {newest} and older",
                            path=str(path), where="format", hint="update recon to read this scan store")
    error = jsonschema.exceptions.best_match(_validator(schema).iter_errors(data))
    if error is None:
        return
    types: list[str] = []  # of anyOf / oneOf branches that differ by type alone
    while error.context:  # within anyOf / oneOf: the problem inside the branch the value was meant for
        depth = len(error.absolute_path)
        deeper = [e for e in error.context if len(e.absolute_path) > depth]
        shallow = [e for e in error.context if len(e.absolute_path) == depth
                   and e.validator not in ("type", "const", "enum")]
        if not (deeper or shallow) and all(e.validator == "type" for e in error.context):
            for e in error.context:
                types += [e.validator_value] if isinstance(e.validator_value, str) else list(e.validator_value)
        error = jsonschema.exceptions.best_match(deeper or shallow or error.context)
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path).lstrip(".")
    message = _message(error, types)
    key = (f"key '{where}'" + (" " if message.startswith(("is ", "has ")) else ": ")) if where else ""
    raise MetadataError(f"{path}: {what} {key}{message}",
                        path=str(path), where=where or None,
                        hint=hint or f"see schemas/{schema} for what {what} holds")


_KINDS = {"number": "a number", "integer": "a whole number", "string": "a text", "boolean": "true or false",
          "array": "a list", "object": "an object", "null": "null"}


def _kind_of(value: Any) -> str:
    """What a JSON value is (never what it holds)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, int):
        return "a whole number"
    if isinstance(value, float):
        return "a number"
    if isinstance(value, str):
        return "a text"
    if isinstance(value, list):
        return "a list"
    return "an object"


def _short_key(key: str) -> str:
    return repr(key if len(key) <= 40 else key[:37] + "...")


def _message(error: Any, types: list[str] | None = None) -> str:
    """A schema violation in words that name what was expected and the kind of value found,
    never the text, list or object found (a number found is named: it is what a range
    refuses)."""
    schema = error.schema if isinstance(error.schema, dict) else {}
    value, rule, bound = error.instance, error.validator, error.validator_value
    number = isinstance(value, int | float) and not isinstance(value, bool)
    if rule == "type":
        expected = list(dict.fromkeys(types or ([bound] if isinstance(bound, str) else list(bound))))
        return f"is {_kind_of(value)}, not {' or '.join(_KINDS.get(t, t) for t in expected)}"
    if rule in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum") and number:
        return error.message  # the number and its bound, e.g. "7 is greater than the maximum of 1"
    if rule == "required":
        missing = [k for k in bound if isinstance(value, dict) and k not in value]
        return f"{_short_key(missing[0]) if missing else 'a key'} is a required property"
    if rule == "additionalProperties" and isinstance(value, dict):
        known = set(schema.get("properties", {}))
        extra = [k for k in value if k not in known]
        return f"holds the unknown key {_short_key(extra[0])}" if extra else "holds an unknown key"
    if rule in ("enum", "const"):
        choices = bound if rule == "enum" else [bound]
        return f"is not {'one of ' if len(choices) > 1 else ''}{', '.join(json.dumps(c) for c in choices)}"
    if rule in ("minItems", "maxItems") and isinstance(value, list):
        items = f"{len(value)} item" + ("" if len(value) == 1 else "s")
        return f"has {items}, {'at least' if rule == 'minItems' else 'at most'} {bound} expected"
    if rule in ("minLength", "maxLength") and isinstance(value, str):
        return f"is a text of {len(value)} characters, {'at least' if rule == 'minLength' else 'at most'} {bound} " \
               "expected"
    if rule in ("minProperties", "maxProperties") and isinstance(value, dict):
        return f"has {len(value)} keys, {'at least' if rule == 'minProperties' else 'at most'} {bound} expected"
    if rule == "pattern":
        return "is not a text of the expected form"
    return f"is not what the schema allows here ({rule})"


def check_pose(value: Any, path: Path, what: str, key: str) -> None:
    """Refuse (MetadataError) a 4 x 4 pose (already of finite, bounded numbers) that is not a
    rigid transform: rotation part orthonormal within RIGID_TOLERANCE with determinant +1,
    last row 0 0 0 1."""
    T = np.asarray(value, dtype=float)
    ok = T.shape == (4, 4) and bool(np.all(np.isfinite(T)))
    if ok:
        R = T[:3, :3]
        ok = (bool(np.allclose(T[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-9))
              and float(np.max(np.abs(R.T @ R - np.eye(3)))) <= RIGID_TOLERANCE and float(np.linalg.det(R)) > 0)
    if not ok:
        raise MetadataError(f"{path}: {what} key '{key}' is not a rigid transform (a rotation and a translation, "
                            "last row 0 0 0 1)", path=str(path), where=key,
                            hint="re-record the scan store, or repair the pose")
