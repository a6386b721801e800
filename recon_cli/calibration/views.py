"""Board views for calibration: the camera around the ChArUco board, tilted and rolled.

Hand-eye calibration needs flange rotations about several axes (Tsai and Lenz: two
non-parallel rotation axes at least, better many); camera calibration needs the board
tilted in different directions and placed across the image (so the corners reach the
image border, where distortion shows). One generated set serves both: views in the marker
frame whose polar angle theta, azimuth phi, roll alpha, distance r and focus offset run
through low-discrepancy sequences (golden-ratio steps), so any prefix of the set is spread
as well as a set of its size can be. Deterministic: no random numbers.

The distances are those of the thesis' camera (the MotionCam-3D M, whose image the thesis'
board just fills at 0.42 m). Another camera sees the board from distances scaled so that
the board covers the same share of its image (:meth:`BoardViewOptions.for_camera`): the
FR3's RealSense D405, 87 deg wide, from 0.23-0.28 m, inside its depth range, instead of
0.42-0.52 m at the end of it, where the board's squares would be 45 % smaller in the image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from recon_cli.errors import InputError
from recon_cli.geometry.view import Frame, View
from recon_cli.perception.charuco import BoardSpec
from recon_cli.perception.sensor import SensorModel, motioncam_3d_m

_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0  # 0.618...


@dataclass(frozen=True)
class BoardViewOptions:
    """The generated set (lengths [m], angles [rad]).

    n: number of views
    radius: camera distance from the focus point, from ... to (for the thesis' camera;
        :meth:`for_camera` scales it for another)
    theta: tilt of the viewing direction from the board normal, from ... to
    alpha: largest roll about the viewing direction (both signs)
    offset: largest shift of the focus point from the board centre, along x and y of the
        marker frame (moves the board across the image)
    """

    n: int = 20
    radius: tuple[float, float] = (0.42, 0.52)
    theta: tuple[float, float] = (math.radians(12.0), math.radians(48.0))
    alpha: float = math.radians(35.0)
    offset: tuple[float, float] = (0.06, 0.04)

    def __post_init__(self) -> None:
        if not 1 <= self.n <= 200:
            raise InputError(f"{self.n} calibration views is outside 1 ... 200", hint="e.g. 20")
        lo, hi = self.radius
        if not 0.05 <= lo <= hi <= 3.0:
            raise InputError(f"view distance {lo:g} ... {hi:g} m is not an increasing range within 0.05 ... 3 m",
                             hint="e.g. 0.42 ... 0.52 m (the board fills the image at about 0.45 m)")
        lo, hi = self.theta
        if not 0.0 <= lo <= hi < math.radians(80.0):
            raise InputError(f"view tilt {math.degrees(lo):g} ... {math.degrees(hi):g} deg is not an increasing "
                             "range within 0 ... 80 deg", hint="e.g. 12 ... 48 deg")

    def for_camera(self, board: BoardSpec, sensor: SensorModel) -> BoardViewOptions:
        """The same views for ``sensor``: the distances scaled by how much nearer (or farther)
        than the thesis' camera it sees the board fill its image (1 for the thesis' camera)."""
        scale = fill_distance(board, sensor) / fill_distance(board, motioncam_3d_m())
        return replace(self, radius=(self.radius[0] * scale, self.radius[1] * scale))


def fill_distance(board: BoardSpec, sensor: SensorModel) -> float:
    """The distance [m] at which the board, seen face-on, fills the sensor's image: spans its
    width or its height, whichever it reaches first."""
    K = sensor.intrinsics()
    return max(board.size[0] * K.fx / K.width, board.size[1] * K.fy / K.height)


def _frac(x: float) -> float:
    return x - math.floor(x)


def board_views(board: BoardSpec, options: BoardViewOptions = BoardViewOptions()  # noqa: B008 (frozen)
                ) -> tuple[View, ...]:
    """Views of the board in the marker frame (see the module docstring)."""
    cx, cy = board.size[0] / 2.0, board.size[1] / 2.0
    (r0, r1), (t0, t1) = options.radius, options.theta
    views = []
    for k in range(options.n):
        u_theta = _frac(0.5 + k * _GOLDEN)  # tilt: golden-ratio sequence in [0, 1)
        u_radius = _frac(0.25 + k * math.sqrt(2.0))  # distance: another irrational step
        phi = math.radians(137.50776) * k + math.radians(15.0)  # golden angle: azimuths spread evenly
        alpha = options.alpha * math.sin(2.4 * k + 0.7)  # roll: both signs, all sizes
        # the focus point moves against the azimuth, so the board slides across the image
        dx = -options.offset[0] * math.cos(phi + 1.1 * k)
        dy = -options.offset[1] * math.sin(phi + 0.7 * k)
        views.append(View((cx + dx, cy + dy, 0.0), r0 + (r1 - r0) * u_radius, t0 + (t1 - t0) * u_theta,
                          phi, alpha, Frame.MARKER))
    return tuple(views)
