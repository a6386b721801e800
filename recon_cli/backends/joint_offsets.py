"""A robot whose reported joints are corrected by its joint zero offsets.

A real arm's encoders read each joint a small constant angle away from the angle its
kinematic model assumes (a joint zero offset: its factory calibration, a motor changed, a
collision). The hand-eye calibration of a data set with logged joints estimates them with the
mount (``recon calibrate handeye --dataset``, docs/calibration.md), and a station file names
them (``joint_offsets``). recon then works in the true joints everywhere (forward kinematics
and the scans' poses, planning, collision checks) and converts at the robot's interface only:
the joints the robot reports plus the offsets are the true joints, and a trajectory planned
in true joints is sent minus the offsets (a constant shift: its timing, velocities and
accelerations are unchanged).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from recon_cli.backends.base import ExecutionReport
from recon_cli.planning.trajectory import Samples, Trajectory


def shifted(trajectory: Trajectory, by: npt.NDArray[np.float64]) -> Trajectory:
    """``trajectory`` with ``by`` (n,) added to every joint position."""
    evaluate = trajectory.evaluate
    sampled = None
    if evaluate is not None:
        inner = evaluate

        def sampled(ts: npt.NDArray[np.float64]) -> Samples:
            q, qd, qdd = inner(ts)
            return q + by, qd, qdd

    return Trajectory(trajectory.times, trajectory.q + by, trajectory.qd, trajectory.qdd, sampled)


class OffsetRobot:
    """A robot backend in true joints over one that reports and takes its encoders' joints."""

    def __init__(self, robot, offsets: npt.ArrayLike) -> None:
        self._robot = robot
        self.offsets: npt.NDArray[np.float64] = np.asarray(offsets, dtype=float)
        self.joint_names = robot.joint_names

    def measured_joints(self) -> npt.NDArray[np.float64]:
        q: npt.NDArray[np.float64] = np.asarray(self._robot.measured_joints(), dtype=float) + self.offsets
        return q

    def execute(self, trajectory: Trajectory) -> ExecutionReport:
        report: ExecutionReport = self._robot.execute(shifted(trajectory, -self.offsets))
        return report

    def __getattr__(self, name: str):  # stop(), close(), adapter specifics
        return getattr(self._robot, name)
