"""JSON documents checked against their schemas in ``schemas/`` (the scan store's and the run
folders' files): the first, most relevant violation as one
:class:`~recon_cli.errors.MetadataError` naming the file and the key; and the check that a
stored pose is a rigid transform."""

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
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in error.absolute_path).lstrip(".")
    message = error.message if len(error.message) <= 160 else error.message[:157] + "..."
    raise MetadataError(f"{path}: {what} " + (f"key '{where}': " if where else "") + message,
                        path=str(path), where=where or None,
                        hint=hint or f"see schemas/{schema} for what {what} holds")


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
