"""Writing and reading one report file of a run folder: written atomically by
:func:`recon_cli.outputs.atomic_write_text`, read by the guarded JSON reader
(:func:`recon_cli.inputs.jsonfile.load_json`: a regular file within its size limit, not a
link leading out of its run folder, no NaN, bounded nesting and integers, no duplicate keys)
and checked against its schema in ``schemas/`` before a model is built, so that a broken
or hostile file is one :class:`~recon_cli.errors.MetadataError` line naming the file and the
key."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from recon_cli.inputs.jsonfile import MAX_JSON_BYTES, load_json
from recon_cli.inputs.jsonschemas import check
from recon_cli.outputs import atomic_write_text
from recon_cli.runs.codec import ModelT, dumps, from_json

if TYPE_CHECKING:
    from _typeshed import DataclassInstance


def target(folder_or_path: Path, name: str) -> Path:
    """``folder/name`` for a folder, else the path itself."""
    p = Path(folder_or_path)
    return p / name if p.is_dir() else p


def write_model(path: Path, model: DataclassInstance) -> Path:
    """``model`` as the JSON file ``path`` (atomically)."""

    return atomic_write_text(Path(path), dumps(model))


def read_document(path: Path, schema: str, what: str, root: Path | None = None) -> dict[str, Any]:
    """The checked JSON object of ``path`` (a MetadataError when it cannot be read or does
    not match ``schemas/<schema>``). ``root``: the run folder the file belongs to (default:
    the folder that holds it); a file that is, or lies behind, a link leading out of it is
    refused before it is read."""

    path = Path(path)
    data: dict[str, Any] = load_json(path, what, MAX_JSON_BYTES, root=path.parent if root is None else Path(root))
    check(data, schema, path, what)
    return data


def read_model(path: Path, cls: type[ModelT], schema: str, what: str, root: Path | None = None) -> ModelT:
    """The model ``cls`` of the report file ``path`` (see :func:`read_document`)."""
    return from_json(cls, read_document(path, schema, what, root))
