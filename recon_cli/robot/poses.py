"""Named joint configurations of a cell (its cell file's ``poses``)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from recon_cli.robot.cell_file import load_cell


def named_configuration(cell: str, name: str, joint_names: tuple[str, ...]) -> npt.NDArray[np.float64]:
    """A named configuration of a cell (a shipped cell's name or a cell file) in SI units
    (linear axes in m, the other joints converted from deg)."""
    return load_cell(str(cell)).pose(name, joint_names)
