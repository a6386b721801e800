"""Kinematics of the cell with pinocchio, built from the expanded URDF.

``Kinematics.world_T_camera(q)`` is eq. 2.10 of the thesis: the chain of link transforms
from the world to the camera's optical frame (the cell file's ``camera.frame``). Joint
vectors follow the URDF tree order, which the cell file's ``joints.planning`` lists (the thesis
order in the shipped cells: base_joint_1, base_joint_2, arm_joint_1 ... arm_joint_7 in the
9-DoF gantry cell, arm_joint_1 ... arm_joint_7 in the 7-DoF ceiling cell).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from recon_cli.lazy import lazy_module
from recon_cli.robot.cell_file import CellFile
from recon_cli.robot.limits import JointLimits, limits_from_urdf

if TYPE_CHECKING:
    import pinocchio as pin
else:
    pin = lazy_module("pinocchio")



class Kinematics:
    """Forward kinematics and Jacobians of one cell. Not thread-safe (one pinocchio Data).

    ``cell``: the cell file the URDF was expanded from (frames, limits).
    """

    def __init__(self, urdf: str, cell: CellFile) -> None:
        self.cell: CellFile = cell
        self.model: pin.Model = pin.buildModelFromXML(urdf)
        self.data: pin.Data = self.model.createData()
        self.joint_names: tuple[str, ...] = tuple(self.model.names[1:])
        self.limits: JointLimits = limits_from_urdf(urdf, self.joint_names, self.cell.limits, self.cell)
        self.camera_frame_id: int = self.model.getFrameId(self.cell.camera_frame)
        self._marker_frame_id: int = self.model.getFrameId(self.cell.board_frame)

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    def frame_id(self, name: str) -> int:
        fid = self.model.getFrameId(name)
        if fid >= self.model.nframes:
            raise KeyError(name)
        return int(fid)

    def frame_pose(self, q: npt.NDArray[np.float64], frame: str | int) -> npt.NDArray[np.float64]:
        """``world_T_frame`` at configuration q, shape (4, 4)."""
        fid = self.frame_id(frame) if isinstance(frame, str) else frame
        pin.forwardKinematics(self.model, self.data, q)
        world_T_frame: npt.NDArray[np.float64] = pin.updateFramePlacement(self.model, self.data, fid).homogeneous
        return world_T_frame

    def world_T_camera(self, q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Camera (optical frame) pose in the world at q, eq. 2.10, shape (4, 4)."""
        return self.frame_pose(q, self.camera_frame_id)

    def world_T_marker(self) -> npt.NDArray[np.float64]:
        """Pose of the marker board frame in the world (fixed), shape (4, 4)."""
        return self.frame_pose(pin.neutral(self.model), self._marker_frame_id)

    def camera_jacobian(self, q: npt.NDArray[np.float64], local: bool = False) -> npt.NDArray[np.float64]:
        """Geometric Jacobian of the camera frame, shape (6, n), rows (v, omega).

        local=False: linear velocity of the camera origin and angular velocity, both in
        world axes (LOCAL_WORLD_ALIGNED); local=True: both in camera axes.
        """
        ref = pin.LOCAL if local else pin.LOCAL_WORLD_ALIGNED
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacement(self.model, self.data, self.camera_frame_id)
        jacobian: npt.NDArray[np.float64] = pin.getFrameJacobian(self.model, self.data, self.camera_frame_id, ref)
        return jacobian

    def neutral(self) -> npt.NDArray[np.float64]:
        q: npt.NDArray[np.float64] = pin.neutral(self.model)
        return q
