"""Geometry and colours for recordings: clouds from depth images, camera paths along
trajectories, view markers, signed-distance colours, images encoded for the file."""

from __future__ import annotations

import numpy as np

from recon_cli.perception.camera_model import Intrinsics

#: the colours of the autoscan iteration pictures (viewplan/picture.py), as RGB bytes
STATUS_RGB = {"infeasible": (214, 39, 40), "completed": (44, 160, 44), "planned": (31, 119, 180),
              "active": (255, 191, 0)}
#: at most this many points of a scan's cloud go into a recording (the image keeps every pixel)
SCAN_POINTS = 60_000
#: image size of the current camera's preview, relative to the scan's
PREVIEW_SCALE = 0.25
#: samples per second of a trajectory's joint animation
JOINT_RATE_HZ = 25.0
#: signed distances beyond this [m] get the end colours of the scale
DISTANCE_RANGE_M = 0.0005


def scan_points(depth: np.ndarray, color: np.ndarray | None, K: Intrinsics, world_T_camera: np.ndarray,
                max_points: int = SCAN_POINTS) -> tuple[np.ndarray, np.ndarray | None]:
    """Points (N, 3) in the world of every ``stride``-th pixel with depth, and their colours;
    the stride is the smallest that keeps N <= max_points."""
    valid = depth > 0
    count = int(np.count_nonzero(valid))
    stride = max(1, int(np.ceil(np.sqrt(count / max_points)))) if count else 1
    d = depth[::stride, ::stride]
    v, u = np.nonzero(d > 0)
    z = d[v, u]
    u, v = u * stride, v * stride
    p = np.stack([(u - K.cx) / K.fx * z, (v - K.cy) / K.fy * z, z], axis=1)
    world = p @ world_T_camera[:3, :3].T + world_T_camera[:3, 3]
    rgb = None if color is None else color[v, u]
    return world.astype(np.float32), rgb


def scaled_images(color: np.ndarray | None, depth: np.ndarray, K: Intrinsics, scale: float
                  ) -> tuple[np.ndarray | None, np.ndarray, Intrinsics]:
    """Colour (area-averaged) and depth (nearest: no blending across edges) at ``scale`` of
    their size, with the intrinsics that go with them."""
    if scale == 1.0:
        return color, depth, K
    import cv2

    w, h = max(1, round(K.width * scale)), max(1, round(K.height * scale))
    sx, sy = w / K.width, h / K.height
    Ks = Intrinsics(w, h, K.fx * sx, K.fy * sy, (K.cx + 0.5) * sx - 0.5, (K.cy + 0.5) * sy - 0.5)
    small = None if color is None else cv2.resize(color, (w, h), interpolation=cv2.INTER_AREA)
    return small, cv2.resize(depth, (w, h), interpolation=cv2.INTER_NEAREST), Ks


def camera_path(kin, q: np.ndarray) -> np.ndarray:
    """Camera positions (K, 3) in the world at the configurations q (K, n)."""
    return np.array([kin.world_T_camera(qk)[:3, 3] for qk in q])


def trajectory_samples(trajectory) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] from 0 and configurations of a trajectory at JOINT_RATE_HZ, its end included."""
    n = max(2, int(np.ceil(trajectory.duration * JOINT_RATE_HZ)) + 1)
    t = np.linspace(0.0, trajectory.duration, n)
    return t, trajectory.sample(t)[0]


def view_arrows(poses: list[np.ndarray], length: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """Origins and viewing directions (camera z, OpenCV) of camera poses."""
    if not poses:
        return np.zeros((0, 3)), np.zeros((0, 3))
    T = np.asarray(poses, float)
    return T[:, :3, 3], T[:, :3, 2] * length


def distance_colors(d: np.ndarray, limit: float = DISTANCE_RANGE_M) -> np.ndarray:
    """RGB bytes of signed distances on a diverging scale: blue inside, white on, red outside."""
    from matplotlib import colormaps

    x = np.clip(np.asarray(d, float) / limit, -1.0, 1.0) * 0.5 + 0.5
    return (colormaps["coolwarm"](x)[:, :3] * 255).astype(np.uint8)


def jpeg(color: np.ndarray, quality: int = 90) -> bytes:
    """RGB image as JPEG bytes."""
    import cv2

    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(color, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return buf.tobytes()


def depth_png(depth: np.ndarray, scale: float) -> bytes:
    """Depth [m] as 16-bit PNG bytes of depth x scale (0 = no return)."""
    import cv2

    d = np.clip(np.round(depth * scale), 0, 65535).astype(np.uint16)
    ok, buf = cv2.imencode(".png", d)
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def board_corners_world(spec, world_T_marker: np.ndarray) -> np.ndarray:
    """The outline of the board's printed area (5 points, closed) in the world."""
    w, h = spec.size
    m = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0], [0, 0, 0]], float)
    return m @ world_T_marker[:3, :3].T + world_T_marker[:3, 3]
