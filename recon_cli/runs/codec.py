"""The one way a run-folder report file becomes a typed model and back.

A model is a frozen dataclass whose fields are the keys of its file, in the file's order.
Field metadata says where a key differs from the field:

* ``key``: the key in the file (``"global"`` is no field name);
* ``omit_none``: the key is left out when the value is None (keys a file holds only
  sometimes, e.g. a scan's ``charuco_error``);
* ``rest``: a mapping of every other key of the object, written after the named ones (the
  details of a script command, which differ by command).

Values are None, bool, int, float, str, tuples (JSON lists), mappings with text keys (JSON
objects), :data:`Matrix` and nested models. :func:`to_json` gives the plain JSON document,
:func:`from_json` builds a model from a document that passed the file's schema.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from collections.abc import Mapping
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, Union, overload

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

#: a 4 x 4 homogeneous transform (rows), as a report file holds it
Matrix = tuple[tuple[float, ...], ...]
#: any JSON value (None, bool, number, text, list, object)
JsonValue = Any
#: a model class
ModelT = TypeVar("ModelT", bound="DataclassInstance")


def key(name: str) -> dict[str, str]:
    """Field metadata: the field is the file's key ``name``."""
    return {"key": name}


OMIT_NONE = {"omit_none": True}
REST = {"rest": True}


@overload
def matrix(value: None) -> None: ...


@overload
def matrix(value: npt.ArrayLike) -> Matrix: ...


def matrix(value: npt.ArrayLike | None) -> Matrix | None:
    """A pose (numpy array or nested lists) as a Matrix; None stays None."""
    if value is None:
        return None
    return tuple(tuple(float(x) for x in row) for row in np.asarray(value, dtype=float).tolist())


def plain(value: Any) -> JsonValue:
    """``value`` with numpy scalars and arrays, paths, tuples, values with ``to_dict`` and
    dataclasses (models) turned into plain JSON values."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value)
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "to_dict"):
        return plain(value.to_dict())
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return to_json(value)
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    raise TypeError(f"not a JSON value: {type(value).__name__}")


def to_json(model: DataclassInstance) -> dict[str, JsonValue]:
    """The JSON object of a model (see the module docstring)."""
    out: dict[str, JsonValue] = {}
    rest: Mapping[Any, Any] = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if f.metadata.get("rest"):
            rest = value or {}
            continue
        if value is None and f.metadata.get("omit_none"):
            continue
        out[f.metadata.get("key", f.name)] = plain(value)
    for k, v in rest.items():
        out.setdefault(str(k), plain(v))
    return out


@cache
def _hints(cls: type[DataclassInstance]) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _convert(value: JsonValue, hint: Any) -> Any:
    if hint is Any or value is None:
        return value
    origin = typing.get_origin(hint)
    if origin in (Union, types.UnionType):
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        return _convert(value, members[0]) if len(members) == 1 else value
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return from_json(hint, value)
    if origin is tuple:
        args = typing.get_args(hint)
        item = args[0] if args else Any
        return tuple(_convert(v, item) for v in value)
    if origin in (dict, Mapping, typing.Mapping) or hint in (dict, Mapping):
        args = typing.get_args(hint)
        item = args[1] if len(args) == 2 else Any
        return {str(k): _convert(v, item) for k, v in value.items()}
    if hint is float:
        return float(value)
    if hint is int:
        return int(value)
    return value


def from_json(cls: type[ModelT], data: Mapping[str, JsonValue]) -> ModelT:
    """The model ``cls`` of a JSON object (missing keys take the field's default)."""
    hints = _hints(cls)
    kwargs: dict[str, Any] = {}
    named: set[str] = set()
    rest_field = None
    for f in dataclasses.fields(cls):
        if f.metadata.get("rest"):
            rest_field = f
            continue
        name = f.metadata.get("key", f.name)
        named.add(name)
        if name in data:
            kwargs[f.name] = _convert(data[name], hints[f.name])
    if rest_field is not None:
        kwargs[rest_field.name] = {k: v for k, v in data.items() if k not in named}
    return cls(**kwargs)


def dumps(model: DataclassInstance) -> str:
    """The text of a report file: the model's JSON, indented, with a final line break."""
    return json.dumps(to_json(model), indent=2) + "\n"
