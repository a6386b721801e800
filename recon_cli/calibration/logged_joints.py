"""Joint positions logged beside a data set's flange poses, and the cell that explains them.

A robot's controller computes the flange pose it logs from the joints it measures (libfranka's
``O_T_EE`` is its kinematic model at ``q`` times the end-effector offset set in Desk). When a
data set holds both, the joints carry what the pose carries and one thing more: where the
pose is wrong. A zero offset of a joint moves every logged pose in its own way, and
:func:`recon_cli.calibration.robust.estimate_joint_offsets` estimates the offsets with the
mount. That needs the cell's kinematics to be the logged robot's: :func:`match_chain` checks
that the cell's forward kinematics give every logged pose up to one constant transform on
either side (the base the poses are logged in, the end-effector frame they name), and says why
not otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from recon_cli.geometry.transforms import invert, pose_error

#: keys a pose file names its joint positions by (libfranka's state: ``q``; franka-handeye: ``joint_pose``)
JOINT_KEYS = ("joint_pose", "joints", "joint_positions", "q", "joint_states", "position")
#: the cell's forward kinematics must give every logged pose within this of one constant offset
CHAIN_TOLERANCE = (1e-4, math.radians(0.01))  # [m], [rad]


def record_joints(record: Any, joints: int) -> np.ndarray | None:
    """The joint positions [rad] a pose file holds beside its pose: the first of JOINT_KEYS
    whose value is a list of ``joints`` finite numbers (a longer list: the arm's first
    ``joints``, as libfranka's 9 with the gripper's two); None when there is none."""
    if not isinstance(record, dict):
        return None
    for key in JOINT_KEYS:
        value = record.get(key)
        if isinstance(value, list) and len(value) >= joints and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value[:joints]):
            q = np.array(value[:joints], dtype=float)
            if np.all(np.isfinite(q)) and np.all(np.abs(q) < 4 * math.pi):
                return q
    return None


@dataclass(frozen=True)
class JointChain:
    """The cell's kinematics as the data set logs it: ``logged = left @ world_T_flange(q) @ right``."""

    kin: Any  # recon_cli.robot.kinematics.Kinematics
    flange: int  # the cell's flange frame id
    left: np.ndarray  # (4, 4) the logged base in the cell's world: identity or base_T_world
    right: np.ndarray  # (4, 4) flange_T_logged (the end-effector frame the poses name)

    def world_T_flange(self, q: np.ndarray) -> np.ndarray:
        return self.kin.frame_pose(q, self.flange)

    def logged(self, q: np.ndarray) -> np.ndarray:
        """The flange pose the data set would log at ``q``."""
        return self.left @ self.world_T_flange(q) @ self.right


def match_chain(kin, joints: list[np.ndarray], logged: list[np.ndarray]) -> JointChain | str:
    """The cell's kinematics matched to the logged poses (see the module), or why they do not
    match: the largest disagreement, in mm and degrees."""
    if len(joints) != len(logged) or not joints:
        return "no joint positions beside the poses"
    if len(joints[0]) != kin.nq:
        return f"{len(joints[0])} joint positions, the cell {kin.cell.name} has {kin.nq} joints"
    flange = kin.frame_id(kin.cell.flange_link)
    base = kin.frame_id(kin.cell.base_link)
    world = [kin.frame_pose(q, flange) for q in joints]
    bases = [kin.frame_pose(q, base) for q in joints]
    worst = (math.inf, math.inf)
    fixed_base = all(pose_error(b, bases[0])[0] <= 1e-9 for b in bases)  # not moved by linear axes
    for left in (np.eye(4), invert(bases[0])) if fixed_base else (np.eye(4),):
        right = invert(left @ world[0]) @ logged[0]
        errors = [pose_error(left @ w @ right, p) for w, p in zip(world, logged, strict=True)]
        t, r = max(e[0] for e in errors), max(e[1] for e in errors)
        if t <= CHAIN_TOLERANCE[0] and r <= CHAIN_TOLERANCE[1]:
            return JointChain(kin, flange, left, right)
        worst = min(worst, (t, r))
    return (f"the cell {kin.cell.name}'s kinematics do not give the logged poses (up to "
            f"{worst[0] * 1e3:.1f} mm and {math.degrees(worst[1]):.2f} deg off a constant offset)")
