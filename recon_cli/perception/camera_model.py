"""Pinhole intrinsics and the OpenGL/OpenCV camera conventions.

recon's camera frame is OpenCV's: x right, y down, z along the viewing direction. OpenGL
(and MuJoCo) cameras look along their -z axis with y up. Pixel coordinates follow OpenCV:
pixel (u, v) = (column, row), pixel centres at integer coordinates, so the image centre of
a W x H image is ((W - 1) / 2, (H - 1) / 2).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics: image size [px], focal lengths and principal point [px]."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Intrinsics:
        return cls(int(d["width"]), int(d["height"]), float(d["fx"]), float(d["fy"]),
                   float(d["cx"]), float(d["cy"]))

    def to_open3d(self):
        import open3d as o3d

        return o3d.camera.PinholeCameraIntrinsic(self.width, self.height, self.fx, self.fy,
                                                 self.cx, self.cy)

    @property
    def fovy(self) -> float:
        """Vertical field of view [rad] (for a centred principal point)."""
        return 2.0 * math.atan(self.height / 2.0 / self.fy)

    @property
    def fovx(self) -> float:
        return 2.0 * math.atan(self.width / 2.0 / self.fx)


def intrinsics_from_fovy(width: int, height: int, fovy: float) -> Intrinsics:
    """Intrinsics of an OpenGL/MuJoCo perspective camera with vertical field of view
    ``fovy`` [rad]: square pixels, principal point at the image centre."""
    f = (height / 2.0) / math.tan(fovy / 2.0)
    return Intrinsics(width, height, f, f, (width - 1) / 2.0, (height - 1) / 2.0)


def fovy_from_hfov(width: int, height: int, hfov: float) -> float:
    """Vertical field of view [rad] of a W x H image with horizontal field of view hfov."""
    return 2.0 * math.atan(math.tan(hfov / 2.0) * height / width)


#: rotation by pi about x: maps OpenCV camera axes to OpenGL camera axes (and back)
GL_T_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def opencv_from_opengl(world_T_gl: np.ndarray) -> np.ndarray:
    """Pose of the OpenCV camera frame from the pose of an OpenGL camera frame (4x4)."""
    return world_T_gl @ GL_T_CV


def opengl_from_opencv(world_T_cv: np.ndarray) -> np.ndarray:
    """Pose of the OpenGL camera frame (looking along -z, y up) from an OpenCV pose."""
    return world_T_cv @ GL_T_CV


def backproject(depth: np.ndarray, K: Intrinsics) -> np.ndarray:
    """Points in the camera frame, shape (N, 3), of the pixels with depth > 0 [m]."""
    v, u = np.nonzero(depth > 0)
    z = depth[v, u]
    x = (u - K.cx) / K.fx * z
    y = (v - K.cy) / K.fy * z
    return np.stack([x, y, z], axis=1)
