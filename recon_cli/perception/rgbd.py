"""An RGB-D frame (colour + metric depth + intrinsics) as an Open3D point cloud."""

from __future__ import annotations

import numpy as np

from recon_cli.perception.camera_model import Intrinsics


def rgbd_cloud(color: np.ndarray | None, depth: np.ndarray, intrinsics: Intrinsics,
               world_T_camera: np.ndarray | None = None, depth_trunc: float = 3.0):
    """Points of every depth pixel (0 = no return) with its colour, in the camera frame or
    placed by ``world_T_camera``. color: (H, W, 3) uint8 RGB or None; depth: (H, W) [m]."""
    import open3d as o3d

    rgb = color if color is not None else np.zeros((*depth.shape, 3), np.uint8)
    # arrays are buffers: numpy's stubs say so for Python 3.12 and newer only, Open3D's take a Buffer
    image = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(np.ascontiguousarray(rgb)), o3d.geometry.Image(depth.astype(np.float32)),  # type: ignore[call-overload]
        depth_scale=1.0, depth_trunc=depth_trunc, convert_rgb_to_intensity=False)
    cloud = o3d.geometry.PointCloud.create_from_rgbd_image(image, intrinsics.to_open3d())
    if world_T_camera is not None:
        cloud.transform(world_T_camera)
    return cloud
