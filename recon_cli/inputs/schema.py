"""One schema per YAML file kind (schemas/KIND.schema.json, JSON Schema 2020-12): the keys
a file may hold, their types, and the documented range of every number. A document read by
:mod:`.yamlfile` is checked against its kind's schema before anything is built from it, and
the first problem is one line naming ``file:line key.path``, the value, what is allowed and
what to do.

Besides JSON Schema's own keywords a schema may carry ``unit`` (printed after numbers and
ranges) and ``hint`` (the "what to do" of a refusal at that place). The tables of
docs/inputs.md are made from the schemas (``recon_cli.inputs.schema.range_rows``).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import jsonschema

from recon_cli.errors import InputError
from recon_cli.inputs.numbers import range_text
from recon_cli.inputs.yamlfile import line_of
from recon_cli.paths import SCHEMA_DIR

#: the YAML file kinds with a schema (schemas/KIND.schema.json)
KINDS = ("station", "realism", "camera", "batch", "config", "cell", "sensor", "board", "drives", "handeye_dataset")


@cache
def load_schema(kind: str) -> dict:

    return json.loads((SCHEMA_DIR / f"{kind}.schema.json").read_text(encoding="utf-8"))


@cache
def _validator(kind: str, part: str | None = None):

    schema = load_schema(kind)
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    if part is not None:  # one definition of the schema, for a file a document refers to
        schema = {"$schema": schema["$schema"], "$ref": f"#/$defs/{part}", "$defs": schema["$defs"]}
    return cls(schema)


def key_path(path) -> str:
    """``a.b[2].c`` of a JSON path."""
    out = ""
    for part in path:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _short(value: Any) -> str:
    text = repr(value) if isinstance(value, str) else json.dumps(value, default=str)
    return text if len(text) <= 60 else text[:57] + "..."


def _locate(doc: Any, path) -> tuple[Any, Any]:
    """The container holding the value at ``path`` and its key (for the line)."""
    parent, key = None, None
    node = doc
    for part in path:
        parent, key = node, part
        try:
            node = node[part]
        except (KeyError, IndexError, TypeError):
            break
    return parent, key


def _line(doc: Any, path) -> int | None:
    parent, key = _locate(doc, path)
    if parent is None:
        return getattr(doc, "line", None) or None
    return line_of(parent, key)


_TYPES = {"number": "a number", "integer": "a whole number", "string": "a text", "boolean": "true or false",
          "array": "a list", "object": "a mapping (key: value lines)", "null": "empty"}


def _type_text(types) -> str:
    types = [types] if isinstance(types, str) else list(types)
    return " or ".join(_TYPES.get(t, t) for t in types)


def _message(error, doc: Any, where: str) -> InputError:
    schema = error.schema if isinstance(error.schema, dict) else {}
    path = list(error.absolute_path)
    unit = schema.get("unit", "")
    hint = schema.get("hint")
    validator = error.validator
    instance = error.instance
    if validator == "additionalProperties" and isinstance(instance, dict):
        known = list(schema.get("properties", {}))
        extra = [k for k in instance if k not in known]
        key = extra[0] if extra else "?"
        line = line_of(instance, key) or _line(doc, path)
        at = f"{where}:{line}" if line else where
        name = key_path([*path, key])
        return InputError(f"{at}: {name} is not a known key",
                          hint=f"known keys{(' of ' + key_path(path)) if path else ''}: {', '.join(known)}")
    line = _line(doc, path)
    at = f"{where}:{line}" if line else where
    name = key_path(path) or "the file"
    if validator == "required":
        missing = [k for k in error.validator_value if not isinstance(instance, dict) or k not in instance]
        if not path:
            names = missing[0] if len(missing) == 1 else f"{', '.join(missing[:-1])} and {missing[-1]}"
            return InputError(f"{at}: no {names} section{'s' if len(missing) > 1 else ''}",
                              hint=hint or "see docs/inputs.md")
        return InputError(f"{at}: {name} lacks {', '.join(missing)}", hint=hint or "see docs/inputs.md")
    if validator == "type":
        return InputError(f"{at}: {name} = {_short(instance)} is not {_type_text(error.validator_value)}",
                          hint=hint)
    if validator in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        lo = schema.get("minimum", schema.get("exclusiveMinimum"))
        hi = schema.get("maximum", schema.get("exclusiveMaximum"))
        rng = range_text(lo, hi, lo_open="exclusiveMinimum" in schema, hi_open="exclusiveMaximum" in schema,
                         unit=unit)
        value = f"{instance:g}" if isinstance(instance, float) else str(instance)
        return InputError(f"{at}: {name} = {value}{(' ' + unit) if unit else ''} is outside {rng}",
                          hint=hint or "give a value inside the range")
    if validator in ("enum", "const"):
        choices = error.validator_value if validator == "enum" else [error.validator_value]
        return InputError(f"{at}: {name} = {_short(instance)} is not "
                          f"{'one of ' if len(choices) > 1 else ''}{', '.join(map(str, choices))}",
                          hint=hint or f"choose {' or '.join(map(str, choices))}")
    if validator in ("minItems", "maxItems"):
        lo, hi = schema.get("minItems"), schema.get("maxItems")
        want = f"{lo}" if lo == hi else f"{lo or 0} to {hi if hi is not None else 'any number of'}"
        return InputError(f"{at}: {name} has {len(instance)} items, {want} expected", hint=hint)
    if validator in ("minLength", "maxLength", "pattern", "minProperties", "maxProperties", "propertyNames",
                     "not"):
        return InputError(f"{at}: {name} = {_short(instance)} is not accepted here "
                          f"({schema.get('description') or validator})", hint=hint)
    return InputError(f"{at}: {name}: {error.message}", hint=hint)


def _best(errors) -> Any:

    return jsonschema.exceptions.best_match(errors)


def check(doc: Any, kind: str, where: str | Path, part: str | None = None) -> None:
    """Refuse ``doc`` (read from ``where``) unless it matches the schema of ``kind`` (or, with
    ``part``, the definition ``$defs/part`` of that schema: a file the document refers to)."""
    error = _best(_validator(kind, part).iter_errors(doc))
    if error is not None:
        # within oneOf/anyOf, the problem inside the branch the value was meant for (the one
        # of its type, or the deepest) is the useful one, not "is not of type null"
        while error.context:
            depth = len(error.absolute_path)
            deeper = [e for e in error.context if len(e.absolute_path) > depth]
            shallow = [e for e in error.context if len(e.absolute_path) == depth
                       and e.validator not in ("type", "const", "enum")]
            error = _best(deeper or shallow or error.context)
        raise _message(error, doc, str(where))


def range_rows(kind: str) -> Iterator[tuple[str, str]]:
    """(key path, allowed range with unit) of every bounded number of a schema."""

    def walk(node: dict, path: str) -> Iterator[tuple[str, str]]:
        if not isinstance(node, dict):
            return
        if any(k in node for k in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")):
            lo = node.get("minimum", node.get("exclusiveMinimum"))
            hi = node.get("maximum", node.get("exclusiveMaximum"))
            yield path, range_text(lo, hi, lo_open="exclusiveMinimum" in node, hi_open="exclusiveMaximum" in node,
                                   unit=node.get("unit", ""))
        for key, sub in node.get("properties", {}).items():
            yield from walk(sub, f"{path}.{key}" if path else key)
        if isinstance(node.get("additionalProperties"), dict):
            yield from walk(node["additionalProperties"], f"{path}.NAME")
        if isinstance(node.get("items"), dict):
            yield from walk(node["items"], f"{path}[]")
        for key in ("oneOf", "anyOf", "allOf"):
            for sub in node.get(key, []):
                yield from walk(sub, path)
        if "$ref" in node:
            ref = node["$ref"].split("/")[-1]
            yield from walk(schema.get("$defs", {}).get(ref, {}), path)

    schema = load_schema(kind)
    seen = set()
    for row in walk(schema, ""):
        if row not in seen:
            seen.add(row)
            yield row
