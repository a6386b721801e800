"""Rigid transforms as 4x4 numpy arrays named ``parent_T_child``.

Units: metres and radians. ``rpy`` follows URDF: fixed-axis roll about x, then pitch
about y, then yaw about z, so ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt


def rot_x(a: float) -> npt.NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> npt.NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> npt.NDArray[np.float64]:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> npt.NDArray[np.float64]:
    """URDF roll-pitch-yaw [rad] to a rotation matrix, shape (3, 3)."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def pose(rotation: npt.ArrayLike | None = None,
         translation: npt.ArrayLike = (0.0, 0.0, 0.0)) -> npt.NDArray[np.float64]:
    """A 4x4 homogeneous transform from a (3, 3) rotation and a translation [m]."""
    T = np.eye(4)
    if rotation is not None:
        T[:3, :3] = rotation
    T[:3, 3] = translation
    return T


def pose_from_xyz_rpy(xyz: npt.ArrayLike, rpy: Sequence[float]) -> npt.NDArray[np.float64]:
    """The URDF ``<origin xyz rpy>`` convention as a 4x4 transform."""
    return pose(rpy_to_matrix(*rpy), xyz)


def invert(T: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Inverse of a rigid transform, without a general matrix inverse."""
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def rotation_angle(R: npt.NDArray[np.float64]) -> float:
    """Angle [rad] of a rotation matrix, robust near 0 and pi."""
    c = (np.trace(R) - 1.0) / 2.0
    s = np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    return float(np.arctan2(s, np.clip(c, -1.0, 1.0)))


def axis_angle(axis: npt.ArrayLike, angle: float) -> npt.NDArray[np.float64]:
    """Rotation (3, 3) by ``angle`` [rad] about the unit ``axis`` (Rodrigues)."""
    x, y, z = np.asarray(axis, dtype=float)
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.asarray(np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K), dtype=float)


def rotation_between(a: npt.ArrayLike, b: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The smallest rotation (3, 3) that turns unit vector ``a`` onto unit vector ``b`` (for
    opposite vectors: a half turn about an axis perpendicular to them)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    axis = np.cross(a, b)
    s, c = float(np.linalg.norm(axis)), float(np.dot(a, b))
    if s < 1e-12:
        if c > 0.0:
            return np.eye(3)
        other = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return axis_angle(other / np.linalg.norm(other), np.pi)
    return axis_angle(axis / s, float(np.arctan2(s, c)))


def pose_error(T_a: npt.NDArray[np.float64], T_b: npt.NDArray[np.float64]) -> tuple[float, float]:
    """Translation [m] and rotation [rad] between two poses of the same frame."""
    dt = float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]))
    dr = rotation_angle(T_a[:3, :3].T @ T_b[:3, :3])
    return dt, dr


def transform_points(T: npt.NDArray[np.float64], points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Apply a 4x4 transform to points of shape (N, 3)."""
    return points @ T[:3, :3].T + T[:3, 3]
