"""Camera views given by focus point, radius and three angles (thesis 2.1.2, Figure 2.3).

A view puts the camera at ``f + r (sin t cos p, sin t sin p, cos t)`` in its reference
frame, looking at the focus point ``f`` (camera z-axis through f), rolled by ``alpha``
about the viewing direction. With ``alpha = 0`` the camera x-axis is horizontal
(perpendicular to the reference z-axis). Camera frame as in OpenCV: z forward, x right,
y down. The axes are those of the thesis' script manager (../shared/CELL_FACTS.md 10.2).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import numpy.typing as npt

from recon_cli.errors import InvalidViewError

#: bounds of a view, the same as a script's (README "limits"): no cell is larger
MAX_COORDINATE = 100.0  # [m] of the focus point
MAX_RADIUS = 10.0  # [m]


class Frame(StrEnum):
    """Reference frame a view (or a box) is given in."""

    WORLD = "world"
    MARKER = "marker"


@dataclass(frozen=True)
class View:
    """A camera view. Lengths in [m], angles in [rad].

    focus: focus point f, shape (3,), in ``frame``
    radius: camera distance r from f
    theta: polar angle from the reference z-axis (0 = looking straight down)
    phi: azimuth about the reference z-axis
    alpha: roll of the camera about its viewing direction
    """

    focus: tuple[float, float, float]
    radius: float
    theta: float
    phi: float
    alpha: float = 0.0
    frame: Frame = Frame.WORLD

    def __post_init__(self) -> None:
        values = (*self.focus, self.radius, self.theta, self.phi, self.alpha)
        if not all(math.isfinite(v) for v in values):
            raise InvalidViewError(f"view has a non-finite value: {self}", hint="use finite numbers")
        if self.radius <= 0.0:
            raise InvalidViewError(
                f"view radius r = {self.radius} m is not positive",
                hint="give the camera distance from the focus point in metres, e.g. 0.6",
            )
        if self.radius > MAX_RADIUS:
            raise InvalidViewError(f"view radius r = {self.radius:.4g} m is beyond {MAX_RADIUS:g} m",
                                   hint="give the camera distance from the focus point in metres, e.g. 0.6")
        worst = max(abs(v) for v in self.focus)
        if worst > MAX_COORDINATE:
            raise InvalidViewError(f"view focus point has a coordinate of {worst:.4g} m, beyond "
                                   f"±{MAX_COORDINATE:g} m", hint="give the focus point in metres, e.g. 0,0,0.78")

    @classmethod
    def from_degrees(cls, focus: Iterable[float], radius: float, theta_deg: float, phi_deg: float,
                     alpha_deg: float = 0.0, frame: Frame = Frame.WORLD) -> View:
        fx, fy, fz = (float(v) for v in focus)
        return cls((fx, fy, fz), float(radius), math.radians(theta_deg),
                   math.radians(phi_deg), math.radians(alpha_deg), Frame(frame))

    def frame_T_camera(self) -> npt.NDArray[np.float64]:
        """Camera pose in the view's own reference frame, shape (4, 4)."""
        return view_pose(np.asarray(self.focus, dtype=float), self.radius, self.theta,
                         self.phi, self.alpha)


def view_pose(focus: npt.NDArray[np.float64], radius: float, theta: float, phi: float,
              alpha: float) -> npt.NDArray[np.float64]:
    """``frame_T_camera`` of a view (f, r, theta, phi, alpha); see the module docstring."""
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(phi), math.cos(phi)
    sa, ca = math.sin(alpha), math.cos(alpha)
    radial = np.array([st * cp, st * sp, ct])
    z = -radial
    x = np.array([cp * ct * sa - sp * ca, sp * ct * sa + cp * ca, -st * sa])
    y = np.array([cp * ct * ca + sp * sa, sp * ct * ca - cp * sa, -st * ca])
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = x, y, z
    T[:3, 3] = focus + radius * radial
    return T


def world_T_camera(view: View, world_T_marker: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Camera pose in the world for a view given in the world or the marker frame."""
    T = view.frame_T_camera()
    if view.frame is Frame.MARKER:
        return world_T_marker @ T
    return T


def look_at_pose(position: npt.NDArray[np.float64], target: npt.NDArray[np.float64],
                 up: npt.NDArray[np.float64] = np.array([0.0, 0.0, 1.0])) -> npt.NDArray[np.float64]:  # noqa: B008
    """Camera pose at ``position`` looking at ``target`` with x perpendicular to ``up``."""
    z = np.asarray(target, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    x = np.cross(-np.asarray(up, float), z)  # "down x z": right-handed with y pointing down
    n = np.linalg.norm(x)
    if n < 1e-9:  # looking along "up": any horizontal x will do
        x = np.array([1.0, 0.0, 0.0]) - z * z[0]
        n = np.linalg.norm(x)
    x /= n
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, position
    return T
