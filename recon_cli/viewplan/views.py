"""Views on the ellipsoid (thesis 2.1.3): camera pose from a surface point (eqs. 2.4-2.5),
the potential-field cost of a candidate (eqs. 2.6, 2.8) and surface sampling (eq. 2.7)."""

from __future__ import annotations

import numpy as np

from recon_cli.config import VIEWPLAN_M
from recon_cli.errors import InputError
from recon_cli.viewplan.ellipsoid import Ellipsoid


def camera_pose(ellipsoid: Ellipsoid, p: np.ndarray, d_c: float) -> np.ndarray:
    """world_T_camera (OpenCV axes) for the surface point p (frame E): the camera sits at
    distance d_c from p along the outward normal, its z-axis along the inward normal, its
    x-axis perpendicular to the world z-axis (the camera is level)."""
    n_E = ellipsoid.normal(p)
    position = ellipsoid.to_world(np.asarray(p, float) + d_c * n_E)
    z = -(ellipsoid.world_T_E[:3, :3] @ n_E)
    x = np.cross(np.array([0.0, 0.0, -1.0]), z)  # world down x z: horizontal
    if np.linalg.norm(x) < 1e-9:  # looking straight down or up: any horizontal x
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, position
    return T


def potential(ellipsoid: Ellipsoid, candidates: np.ndarray, previous: np.ndarray, sigma: float) -> np.ndarray:
    """Eq. 2.6: sum over previous samples of 1 / (||s - p'||_E^2 + sigma), for candidates
    (M, 3) and previous samples (K, 3), all in frame E."""
    if len(previous) == 0:
        return np.zeros(len(candidates))
    diff = np.asarray(candidates)[:, None, :] - np.asarray(previous)[None, :, :]
    d2 = ellipsoid.norm(diff) ** 2
    return np.sum(1.0 / (d2 + sigma), axis=1)


def next_sample(ellipsoid: Ellipsoid, previous: np.ndarray, m: int, sigma: float,
                rng: np.random.Generator) -> np.ndarray:
    """Eq. 2.7: of M random surface points (uniform directions on the sphere mapped onto
    the ellipsoid), the one with the lowest potential. ``m`` within VIEWPLAN_M (every candidate
    is compared with every earlier sample at once)."""
    if not VIEWPLAN_M[0] <= m <= VIEWPLAN_M[1]:
        raise InputError(f"{m} preliminary samples per view is outside {VIEWPLAN_M[0]} ... {VIEWPLAN_M[1]}",
                         hint=f"choose m within {VIEWPLAN_M[0]} ... {VIEWPLAN_M[1]} (thesis: 200)")
    u = rng.normal(size=(m, 3))
    candidates = ellipsoid.surface_from_directions(u)
    return candidates[int(np.argmin(potential(ellipsoid, candidates, np.asarray(previous).reshape(-1, 3), sigma)))]
