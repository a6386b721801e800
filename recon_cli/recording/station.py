"""A station whose robot reports every executed trajectory to a recorder.

The wrapper sits on the backend interfaces (``RobotBackend.execute``), so every workflow
records the same way on the simulation and on hardware, whoever asks the robot to move.
"""

from __future__ import annotations

from recon_cli.backends.base import ExecutionReport, Station


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


class RecordedStation(Station):
    """A station with a :class:`RecordedRobot`; everything else (capabilities included) is
    the station's own."""

    def __init__(self, station: Station, recorder) -> None:
        self._station = station
        self.capabilities = station.capabilities
        self.robot = RecordedRobot(station.robot, recorder)
        self.camera = station.camera

    def ground_truth(self) -> dict | None:
        return self._station.ground_truth()

    def cover_board(self, covered: bool) -> None:
        self._station.cover_board(covered)

    def realism_record(self) -> dict:
        return self._station.realism_record()

    def close(self) -> None:
        self._station.close()
