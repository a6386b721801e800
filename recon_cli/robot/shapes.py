"""The collision primitive that the collision model and the batched checkers share.

``collision`` builds the list of shapes from the expanded URDF; ``motion_check`` hands the
same list to pinocchio and coal. Both index that one list, so the type lives below them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class CollisionShape:
    """One collision primitive. ``joint_T_shape`` places it in its pinocchio joint frame."""

    name: str
    link: str
    joint: int  # pinocchio joint index the link moves with (0: fixed to the world)
    kind: str  # box | capsule | cylinder | sphere
    dims: tuple[float, ...]  # box (sx, sy, sz); capsule/cylinder (radius, length); sphere (r,)
    joint_T_shape: npt.NDArray[np.float64]

    @property
    def label(self) -> str:
        return f"{self.link}/{self.name}"
