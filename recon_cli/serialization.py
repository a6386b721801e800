"""JSON conversion of the values recon writes (numpy arrays and scalars, paths, dataclasses
with ``to_dict``)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np


def to_jsonable(value):
    """``default=`` hook for ``json.dump``."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.floating | np.integer):
        return value.item()
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.asdict(value)
    raise TypeError(f"not JSON serializable: {type(value)}")
