"""Named joint configurations of the cells (robot/poses.yaml)."""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
import numpy.typing as npt

from recon_cli.errors import UnknownNameError
from recon_cli.inputs.yamlfile import read_yaml
from recon_cli.paths import ROBOT_DIR
from recon_cli.robot.description import CellKind


@functools.lru_cache(maxsize=1)
def _poses() -> dict[str, Any]:
    doc: dict[str, Any] = read_yaml(ROBOT_DIR / "poses.yaml", "poses file")
    return doc


def named_configuration(kind: CellKind, name: str, joint_names: tuple[str, ...]) -> npt.NDArray[np.float64]:
    """A named configuration in SI units (prismatic in m, revolute converted from deg)."""
    table = _poses()[kind.value]
    if name not in table:
        raise UnknownNameError(f"configuration of the {kind.value} cell", name, list(table))
    values = table[name]
    return np.array([float(v) if j.startswith("base_joint") else math.radians(float(v))
                     for j, v in zip(joint_names, values, strict=True)])
