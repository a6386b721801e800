"""A station whose robot reports every executed trajectory to a recorder.

The wrapper sits on the backend interfaces (``RobotBackend.execute``), so every workflow
records the same way on the simulation and on hardware, whoever asks the robot to move.
"""

from __future__ import annotations

from recon_cli.backends.base import ExecutionReport


class RecordedRobot:
    """A robot backend that logs each trajectory it has executed (also one stopped by a
    fault: the part before the fault is not known, so nothing is logged then)."""

    def __init__(self, robot, recorder) -> None:
        self._robot = robot
        self._recorder = recorder
        self.joint_names = robot.joint_names

    def measured_joints(self):
        return self._robot.measured_joints()

    def execute(self, trajectory) -> ExecutionReport:
        report = self._robot.execute(trajectory)
        self._recorder.move(trajectory, report.settle_time)
        return report

    def __getattr__(self, name: str):  # stop(), close(), adapter specifics
        return getattr(self._robot, name)


class RecordedStation:
    """A station with a :class:`RecordedRobot`; everything else is the station's own."""

    def __init__(self, station, recorder) -> None:
        self._station = station
        self.robot = RecordedRobot(station.robot, recorder)
        self.camera = station.camera
        self.backend = station.backend

    def ground_truth(self):
        return self._station.ground_truth()

    def close(self) -> None:
        self._station.close()

    def __getattr__(self, name: str):  # cover_board(), realism_record(), ...
        return getattr(self._station, name)

    def __enter__(self) -> RecordedStation:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
