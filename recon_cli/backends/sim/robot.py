"""The simulated robot: MuJoCo plant under computed-torque control with integral action.

Control law (thesis eqs. 2.12-2.14), at the plant's 1 kHz step (gains in the cell's drives file):
    tau = M(q) v + C(q, qd) qd + g(q),   v = qdd_d - K0 e - K1 ed - KI int(e),   e = q - q_d
with M, C, g from pinocchio's model of the same URDF plus the reflected rotor inertia of
the drives file. The plant additionally has viscous joint friction the controller does
not know; the integral term removes the resulting error. After the trajectory the final
configuration is held until the robot has settled: the camera within ``position`` [m] and
``rotation`` [rad] of its goal pose (forward kinematics of the measured joints) and every
joint slower than ``velocity``, for ``hold`` seconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.backends.base import ExecutionReport
from recon_cli.backends.sim.scene import Drives, SimScene, mujoco
from recon_cli.backends.sim.truth import JointSensor
from recon_cli.lazy import lazy_module
from recon_cli.planning.trajectory import Trajectory
from recon_cli.robot.kinematics import Kinematics

if TYPE_CHECKING:
    import pinocchio as pin
else:
    pin = lazy_module("pinocchio")


@dataclass(frozen=True)
class ControllerGains:
    """Diagonal gains of eq. 2.14 (same for every joint) [1/s^2, 1/s, 1/s^3]."""

    K0: float
    K1: float
    KI: float

    @classmethod
    def from_drives(cls, d: Drives) -> ControllerGains:
        """The gains of a cell's drives file."""
        return cls(d.K0, d.K1, d.KI)


@dataclass(frozen=True)
class SettleCriterion:
    position: float = 2.5e-5  # [m] camera position error
    rotation: float = 2.5e-5  # [rad] camera rotation error
    velocity: float = 1e-3  # [rad/s or m/s] per joint
    hold: float = 0.05  # [s]
    timeout: float = 3.0  # [s]


class SimRobot:
    """RobotBackend of the simulation."""

    def __init__(self, scene: SimScene, data: mujoco.MjData, kin: Kinematics,
                 gains: ControllerGains | None = None, settle: SettleCriterion | None = None,
                 joint_sensor: JointSensor | None = None) -> None:
        if tuple(kin.joint_names) != scene.joint_names:
            raise ValueError("the controller model and the plant have different joints")
        self.scene = scene
        self.data = data
        self.kin = kin
        self.joint_names = scene.joint_names
        self.gains = gains or ControllerGains.from_drives(scene.drives)
        self.settle = settle or SettleCriterion()
        self._pin_data = kin.model.createData()
        self._armature = np.array([scene.drives.armature_of(n) for n in self.joint_names])
        self._effort = kin.limits.effort
        # the true robot's joint sensors (realism profile); None: they read the true angles
        self.joint_sensor = joint_sensor

    # ------------------------------------------------------------------ state
    def measured_joints(self) -> np.ndarray:
        q = self.data.qpos[self.scene.qpos_index].copy()
        return q if self.joint_sensor is None else self.joint_sensor.read(q)

    def true_joints(self) -> np.ndarray:
        """The plant's true joint angles (simulation ground truth)."""
        return self.data.qpos[self.scene.qpos_index].copy()

    def _sensed(self, q: np.ndarray) -> np.ndarray:
        """What the controller reads at true joints q (noise-free)."""
        return q if self.joint_sensor is None else self.joint_sensor.sense(q)

    def measured_velocities(self) -> np.ndarray:
        return self.data.qvel[self.scene.dof_index].copy()

    def reset(self, q: np.ndarray) -> None:
        """Place the robot at rest where its joints read q (start of a session)."""
        self.data.qpos[self.scene.qpos_index] = q if self.joint_sensor is None else self.joint_sensor.link_angles(q)
        self.data.qvel[:] = 0.0
        self.data.ctrl[:] = 0.0
        mujoco.mj_forward(self.scene.model, self.data)

    def stop(self) -> bool:
        """The simulated robot moves only inside ``execute``: it holds still already."""
        return True

    def close(self) -> None:
        """Nothing to release: the scene belongs to whoever built it."""

    # ------------------------------------------------------------------ control
    def _torque(self, q, qd, q_d, qd_d, qdd_d, integral) -> np.ndarray:
        g = self.gains
        e, ed = q - q_d, qd - qd_d
        v = qdd_d - g.K0 * e - g.K1 * ed - g.KI * integral
        tau = pin.rnea(self.kin.model, self._pin_data, q, qd, v) + self._armature * v
        return np.clip(tau, -self._effort, self._effort)

    def _camera_close(self, goal_inv: np.ndarray, q: np.ndarray) -> bool:
        D = goal_inv @ self.kin.world_T_camera(q)
        angle = np.arccos(np.clip((np.trace(D[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
        return bool(np.linalg.norm(D[:3, 3]) < self.settle.position and angle < self.settle.rotation)

    def execute(self, trajectory: Trajectory) -> ExecutionReport:
        model, data = self.scene.model, self.data
        qi, di = self.scene.qpos_index, self.scene.dof_index
        dt = model.opt.timestep
        steps = int(np.ceil(trajectory.duration / dt))
        q_des, qd_des, qdd_des = trajectory.sample(np.arange(steps + 1) * dt)
        integral = np.zeros(len(qi))
        max_err = np.zeros(len(qi))
        for k in range(steps):
            q, qd = self._sensed(data.qpos[qi]), data.qvel[di]
            e = q - q_des[k]
            np.maximum(max_err, np.abs(e), out=max_err)
            integral += e * dt
            data.ctrl[:] = self._torque(q, qd, q_des[k], qd_des[k], qdd_des[k], integral)
            mujoco.mj_step(model, data)
        # hold the goal until settled
        goal = trajectory.goal
        goal_inv = np.linalg.inv(self.kin.world_T_camera(goal))
        zero = np.zeros(len(qi))
        s = self.settle
        held = 0.0
        t = 0.0
        settled = False
        while t < s.timeout:
            q, qd = self._sensed(data.qpos[qi]), data.qvel[di]
            e = q - goal
            np.maximum(max_err, np.abs(e), out=max_err)
            if np.all(np.abs(qd) < s.velocity) and self._camera_close(goal_inv, q):
                held += dt
                if held >= s.hold:
                    settled = True
                    break
            else:
                held = 0.0
            integral += e * dt
            data.ctrl[:] = self._torque(q, qd, goal, zero, zero, integral)
            mujoco.mj_step(model, data)
            t += dt
        mujoco.mj_forward(model, data)
        final = np.abs(self._sensed(data.qpos[qi]) - goal)
        return ExecutionReport(trajectory.duration, t, max_err, final, settled)
