"""The true robot of a realism profile: the model's own description with other arguments,
and joint sensors that do not read the true joint angles.

recon plans and computes forward kinematics with the model (``Cell``). The simulated plant
is the same xacro expanded with a robot base moved by the profile's base error
(``CellConfig.mount_T_base``) and a camera moved by its hand-eye error
(``CellConfig.flange_T_camera``); no second robot model is written anywhere. Its joint
sensors (:class:`JointSensor`) read, for true link angles q::

    reading = q + offset + C g(q) + noise

offset: the encoder zero offset of each joint, drawn once per session; C g(q): the elastic
deflection under gravity (compliance = 1 / stiffness times the gravity torque of the true
robot, from pinocchio), because the iiwa's position sensors sit on the motor side of its
elastic joints; noise: per reading (the controller's loop uses the noise-free reading).
The controller servoes the readings, so the true robot ends where offsets and sag put it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from lxml import etree

from recon_cli.errors import InputError
from recon_cli.geometry.transforms import invert, rpy_to_matrix
from recon_cli.inputs.yamlfile import shown_key
from recon_cli.lazy import lazy_module
from recon_cli.realism import KinematicErrors, PoseError
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import load_cell, shipped_cells
from recon_cli.robot.description import CellConfig, expand_urdf
from recon_cli.robot.urdf import child

if TYPE_CHECKING:
    import pinocchio as pin
else:
    pin = lazy_module("pinocchio")


@dataclass(frozen=True)
class TrueCell:
    """What a realism profile drew for one session (simulation ground truth, never read by
    any algorithm; recorded in ground_truth/realism.json)."""

    config: CellConfig  # arguments of the true description
    joint_names: tuple[str, ...]
    offsets: np.ndarray  # (n,) encoder zero offsets [rad or m]
    noise_std: np.ndarray  # (n,) per reading [rad or m]
    compliance: np.ndarray  # (n,) 1 / stiffness [rad/(N m) or m/N]
    base_error: np.ndarray  # (4, 4) true mount_T_base = nominal @ base_error
    hand_eye_error: np.ndarray  # (4, 4) true flange_T_camera = nominal @ hand_eye_error

    def to_dict(self) -> dict:
        return {"joints": list(self.joint_names), "encoder_offsets": self.offsets.tolist(),
                "encoder_noise_std": self.noise_std.tolist(), "compliance": self.compliance.tolist(),
                "base_error": self.base_error.tolist(), "hand_eye_error": self.hand_eye_error.tolist(),
                "mount_T_base": None if self.config.mount_T_base is None
                else np.reshape(self.config.mount_T_base, (4, 4)).tolist(),
                "flange_T_camera": None if self.config.flange_T_camera is None
                else np.reshape(self.config.flange_T_camera, (4, 4)).tolist()}


def random_pose_error(error: PoseError, rng: np.random.Generator) -> np.ndarray:
    """A rigid transform of the error's size, translation and rotation axis in uniformly
    random directions (both drawn, so the stream of draws does not depend on the sizes)."""
    from scipy.spatial.transform import Rotation

    axis, shift = rng.normal(size=3), rng.normal(size=3)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * error.rotation).as_matrix()
    T[:3, 3] = shift / np.linalg.norm(shift) * error.translation
    return T


@functools.lru_cache(maxsize=4)
def _joint_origin(urdf: str, link: str) -> np.ndarray:
    """The origin of the joint above ``link`` as a 4 x 4 transform (parent link -> link)."""

    root = etree.fromstring(urdf.encode())
    joint = next(j for j in root.iterfind("joint") if child(j, "child").get("link") == link)
    origin = child(joint, "origin")
    xyz = [float(v) for v in (origin.get("xyz") or "0 0 0").split()]
    rpy = [float(v) for v in (origin.get("rpy") or "0 0 0").split()]
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(*rpy)
    T[:3, 3] = xyz
    return T


@functools.lru_cache(maxsize=1)
def _all_joint_names() -> frozenset[str]:
    """Planning joints of every shipped cell (a profile may name joints of another cell)."""

    names: set[str] = set()
    for name in shipped_cells():
        names |= set(load_cell(name).planning_joints)
    return frozenset(names)


def true_cell(cell: Cell, errors: KinematicErrors, rng: np.random.Generator, where: str = "profile") -> TrueCell:
    """Draw the true robot of a session: encoder offsets, then the base and the hand-eye
    error directions (always in that order, from ``rng``)."""
    names = cell.joint_names
    for name, _ in errors.stiffness:
        if name not in _all_joint_names():
            raise InputError(f"{where}: kinematics.joint_stiffness.{shown_key(name) or '<key>'} is not a joint of "
                             "the cells",
                             hint="joints: " + ", ".join(sorted(_all_joint_names())))
    prismatic = np.asarray(cell.kin.limits.prismatic, dtype=bool)
    std = np.where(prismatic, errors.axis_offset_std, errors.joint_offset_std)
    offsets = rng.normal(size=len(names)) * std
    noise = np.where(prismatic, errors.axis_noise_std, errors.encoder_noise_std)
    base_error = random_pose_error(errors.base, rng)
    hand_eye_error = random_pose_error(errors.hand_eye, rng)
    config = cell.config
    if errors.base != PoseError():
        nominal = (np.reshape(config.mount_T_base, (4, 4)) if config.mount_T_base is not None
                   else _joint_origin(cell.urdf, cell.kin.cell.base_link))
        config = replace(config, mount_T_base=tuple((nominal @ base_error).ravel()))
    if errors.hand_eye != PoseError():
        q0 = cell.kin.neutral()
        nominal = invert(cell.kin.frame_pose(q0, cell.kin.cell.flange_link)) @ cell.kin.world_T_camera(q0)
        config = replace(config, flange_T_camera=tuple((nominal @ hand_eye_error).ravel()))
    return TrueCell(config, tuple(names), offsets, noise, np.asarray(errors.compliance(names)), base_error,
                    hand_eye_error)


class JointSensor:
    """The joint readings of the true robot (see the module docstring)."""

    def __init__(self, truth: TrueCell, rng: np.random.Generator) -> None:
        self.truth = truth
        self.rng = rng
        self._gravity = bool(np.any(truth.compliance > 0))
        if self._gravity:
            self.model = pin.buildModelFromXML(expand_urdf(replace(truth.config, safety_distance=0.0)))
            self.data = self.model.createData()

    def deflection(self, q: np.ndarray) -> np.ndarray:
        """Elastic deflection C g(q) at true link angles q [rad or m]."""
        if not self._gravity:
            return np.zeros(len(q))
        return self.truth.compliance * pin.computeGeneralizedGravity(self.model, self.data, np.asarray(q, float))

    def sense(self, q: np.ndarray) -> np.ndarray:
        """Noise-free reading at true link angles q."""
        return q + self.truth.offsets + self.deflection(q)

    def read(self, q: np.ndarray) -> np.ndarray:
        """A reading as the robot reports it (with encoder noise)."""
        noise = self.rng.normal(size=len(q)) * self.truth.noise_std
        return self.sense(q) + noise

    def link_angles(self, reading: np.ndarray) -> np.ndarray:
        """True link angles whose noise-free reading is ``reading`` (fixed point; the
        deflection changes by far less than itself over the deflection)."""
        q = np.asarray(reading, dtype=float) - self.truth.offsets
        base = q.copy()
        for _ in range(6):
            q = base - self.deflection(q)
        return q
