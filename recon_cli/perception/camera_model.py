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


# --------------------------------------------------------------------- lens distortion
def undistort_normalized(x0: np.ndarray, y0: np.ndarray, distortion, iterations: int = 20
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Ideal normalized image coordinates of distorted ones (OpenCV's model with k1, k2, p1,
    p2[, k3]; the same fixed-point iteration as cv2.undistortPoints, run to convergence)."""
    k1, k2, p1, p2, k3 = (list(distortion) + [0.0] * 5)[:5]
    x, y = x0.copy(), y0.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        x, y = (x0 - dx) / radial, (y0 - dy) / radial
    return x, y


def distorted_pixel_maps(K_distorted: Intrinsics, distortion, K_pinhole: Intrinsics
                         ) -> tuple[np.ndarray, np.ndarray]:
    """For every pixel of a camera with lens distortion (OpenCV model, coefficients
    k1, k2, p1, p2[, k3]), the position (float32 maps for ``cv2.remap``) where its ray meets
    the image of a distortion-free pinhole camera at the same centre and orientation."""
    u = (np.arange(K_distorted.width, dtype=np.float64) - K_distorted.cx) / K_distorted.fx
    v = (np.arange(K_distorted.height, dtype=np.float64) - K_distorted.cy) / K_distorted.fy
    x0, y0 = np.meshgrid(u, v)
    x, y = undistort_normalized(x0, y0, distortion)
    return ((K_pinhole.fx * x + K_pinhole.cx).astype(np.float32),
            (K_pinhole.fy * y + K_pinhole.cy).astype(np.float32))


def undistort_depth(depth: np.ndarray, K: Intrinsics, distortion) -> np.ndarray:
    """A depth image [m] of a camera with lens distortion resampled (nearest pixel) into the
    pinhole camera with the same K: back-project the result with K alone."""
    import cv2

    map_x, map_y = cv2.initUndistortRectifyMap(K.matrix(), np.asarray(distortion, dtype=np.float64), None,
                                               K.matrix(), (K.width, K.height), cv2.CV_32FC1)
    return cv2.remap(depth, map_x, map_y, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def undistort_color(color: np.ndarray, K: Intrinsics, distortion) -> np.ndarray:
    """The colour image of a camera with lens distortion in the pinhole camera with the same K."""
    import cv2

    map_x, map_y = cv2.initUndistortRectifyMap(K.matrix(), np.asarray(distortion, dtype=np.float64), None,
                                               K.matrix(), (K.width, K.height), cv2.CV_32FC1)
    return cv2.remap(color, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
