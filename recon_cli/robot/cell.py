"""The cell: one description expanded once, and everything built from it.

``Cell`` bundles the pinocchio kinematics, the collision model (pinocchio/coal; with the optional
object bounding box) and the IK solver of one ``CellConfig``; callers above this module
ask it for camera poses, IK solutions and collision checks.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from recon_cli.errors import InvalidViewError, UnreachableViewError
from recon_cli.geometry.view import View, world_T_camera
from recon_cli.robot.collision import CollisionModel, ObjectBox
from recon_cli.robot.description import CellConfig, expand_urdf
from recon_cli.robot.ik import IKOptions, IKResult, IKSolver, IKStatus, check_library_size
from recon_cli.robot.kinematics import Kinematics
from recon_cli.robot.limits import JointLimits
from recon_cli.robot.shapes import CollisionShape


class Cell:
    """Kinematics, collision model and IK of one cell configuration."""

    def __init__(self, config: CellConfig = CellConfig(),  # noqa: B008 (frozen)
                 object_box: ObjectBox | None = None) -> None:
        self.config = config
        self.urdf = expand_urdf(config)
        self.kin = Kinematics(self.urdf, config.cell_file)
        check_library_size(self.kin)  # before the collision model, whose making takes longest
        self.collision = CollisionModel(self.urdf, self.kin, object_box, config.safety_distance)
        self.ik = IKSolver(self.kin, self.collision)
        self.world_T_marker = self.kin.world_T_marker()

    @property
    def limits(self) -> JointLimits:
        return self.kin.limits

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.kin.joint_names

    def set_object_box(self, box: ObjectBox | None) -> None:
        self.collision.set_object_box(box)

    def view_pose(self, view: View) -> npt.NDArray[np.float64]:
        """``world_T_camera`` of a view given in the world or the marker frame."""
        return world_T_camera(view, self.world_T_marker)

    def table_top_shape(self) -> CollisionShape:
        """The table top's collision shape (the cell file's ``table.shape``)."""
        name = self.config.cell_file.table_shape
        return next(s for s in self.collision.env_shapes if s.name == name)

    @property
    def table_surface_z(self) -> float:
        """[m] world height of the table top surface (from the description, lift included)."""
        top = self.table_top_shape()
        return float(top.joint_T_shape[2, 3] + top.dims[2] / 2.0 - self.config.safety_distance)

    def check_camera_position(self, world_T_cam: npt.NDArray[np.float64], what: str = "view") -> None:
        """Refuse a camera pose whose origin lies inside an obstacle (table, frame, object)."""
        p = world_T_cam[:3, 3]
        top = self.table_top_shape()
        centre, half = top.joint_T_shape[:3, 3], np.asarray(top.dims) / 2.0  # axis-aligned
        if np.all(np.abs(p[:2] - centre[:2]) <= half[:2]) and p[2] < centre[2] + half[2]:
            raise InvalidViewError(
                f"{what} puts the camera at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m, inside or "
                f"under the table top (surface at z = {centre[2] + half[2] - self.config.safety_distance:.3f} m, "
                f"{self.config.safety_distance:.3f} m safety distance above it)",
                hint="choose a smaller polar angle theta or a higher focus point",
            )
        inside = self.collision.point_inside_environment(p)
        if inside is not None:
            raise InvalidViewError(
                f"{what} puts the camera at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m inside "
                f"{inside} (with the {self.config.safety_distance:.3f} m safety distance)",
                hint="choose a larger radius or a smaller polar angle theta",
            )

    def solve_pose(self, world_T_cam: npt.NDArray[np.float64], rng: np.random.Generator,
                   seed: npt.NDArray[np.float64] | None = None,
                   options: IKOptions = IKOptions(),  # noqa: B008 (frozen)
                   what: str = "view") -> IKResult:
        """IK for a camera pose; raises when the pose cannot be reached collision-free."""
        self.check_camera_position(world_T_cam, what)
        result = self.ik.solve(world_T_cam, rng, seed=seed, options=options)
        if result.status is IKStatus.UNREACHABLE:
            p = world_T_cam[:3, 3]
            raise UnreachableViewError(
                f"{what} is out of reach of the {self.config.name} cell: no IK solution "
                f"within the soft joint limits for the camera at ({p[0]:.3f}, {p[1]:.3f}, "
                f"{p[2]:.3f}) m after {result.attempts} attempts",
                hint="move the focus point toward the table or change r, theta or phi",
            )
        if result.status is IKStatus.COLLIDING:
            a, b = result.colliding_pairs[0] if result.colliding_pairs else ("?", "?")
            raise UnreachableViewError(
                f"{what} is reachable only in collision ({result.converged} IK solutions, all "
                f"colliding, e.g. {a} with {b})",
                hint="change r, theta or phi, or shrink the object box / safety distance",
            )
        return result

    def solve_view(self, view: View, rng: np.random.Generator,
                   seed: npt.NDArray[np.float64] | None = None,
                   options: IKOptions = IKOptions()) -> IKResult:  # noqa: B008 (frozen)
        return self.solve_pose(self.view_pose(view), rng, seed=seed, options=options)
