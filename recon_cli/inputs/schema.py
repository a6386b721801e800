"""One schema per YAML file kind (schemas/KIND.schema.json, JSON Schema 2020-12): the keys
a file may hold, their types, and the documented range of every number. A document read by
:mod:`.yamlfile` is checked against its kind's schema before anything is built from it, and
the first problem is one line naming ``file:line key.path``, what is allowed and what to do.
It never quotes the file's text: a number outside its range is named as the parsed number, a
text or a key that is not a plain name is described ("a text", "a key"), not shown.

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
from recon_cli.inputs.yamlfile import key_path, line_of, shown_key
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


__all__ = ["KINDS", "check", "key_path", "load_schema", "range_rows"]


def _what(value: Any) -> str:
    """What a value is, without its content: a number is shown (parsed), anything else is
    described (a text of 12 characters, a list of 3 items, ...)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return f"{value:g}" if isinstance(value, float) else str(value)
    if value is None:
        return "empty"
    if isinstance(value, str):
        return f"a text of {len(value)} character{'s' if len(value) != 1 else ''}"
    if isinstance(value, dict):
        return f"a mapping of {len(value)} key{'s' if len(value) != 1 else ''}"
    if isinstance(value, list):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    return "a value"


def _is(value: Any) -> str:
    """``= 3 is`` for a number, ``is a text of 5 characters,`` for anything else (followed by
    ``not ...``)."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        return f"= {_what(value)} is"
    return f"is {_what(value)},"


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
        if shown_key(key) is not None:
            text = f"{key_path([*path, key])} is not a known key"
        else:  # not a plain name: not shown
            text = f"a key of {key_path(path) or 'the file'} is not a known key (nor a plain name)"
        return InputError(f"{at}: {text}",
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
        return InputError(f"{at}: {name} {_is(instance)} not {_type_text(error.validator_value)}",
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
        shown = f" = {_what(instance)}" if isinstance(instance, int | float) and not isinstance(instance, bool) else ""
        return InputError(f"{at}: {name}{shown} is not "
                          f"{'one of ' if len(choices) > 1 else ''}{', '.join(map(str, choices))}",
                          hint=hint or f"choose {' or '.join(map(str, choices))}")
    if validator in ("minItems", "maxItems"):
        lo, hi = schema.get("minItems"), schema.get("maxItems")
        want = f"{lo}" if lo == hi else f"{lo or 0} to {hi if hi is not None else 'any number of'}"
        return InputError(f"{at}: {name} has {len(instance)} items, {want} expected", hint=hint)
    if validator in ("minLength", "maxLength", "pattern", "minProperties", "maxProperties", "propertyNames",
                     "not"):
        return InputError(f"{at}: {name} {_is(instance)} not accepted here "
                          f"({schema.get('description') or validator})", hint=hint)
    # jsonschema's own message quotes the value: not used
    return InputError(f"{at}: {name} {_is(instance)} not accepted here ({validator})", hint=hint)


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
