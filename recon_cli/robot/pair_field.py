"""Distance lower-bound tables for robot shape pairs whose relative pose depends on two joints.

Some shape pairs are close in almost every configuration without being in collision, for
instance the wrist link and the camera housing, which only joints 6 and 7 move relative to
each other. A collision check would follow them with exact distance queries on nearly every
motion. Because their relative pose depends on two joints only, their distance is a function
on a rectangle; ``PairField`` tabulates a certified lower bound of it once, on a grid:

    bound[cell] = distance(cell centre) - sum_k lever_k * half_width_k

(within a cell each shape moves by at most lever_k per unit of joint k relative to the other,
``CollisionModel``'s lever arms). A motion along which every visited cell keeps a positive
bound cannot bring the pair into contact, and the exact checks skip the pair.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class PairField:
    """Lower bounds [m] of one pair's distance on a grid over the joints ``joints``."""

    joints: tuple[int, ...]  # configuration indices (one or two)
    levers: npt.NDArray[np.float64]  # (J,) relative motion per unit of each joint [m/rad or m/m]
    lower: npt.NDArray[np.float64]  # (J,) grid origin (the joints' lower limits)
    width: npt.NDArray[np.float64]  # (J,) cell widths
    bound: npt.NDArray[np.float64]  # (n_0[, n_1]) lower bound of the distance in each cell [m]

    @classmethod
    def build(cls, distances: Callable[[npt.NDArray[np.float64]], npt.NDArray[np.float64]],
              joints: tuple[int, ...], levers: npt.NDArray[np.float64], lower: npt.NDArray[np.float64],
              upper: npt.NDArray[np.float64], reach: float = 0.02) -> PairField:
        """Tabulate ``distances`` (exact distances at joint values (N, J) of ``joints``) on
        cells small enough that the pair moves by at most ``reach`` [m] from a cell's centre."""
        levers, lower, upper = (np.asarray(v, dtype=float) for v in (levers, lower, upper))
        span = upper - lower
        counts = np.maximum(1, np.ceil(levers * span * len(joints) / (2.0 * reach))).astype(int)
        width = span / counts
        half_reach = float(levers @ (width / 2.0))
        axes = [lower[k] + (np.arange(counts[k]) + 0.5) * width[k] for k in range(len(joints))]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(joints))
        values = np.asarray(distances(grid), dtype=float).reshape(tuple(counts))
        return cls(tuple(int(j) for j in joints), levers, lower, width, values - half_reach)

    def _cells(self, x: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.intp], ...]:
        idx = np.floor((x - self.lower) / self.width).astype(int)
        idx = np.clip(idx, 0, np.asarray(self.bound.shape) - 1)
        return tuple(idx[..., k] for k in range(len(self.joints)))

    def at(self, qs: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Lower bounds of the distance at configurations qs (..., n)."""
        bound: npt.NDArray[np.float64] = self.bound[self._cells(np.asarray(qs)[..., list(self.joints)])]
        return bound

    def along(self, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], slack: float = 0.004) -> float:
        """Lower bound of the distance along the straight motion a -> b: samples at most
        ``slack`` [m] of pair motion apart, every point within slack / 2 of one of them."""
        x0, x1 = np.asarray(a)[list(self.joints)], np.asarray(b)[list(self.joints)]
        motion = float(self.levers @ np.abs(x1 - x0))
        t = np.linspace(0.0, 1.0, int(np.ceil(motion / slack)) + 1)
        return float(self.bound[self._cells(x0 + t[:, None] * (x1 - x0))].min()) - slack / 2.0
