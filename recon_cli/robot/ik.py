"""Inverse kinematics of the camera pose for the redundant cells (thesis 2.2.1).

Damped least squares (Levenberg-Marquardt) on the SE(3) error ``log(world_T_camera(q)^-1
world_T_goal)`` with pinocchio's Jacobians, from several seeds, projected onto the soft
joint limits. Converged solutions are kept when they are collision-free and differ from
the ones already found, so the caller gets several distinct goal configurations (the
redundancy of the 9-DoF chain gives infinitely many). Seeds: the caller's seed first, then
the cell file's posture seeds (``ik.seeds``: named poses such as an elbow-up home), then the
nearest configurations of the cell's seed library (``ik.library``: that many configurations
drawn once, uniformly within the soft limits, with their camera poses; nearest in camera
position plus :data:`LIBRARY_ROTATION_WEIGHT` x rotation angle), then random configurations
within the soft limits whose linear axes (if any) put the arm's base near the camera.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from recon_cli.errors import InputError
from recon_cli.lazy import lazy_module
from recon_cli.robot.batch_fk import BatchFK
from recon_cli.robot.collision import CollisionModel
from recon_cli.robot.kinematics import Kinematics

if TYPE_CHECKING:
    import pinocchio as pin
else:
    pin = lazy_module("pinocchio")

#: [m] a goal farther than this from the world origin (or not finite) is out of reach of any
#: cell without a descent
MAX_GOAL_DISTANCE = 1000.0
#: damping put back when a singular Jacobian meets a damping decayed to (numerically) nothing
SINGULAR_DAMPING = 1e-6
#: [m/rad] the seed library's pose distance: position error plus this times the rotation angle
LIBRARY_ROTATION_WEIGHT = 0.2
#: descents started from the seed library at most, per solve
LIBRARY_SEEDS = 6
#: the seed library's configurations are drawn with this seed: part of the cell, not of a run
LIBRARY_DRAW_SEED = 20250101
#: the seed library's size at most, in joint values (configurations x joints: 100,000
#: configurations of a 10-joint cell); its making and each solve's nearest search grow with it
MAX_LIBRARY_VALUES = 1_000_000
#: configurations whose camera poses are computed at once when the library is made
LIBRARY_CHUNK = 10_000


def check_library_size(kin: Kinematics) -> None:
    """Refuse a cell file's ``ik.library`` of more than :data:`MAX_LIBRARY_VALUES` joint values
    (one line naming the key and the largest library for the cell's joints)."""
    size = kin.cell.ik_library * kin.nq
    if size > MAX_LIBRARY_VALUES:
        raise InputError(f"{kin.cell.where('ik.library')}: ik.library: {kin.cell.ik_library:,} configurations of "
                         f"{kin.nq} joints are {size:,} joint values, more than the {MAX_LIBRARY_VALUES:,} of a "
                         "seed library", hint=f"give at most {MAX_LIBRARY_VALUES // kin.nq:,} configurations for "
                                              "this cell")


class IKStatus(StrEnum):
    SOLVED = "solved"
    #: no attempt converged: the pose is out of reach (or too close to the limits)
    UNREACHABLE = "unreachable"
    #: attempts converged, but every solution collides
    COLLIDING = "colliding"


@dataclass(frozen=True)
class IKOptions:
    """Options of :func:`solve_ik`.

    max_solutions: stop after this many distinct solutions
    max_attempts: seeds to try at most
    max_iterations: LM iterations per seed
    tol_position [m], tol_rotation [rad]: convergence tolerances
    min_separation: smallest joint-space distance (max norm, [rad] or [m]) between solutions
    check_collision: reject colliding solutions
    limit_avoidance: gain of the null-space motion toward mid-range (0 disables it)
    """

    max_solutions: int = 4
    max_attempts: int = 60
    max_iterations: int = 80
    tol_position: float = 1e-6
    tol_rotation: float = 1e-6
    min_separation: float = 0.1
    check_collision: bool = True
    limit_avoidance: float = 1.0


@dataclass(frozen=True)
class IKSolution:
    """One goal configuration. q: (n,) joint vector; limit_margin: smallest distance to a
    soft limit [rad or m]; position_error [m], rotation_error [rad] of the camera."""

    q: npt.NDArray[np.float64]
    limit_margin: float
    position_error: float
    rotation_error: float


@dataclass(frozen=True)
class IKResult:
    status: IKStatus
    solutions: tuple[IKSolution, ...]
    attempts: int
    converged: int
    rejected_collision: int
    seconds: float
    colliding_pairs: tuple[tuple[str, str], ...] = field(default=())

    @property
    def ok(self) -> bool:
        return self.status is IKStatus.SOLVED


class IKSolver:
    """Camera-pose IK for one cell; reuses one pinocchio Data across calls."""

    def __init__(self, kin: Kinematics, collision: CollisionModel | None = None) -> None:
        self.kin = kin
        self.collision = collision
        self._data = kin.model.createData()
        self._lo = kin.limits.soft_lower
        self._hi = kin.limits.soft_upper
        self._mid = (self._lo + self._hi) / 2.0
        self._inv_range2 = 1.0 / ((self._hi - self._lo) / 2.0) ** 2
        names = kin.joint_names
        self._linear = [names.index(j) for j in kin.cell.linear_joints]
        # how the linear axes move the arm's base: base_xy = offset + A q_linear
        q0 = kin.neutral()
        base0 = kin.frame_pose(q0, kin.cell.base_link)[:3, 3]
        self._base_offset_xy = base0[:2].copy()
        columns = []
        for i in self._linear:
            q1 = q0.copy()
            q1[i] += 1.0
            columns.append(kin.frame_pose(q1, kin.cell.base_link)[:2, 3] - base0[:2])
        axes = np.array(columns).T.reshape(2, len(self._linear))  # (2, k)
        unit = np.round(axes)  # axes along the world's x or y: exactly so (no rounding in the seeds)
        self._axes_xy = np.where(np.abs(axes - unit) < 1e-9, unit, axes)
        # orthonormal horizontal axes (any gantry): project; otherwise least squares
        gram = self._axes_xy.T @ self._axes_xy
        self._orthonormal = bool(np.allclose(gram, np.eye(len(self._linear)), atol=1e-9))
        self._posture_seeds = tuple(np.clip(kin.cell.pose(name, names), self._lo, self._hi)
                                    for name in kin.cell.ik_seeds)
        check_library_size(kin)
        self._nearest: list[npt.NDArray[np.float64]] | None = None
        self._library: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None

    # ------------------------------------------------------------------ seed library
    def seed_library(self, progress: Callable[[int, int], None] | None = None
                     ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """(configurations (N, n), camera positions (N, 3), camera rotations (N, 3, 3)), made once
        (in chunks of :data:`LIBRARY_CHUNK` configurations; ``progress(done, total)`` after each)."""
        if self._library is None:
            model = self.kin.model
            frame = model.frames[self.kin.camera_frame_id]
            n = self.kin.cell.ik_library
            Q = np.random.default_rng(LIBRARY_DRAW_SEED).uniform(self._lo, self._hi, size=(n, model.nq))
            p, R = np.empty((n, 3)), np.empty((n, 3, 3))
            fk, joint, placement = BatchFK(model), int(frame.parentJoint), frame.placement.homogeneous
            for start in range(0, n, LIBRARY_CHUNK):
                part = slice(start, start + LIBRARY_CHUNK)
                T = fk.joint_poses(Q[part])[:, joint] @ placement
                p[part], R[part] = T[:, :3, 3], T[:, :3, :3]
                if progress is not None:
                    progress(min(start + LIBRARY_CHUNK, n), n)
            self._library = (Q, p, R)
        return self._library

    def library_seeds(self, world_T_goal: npt.NDArray[np.float64], k: int) -> list[npt.NDArray[np.float64]]:
        """The ``k`` library configurations whose camera pose is nearest the goal's."""
        if self.kin.cell.ik_library == 0 or k <= 0:
            return []
        Q, p, R = self.seed_library()
        cos = (np.einsum("nij,ij->n", R, world_T_goal[:3, :3]) - 1.0) / 2.0
        d = np.linalg.norm(p - world_T_goal[:3, 3], axis=1) + LIBRARY_ROTATION_WEIGHT * np.arccos(np.clip(cos, -1, 1))
        nearest = np.argsort(d, kind="stable")[:k]
        return [Q[i].copy() for i in nearest]

    # ------------------------------------------------------------------ seeds
    def random_seed(self, world_T_goal: npt.NDArray[np.float64], rng: np.random.Generator) -> npt.NDArray[np.float64]:
        """A random configuration; with linear axes, the arm's base is placed within 0.6 m
        (horizontally) of the goal camera position, as far as the axes reach."""
        q = rng.uniform(self._lo, self._hi)
        if self._linear:
            target = world_T_goal[:2, 3] + rng.uniform(-0.6, 0.6, size=2)
            shift = target - self._base_offset_xy
            if self._orthonormal:
                q[self._linear] = self._axes_xy.T @ shift
            else:
                q[self._linear] = np.linalg.lstsq(self._axes_xy, shift, rcond=None)[0]
            q = np.clip(q, self._lo, self._hi)
        return q

    def shift_linear(self, q: npt.NDArray[np.float64], dxy: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """q with the linear axes moved so that the arm's base moves by dxy [m] in the world's
        horizontal plane (as far as the axes' directions allow; q itself without linear axes)."""
        q = np.array(q, dtype=float)
        if self._linear:
            if self._orthonormal:
                q[self._linear] += self._axes_xy.T @ dxy
            else:
                q[self._linear] += np.linalg.lstsq(self._axes_xy, dxy, rcond=None)[0]
        return q

    def start(self, attempt: int, world_T_goal: npt.NDArray[np.float64], rng: np.random.Generator,
              seed: npt.NDArray[np.float64] | None) -> npt.NDArray[np.float64]:
        """The start of one descent: the caller's seed, then the posture seeds, then random."""
        if seed is not None:
            if attempt == 0:
                return np.clip(seed, self._lo, self._hi)
            attempt -= 1
        if attempt < len(self._posture_seeds):
            return self._posture_seeds[attempt].copy()
        attempt -= len(self._posture_seeds)
        if attempt < LIBRARY_SEEDS and self.kin.cell.ik_library:
            if attempt == 0 or self._nearest is None:
                self._nearest = self.library_seeds(world_T_goal, LIBRARY_SEEDS)
            return self._nearest[attempt]
        return self.random_seed(world_T_goal, rng)

    # ------------------------------------------------------------------ one descent
    def descend(self, world_T_goal: npt.NDArray[np.float64], q: npt.NDArray[np.float64], options: IKOptions
                ) -> tuple[npt.NDArray[np.float64], bool, float, float]:
        """LM from q; returns (q, converged, position error [m], rotation error [rad])."""
        model, data, fid = self.kin.model, self._data, self.kin.camera_frame_id
        oMgoal = pin.SE3(world_T_goal[:3, :3], world_T_goal[:3, 3])
        lam = 1e-3
        q = q.copy()
        err = None
        prev_cost = np.inf
        for _ in range(options.max_iterations):
            pin.computeJointJacobians(model, data, q)
            oMf = pin.updateFramePlacement(model, data, fid)
            cMg = oMf.actInv(oMgoal)
            err = pin.log6(cMg).vector  # in the camera frame: (v, w)
            ep, er = float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:]))
            if ep < options.tol_position and er < options.tol_rotation:
                return q, True, ep, er
            cost = ep * ep + er * er
            lam = lam * 0.3 if cost < prev_cost else min(lam * 4.0, 1.0)
            prev_cost = cost
            J = pin.getFrameJacobian(model, data, fid, pin.LOCAL)
            J = pin.Jlog6(cMg.inverse()) @ J
            JJt = J @ J.T
            JJt[np.diag_indices(6)] += lam
            try:
                Jpinv = J.T @ np.linalg.inv(JJt)
            except np.linalg.LinAlgError:  # a singular chain (a wrist at 0) with a vanished damping
                lam = max(lam, SINGULAR_DAMPING)
                JJt[np.diag_indices(6)] += lam
                Jpinv = J.T @ np.linalg.inv(JJt)
            dq = Jpinv @ err
            if options.limit_avoidance > 0.0 and ep + er > 1e-3:
                # secondary task in the null space while far from the goal: pull joints toward
                # the middle of their range (off near the goal, for quadratic convergence)
                pull = options.limit_avoidance * (self._mid - q) * self._inv_range2
                dq += pull - Jpinv @ (J @ pull)
            step = np.max(np.abs(dq))
            if step > 0.5:
                dq *= 0.5 / step
            q = np.clip(pin.integrate(model, q, dq), self._lo, self._hi)
        ep = float(np.linalg.norm(err[:3])) if err is not None else np.inf
        er = float(np.linalg.norm(err[3:])) if err is not None else np.inf
        return q, False, ep, er

    # ------------------------------------------------------------------ solve
    def solve(self, world_T_goal: npt.NDArray[np.float64], rng: np.random.Generator,
              seed: npt.NDArray[np.float64] | None = None, options: IKOptions = IKOptions()  # noqa: B008
              ) -> IKResult:
        """Up to ``options.max_solutions`` distinct collision-free solutions for a camera pose."""
        t0 = time.perf_counter()
        solutions: list[IKSolution] = []
        converged = rejected = 0
        pairs: tuple[tuple[str, str], ...] = ()
        goal = np.asarray(world_T_goal, dtype=float)
        if goal.shape != (4, 4) or not np.all(np.isfinite(goal)) or np.max(np.abs(goal[:3, 3])) > MAX_GOAL_DISTANCE:
            # no robot reaches it; the descent would only overflow
            return IKResult(IKStatus.UNREACHABLE, (), 0, 0, 0, time.perf_counter() - t0, pairs)
        attempts = 0
        while attempts < options.max_attempts and len(solutions) < options.max_solutions:
            start = self.start(attempts, world_T_goal, rng, seed)
            attempts += 1
            q, ok, ep, er = self.descend(world_T_goal, start, options)
            if not ok:
                continue
            converged += 1
            if any(np.max(np.abs(q - s.q)) < options.min_separation for s in solutions):
                continue
            if options.check_collision and self.collision is not None:
                if self.collision.in_collision(q):
                    rejected += 1
                    pairs = pairs or self.collision.check(q).pairs
                    continue
            margin = float(np.min(self.kin.limits.margin_to_soft(q)))
            solutions.append(IKSolution(q, margin, ep, er))
        if solutions:
            status = IKStatus.SOLVED
        elif converged:
            status = IKStatus.COLLIDING
        else:
            status = IKStatus.UNREACHABLE
        return IKResult(status, tuple(solutions), attempts, converged, rejected,
                        time.perf_counter() - t0, pairs)
