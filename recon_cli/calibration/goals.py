"""Joint goals for calibration views that keep the arm's posture.

A robot whose model is not exact (joint zero offsets, elastic joints sagging under gravity,
a base placed a little off) puts the flange off its modelled pose by an error that depends
on the configuration. Hand-eye calibration works with the flange motions between views, so
what matters is how much that error *changes* between views. It changes little when the
shoulder and elbow (the arm's revolute joints before its three wrist joints: joints 1-4 of a
7-joint arm, 1-3 of a 6-joint arm; they carry the arm's weight) keep their posture and the
camera is turned by the wrist and carried by the linear axes: the error is then
nearly one rigid transform in the frame of the gantry carriage, which the calibration
estimates alongside (:mod:`recon_cli.calibration.refine`). On the ceiling cell, which has no
linear axes, the weighting still keeps the shoulder and elbow as still as the views allow.

Goals come from a weighted Levenberg-Marquardt on the camera pose: moving an arm joint 1-4
costs ``POSTURE_WEIGHT`` times as much as moving the linear axes or the wrist.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.robot.ik import IKOptions

POSTURE_WEIGHT = 100.0
#: the last revolute joints of an arm that turn the camera (the wrist)
WRIST_JOINTS = 3


@dataclass(frozen=True)
class ViewGoal:
    """The joint goal of one view, or why there is none."""

    q: np.ndarray | None
    reason: str = ""


def posture_joints(cell) -> tuple[str, ...]:
    """The joints that hold the arm's posture: its revolute planning joints before the wrist."""
    revolute = [n for n in cell.joint_names if n not in cell.config.cell_file.linear_joints]
    return tuple(revolute[:-WRIST_JOINTS])


def joint_weights(cell) -> np.ndarray:
    posture = posture_joints(cell)
    return np.array([POSTURE_WEIGHT if n in posture else 1.0 for n in cell.joint_names])


def _descend(kin, weights: np.ndarray, goal: np.ndarray, q: np.ndarray, lo: np.ndarray, hi: np.ndarray,
             iterations: int = 150, tol: float = 1e-7) -> tuple[np.ndarray, bool]:
    """Weighted Levenberg-Marquardt on the camera pose: the smallest step in the metric
    ``weights`` that reduces the pose error."""
    import pinocchio as pin

    model, fid = kin.model, kin.camera_frame_id
    data = model.createData()
    oMgoal = pin.SE3(goal[:3, :3], goal[:3, 3])
    w_inv = 1.0 / weights
    lam, prev = 1e-4, np.inf
    q = q.copy()
    for _ in range(iterations):
        pin.computeJointJacobians(model, data, q)
        cMg = pin.updateFramePlacement(model, data, fid).actInv(oMgoal)
        err = pin.log6(cMg).vector
        cost = float(err @ err)
        if cost < tol * tol:
            return q, True
        lam = lam * 0.3 if cost < prev else min(lam * 4.0, 1.0)
        prev = cost
        J = pin.Jlog6(cMg.inverse()) @ pin.getFrameJacobian(model, data, fid, pin.LOCAL)
        JW = J * w_inv  # J W^-1
        dq = w_inv * (J.T @ np.linalg.solve(JW @ J.T + lam * np.eye(6), err))
        step = np.max(np.abs(dq))
        if step > 0.3:
            dq *= 0.3 / step
        q = np.clip(pin.integrate(model, q, dq), lo, hi)
    return q, False


def posture_goal(cell, world_T_camera: np.ndarray, reference: np.ndarray, reference_T: np.ndarray,
                 min_margin: float = 0.05) -> ViewGoal:
    """A collision-free goal near the reference posture: the linear axes shifted by the
    camera's horizontal displacement from the reference view, then the weighted descent."""
    lim = cell.limits
    lo, hi = np.asarray(lim.soft_lower, float), np.asarray(lim.soft_upper, float)
    start = np.clip(cell.ik.shift_linear(reference, world_T_camera[:2, 3] - reference_T[:2, 3]), lo, hi)
    q, ok = _descend(cell.kin, joint_weights(cell), world_T_camera, start, lo, hi)
    if not ok:
        return ViewGoal(None, "out of reach while keeping the arm's posture")
    if float(np.min(lim.margin_to_soft(q))) < min_margin:
        return ViewGoal(None, "keeping the arm's posture needs a joint at its limit")
    if cell.collision.in_collision(q):
        a, b = cell.collision.check(q).pairs[0]
        return ViewGoal(None, f"keeping the arm's posture collides ({a} with {b})")
    return ViewGoal(q)


def _posture_change(cell, goals: list[ViewGoal], reference: np.ndarray) -> float:
    """Largest change of an arm joint 1-4 from the reference over the goals [rad]."""
    idx = [i for i, n in enumerate(cell.joint_names) if n in posture_joints(cell)]
    Q = [g.q for g in goals if g.q is not None]
    return max((float(np.max(np.abs(q[idx] - reference[idx]))) for q in Q), default=np.inf)


def board_view_goals(cell, poses: list[np.ndarray], rng: np.random.Generator) -> list[ViewGoal]:
    """Goals for camera poses (world_T_camera, (4, 4) each) that keep the arm's posture: the
    reference posture is the IK solution of one of the views from which the most views are
    reached with the least change of the arm joints 1-4."""

    candidates = []
    for T in poses[: min(len(poses), 4)]:
        try:
            candidates += [(s.q, T) for s in cell.solve_pose(T, rng, options=IKOptions(max_solutions=4)).solutions]
        except ReconError:
            continue
    if not candidates:
        return [ViewGoal(None, "no view is reachable at all") for _ in poses]
    scored = []
    for reference, reference_T in candidates:
        goals = [posture_goal(cell, T, reference, reference_T) for T in poses]
        scored.append(((-sum(g.q is not None for g in goals), _posture_change(cell, goals, reference)), goals))
    return min(scored, key=lambda entry: entry[0])[1]  # the first of equal scores
