"""Batched collision checks in C++: pinocchio's geometry models and coal broad-phase managers.

``CollisionModel`` describes the cell's shapes (from the expanded URDF) and decides which
pairs are checked; this module hands exactly those shapes and pairs to pinocchio, whose
``computeCollisions`` runs forward kinematics, the placement of every shape, a dynamic AABB
tree and coal's narrow phase for a whole batch of configurations in one call (one thread).

Straight motions are checked hierarchically. Between two samples spaced so that no robot
point moves more than 2G, every point of a shape stays within G of where it is at the nearer
sample; so a copy of the robot whose shapes are inflated by G (capsules and spheres exactly,
boxes by their edge lengths + 2G, which contains the Minkowski sum) that is free at a sample
proves the motion free on that sample's whole interval - for robot-environment pairs and,
with both shapes inflated, for self pairs. Levels G = 16, 4, 1 x max_step / 2: the coarse
level covers the motion with few samples; an interval the inflated robot touches something
on is re-covered by four samples of the next level. Flagged samples get the exact check at
once (a blocked motion usually fails there, long before the finest level); at the last level
the samples are max_step apart. Every instant of the motion is therefore either proved free
or within max_step / 2 of robot-point motion of an exactly checked sample.

Pairs that are close in nearly every configuration (the wrist and the camera, whose distance
tables ``PairField`` bound) stay out of the inflated copies; where their table does not clear
the motion, the samples of the finest spacing whose bound is not positive get the exact check.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from recon_cli.lazy import lazy_module

if TYPE_CHECKING:
    import coal
    import pinocchio as pin
else:
    pin = lazy_module("pinocchio")
    coal = lazy_module("coal")


if TYPE_CHECKING:
    from recon_cli.robot.pair_field import PairField
    from recon_cli.robot.shapes import CollisionShape

#: inflation of each level in units of max_step / 2 (coarse to fine, ratio 4)
LEVELS = (16.0, 4.0, 1.0)


def coal_geometry(kind: str, dims: tuple[float, ...], grow: float = 0.0) -> coal.CollisionGeometry:
    """coal shape of a collision primitive, enlarged by ``grow`` [m] (a superset of the
    primitive's Minkowski sum with a ball of that radius)."""
    if kind == "box":
        return coal.Box(*(float(d) + 2.0 * grow for d in dims))
    if kind == "capsule":
        return coal.Capsule(dims[0] + grow, dims[1])
    if kind == "cylinder":
        return coal.Cylinder(dims[0] + grow, dims[1] + 2.0 * grow)
    if kind == "sphere":
        return coal.Sphere(dims[0] + grow)
    raise ValueError(kind)


class _Level:
    """One geometry model (shapes inflated by ``grow``) with its pairs and a one-thread pool."""

    def __init__(self, model: pin.Model, shapes: list[CollisionShape], n_robot: int,
                 pairs: list[tuple[int, int]], grow: float) -> None:
        gm = pin.GeometryModel()
        for k, s in enumerate(shapes):
            g = grow if k < n_robot else 0.0  # the environment is never inflated
            gm.addGeometryObject(pin.GeometryObject(s.label, int(s.joint), pin.SE3(s.joint_T_shape),
                                                    coal_geometry(s.kind, s.dims, g)))
        for i, j in pairs:
            gm.addCollisionPair(pin.CollisionPair(int(i), int(j)))
        self.grow = grow
        self.empty = not pairs
        self.pool = pin.BroadPhaseManagerPool_DynamicAABBTreeCollisionManager(model, gm, 1)
        self.model, self.data = model, model.createData()
        # the manager refers to the geometry model and data: both are kept alive here
        self._geometry, self._geometry_data = gm, pin.GeometryData(gm)
        self.manager = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(model, gm, self._geometry_data)

    def batch(self, qs: npt.NDArray[np.float64], stop_at_first: bool = False) -> npt.NDArray[np.bool_]:
        """Collision flag of every configuration of qs (K, n)."""
        if self.empty or not len(qs):
            return np.zeros(len(qs), dtype=bool)
        res = pin.computeCollisionsInParallel(1, self.pool, np.asfortranarray(qs.T), True, stop_at_first)
        return np.asarray(res, dtype=bool)

    def one(self, q: npt.NDArray[np.float64]) -> bool:
        if self.empty:
            return False
        return bool(pin.computeCollisions(self.model, self.data, self.manager, q, True))


class BatchChecker:
    """Exact and inflated copies of the checked shapes and pairs, for batches of configurations.

    shapes: robot shapes first (``n_robot`` of them), then the environment; pairs: index
    pairs into shapes; swept_pairs: the subset kept in the inflated levels; lever (n, R):
    motion bound of each robot shape per unit of each joint [m]; fields: the distance tables
    of the pairs left out of the inflated levels (pairs minus swept_pairs).
    """

    def __init__(self, model: pin.Model, shapes: list[CollisionShape], n_robot: int,
                 pairs: list[tuple[int, int]], swept_pairs: list[tuple[int, int]], lever: npt.NDArray[np.float64],
                 fields: list[PairField]) -> None:
        self.lever = lever
        self.fields = fields
        self._model, self._shapes, self._n_robot, self._swept = model, shapes, n_robot, swept_pairs
        self.exact = _Level(model, shapes, n_robot, pairs, 0.0)
        self._levels: dict[float, list[_Level]] = {}

    def levels(self, max_step: float) -> list[_Level]:
        """The inflated copies for one sampling resolution (built on first use)."""
        if max_step not in self._levels:
            self._levels[max_step] = [_Level(self._model, self._shapes, self._n_robot, self._swept,
                                             f * max_step / 2.0) for f in LEVELS]
        return self._levels[max_step]

    def in_collision(self, q: npt.NDArray[np.float64]) -> bool:
        return self.exact.one(np.asarray(q, dtype=float))

    def first_collision(self, qs: npt.NDArray[np.float64], max_step: float = 0.005) -> int:
        """Index of the first colliding configuration of qs (K, n), -1 when all are free.

        A densely sampled course (a timed trajectory) is grouped like a motion: samples whose
        accumulated robot-point motion lies in one bin of width G are all within G of the
        bin's first sample, so the copy inflated by G clears the whole bin at once (levels
        coarser than ``max_step`` only). The samples left, and those where a distance table
        does not clear its pair, get the exact check, in order."""
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        cand = np.arange(len(qs))
        if len(qs) > 16:
            step = np.max(np.abs(np.diff(qs, axis=0)) @ self.lever, axis=1)
            cum = np.concatenate([[0.0], np.cumsum(step)])
            tabled = np.zeros(len(qs), dtype=bool)
            for field in self.fields:
                tabled |= field.at(qs) <= 0.0
            for level in self.levels(max_step):
                if level.grow <= max_step:
                    break
                bins = np.floor(cum[cand] / level.grow)
                first = np.concatenate([[True], bins[1:] != bins[:-1]])
                flagged = level.batch(qs[cand[first]])
                cand = cand[flagged[np.cumsum(first) - 1]]
                if not len(cand):
                    break
            cand = np.union1d(cand, np.nonzero(tabled)[0])
        hit = np.nonzero(self.exact.batch(qs[cand], stop_at_first=True))[0]
        return int(cand[hit[0]]) if len(hit) else -1

    def segment_free(self, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], max_step: float = 0.005,
                     check_end: bool = True) -> bool:
        """Is the straight joint motion a -> b free (see the module text)?"""
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        if check_end and self.exact.one(b):
            return False
        d = b - a
        longest = float(np.max(np.abs(d) @ self.lever))
        if longest <= 0.0:
            return True
        levels = self.levels(max_step)
        # level 0: samples at the centres of m equal intervals, each moving <= 2 G0
        spacing0 = 2.0 * levels[0].grow
        m = max(1, int(np.ceil(longest / spacing0)))
        width = 1.0 / m
        t = (np.arange(m) + 0.5) * width
        for k, level in enumerate(levels):
            qs = a + t[:, None] * d
            flagged = level.batch(qs)
            if not flagged.any():
                break
            # samples the inflated robot touches get the exact check at once: a blocked
            # motion crosses an obstacle, and its flagged samples are often inside it
            if self.exact.batch(qs[flagged], stop_at_first=True).any():
                return False
            if k + 1 < len(levels):  # sub-intervals of each flagged one, for the next level
                n_sub = int(round(level.grow / levels[k + 1].grow))
                offsets = (np.arange(n_sub) + 0.5) / n_sub - 0.5
                t = (t[flagged][:, None] + width * offsets).ravel()
                width /= n_sub
        if not self.fields:
            return True
        ts = self._field_samples(a, b, longest, max_step)
        return not (len(ts) and self.exact.batch(a + ts[:, None] * d, stop_at_first=True).any())

    def _field_samples(self, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], longest: float,
                       max_step: float) -> npt.NDArray[np.float64]:
        """Instants (finest spacing) where a distance table does not clear its pair."""
        if all(field.along(a, b) > 0.0 for field in self.fields):
            return np.zeros(0)
        fine = max(1, int(np.ceil(longest / max_step)))
        t = (np.arange(fine) + 0.5) / fine
        qs = a + t[:, None] * (b - a)
        low: npt.NDArray[np.float64] = np.min([field.at(qs) for field in self.fields], axis=0)
        # within half a spacing the pair moves at most max_step (both shapes max_step / 2)
        return t[low <= max_step]
