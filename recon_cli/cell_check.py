"""``recon cell check``: is a cell file fit to scan with?

Loads the cell (its description, kinematics, collision model and sensor) and answers what a
user writing a cell file for their own robot needs to know before the first scan:

- the joints and their limits as recon reads them (URDF values and the cell file's overrides);
- the home pose: inside the soft limits, free of self-collision and of collision with the
  table and everything else of the cell, with its clearances;
- the board: is it in the camera's view from home, and from a view straight above it at the
  camera's scan distance (registration needs the board, or the kinematics alone);
- reachability over the table top: on a grid of points, a focus point ``focus_height`` above
  the table top, the number of viewing directions (polar angles :data:`THETAS` x
  :data:`AZIMUTHS` azimuths, at the sensor's scan distance) with a collision-free IK
  solution: where an object can be scanned from how many sides. The cell file's object
  position is one of the points reported.

A problem (home in collision or outside the soft limits, the board in view from no checked
view, the object position seen from less than :data:`MIN_OBJECT_SHARE` of the directions)
makes the check fail; everything else is information.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from recon_cli.errors import InputError, ReconError
from recon_cli.geometry.transforms import invert, transform_points
from recon_cli.geometry.view import View
from recon_cli.perception.charuco import cell_board
from recon_cli.perception.sensor import SensorModel, cell_sensor
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import descendant_links
from recon_cli.robot.collision import DistanceReport
from recon_cli.robot.ik import IKOptions
from recon_cli.robot.shapes import CollisionShape

#: polar angles of the checked viewing directions [deg] (0: looking straight down)
THETAS = (20.0, 40.0, 60.0)
#: azimuths per polar angle
AZIMUTHS = 8
#: IK effort per direction: a few seeds find a reachable view, an unreachable one costs little
IK = IKOptions(max_solutions=1, max_attempts=10)
#: the cell fails the check when its object position is reachable from fewer directions
MIN_OBJECT_SHARE = 0.5


@dataclass(frozen=True)
class JointRow:
    """One planning joint as recon reads it (m for linear axes, rad otherwise)."""

    name: str
    prismatic: bool
    lower: float
    upper: float
    soft_lower: float
    soft_upper: float
    velocity: float
    acceleration: float
    effort: float


@dataclass(frozen=True)
class BoardSight:
    """How much of the board (its 4 corners and centre) a camera pose sees, and from where."""

    points_in_view: int
    distance: float  # [m] camera to board centre along the viewing direction
    where: str  # "home" or "above the board"

    @property
    def seen(self) -> bool:
        return self.points_in_view == 5


@dataclass(frozen=True)
class Reachability:
    """Reachable viewing directions on a grid over the table top.

    xs (nx,), ys (ny,): grid [m, world]; counts (ny, nx): directions with a collision-free IK
    solution; directions: how many were tried per point; distance: camera distance [m];
    focus_height: of the focus points above the table top [m]; table: (x0, x1, y0, y1) of the
    table top; base: (x, y) of the robot base at home; board: (4, 2) board corners (x, y)."""

    xs: np.ndarray
    ys: np.ndarray
    counts: np.ndarray
    directions: int
    distance: float
    focus_height: float
    table: tuple[float, float, float, float]
    base: tuple[float, float]
    board: np.ndarray
    object_xy: tuple[float, float]
    object_count: int
    ik_ms_median: float


@dataclass(frozen=True)
class CellCheck:
    name: str
    file: str
    joints: tuple[JointRow, ...]
    sensor: SensorModel
    home: np.ndarray
    home_margin: float  # [rad or m] smallest distance to a soft limit (negative: outside)
    home_collisions: tuple[tuple[str, str], ...]
    home_distance: DistanceReport
    board_home: BoardSight
    board_above: BoardSight | None  # None: no collision-free view above the board
    reach: Reachability
    problems: tuple[str, ...]


#: [m] how far the board's top face may lie from the table top's surface
BOARD_HEIGHT_TOLERANCE = 0.02


def _inside(shape: CollisionShape, world_T_shape: np.ndarray, point: np.ndarray, shrink: float) -> bool:
    """Is a world point inside a primitive shrunk by ``shrink`` on every side (the real shape
    within its safety inflation)?"""
    p = transform_points(invert(world_T_shape), point[None, :])[0]
    d = np.asarray(shape.dims, dtype=float)
    if shape.kind == "box":
        return bool(np.all(np.abs(p) < d / 2.0 - shrink))
    if shape.kind == "sphere":
        return bool(np.linalg.norm(p) < d[0] - shrink)
    r, length = d[0] - shrink, d[1] / 2.0
    if shape.kind == "cylinder":
        return bool(np.hypot(p[0], p[1]) < r and abs(p[2]) < length - shrink)
    axial = np.clip(p[2], -length, length)  # capsule: distance to its segment
    return bool(np.linalg.norm(p - np.array([0.0, 0.0, axial])) < r)


def check_layout(cell: Cell) -> None:
    """Refuse a cell whose board lies off its table top, or whose camera's optical centre lies
    inside a link of the robot at home (one line naming the cell file's line)."""
    cf = cell.config.cell_file
    x0, x1, y0, y1, z = table_top(cell)
    corners = board_corners(cell)[:4]
    margin = 1e-3
    off = [c for c in corners if not (x0 - margin <= c[0] <= x1 + margin and y0 - margin <= c[1] <= y1 + margin)]
    if off or np.max(np.abs(corners[:, 2] - z)) > BOARD_HEIGHT_TOLERANCE:
        c = off[0] if off else corners[int(np.argmax(np.abs(corners[:, 2] - z)))]
        raise InputError(f"{cf.where('board.frame')}: the board ({board_corners(cell)[0, 2]:.3f} m high) lies off the "
                         f"table top {cf.table_shape} (x {x0:.3f} ... {x1:.3f}, y {y0:.3f} ... {y1:.3f} m, surface "
                         f"at {z:.3f} m): its corner ({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}) m",
                         hint="place the board's link on the table top in the description, or name the right "
                              "board.frame and table.shape")
    home = cf.pose("home", cell.joint_names) if "home" in dict(cf.poses) else cell.kin.neutral()
    optical = cell.kin.world_T_camera(home)[:3, 3]
    own = set(camera_links(cell))
    poses = cell.collision.shape_poses(home)
    for shape, T in zip(cell.collision.robot_shapes, poses, strict=True):
        if shape.link not in own and _inside(shape, T, optical, cell.config.safety_distance):
            raise InputError(f"{cf.where('camera.frame')}: the camera's optical centre lies inside "
                             f"{shape.label} (at home)",
                             hint="check the camera mount in the description (camera_xyz / camera_pose): the "
                                  "optical frame belongs in front of the camera, outside the robot's links")


def camera_links(cell: Cell) -> tuple[str, ...]:
    """The links fixed under the flange: the camera's own parts (bracket, housing, optical frame)."""
    return descendant_links(cell.urdf, cell.config.cell_file.flange_link, fixed_only=True)


def joint_rows(cell: Cell) -> tuple[JointRow, ...]:
    lim = cell.limits
    return tuple(JointRow(n, bool(lim.prismatic[i]), float(lim.lower[i]), float(lim.upper[i]),
                          float(lim.soft_lower[i]), float(lim.soft_upper[i]), float(lim.velocity[i]),
                          float(lim.acceleration[i]), float(lim.effort[i]))
                 for i, n in enumerate(lim.names))


def board_corners(cell: Cell) -> np.ndarray:
    """The printed board's 4 corners and its centre in the world, (5, 3)."""
    sx, sy = cell_board(cell.config.cell_file).size
    local = np.array([[0, 0, 0], [sx, 0, 0], [sx, sy, 0], [0, sy, 0], [sx / 2, sy / 2, 0]], dtype=float)
    return transform_points(cell.world_T_marker, local)


def board_sight(world_T_camera: np.ndarray, points: np.ndarray, sensor: SensorModel, where: str) -> BoardSight:
    """How many of the board's points lie in the image and inside the working range."""
    p = transform_points(invert(world_T_camera), points)
    K = sensor.intrinsics()
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = K.fx * p[:, 0] / z + K.cx
        v = K.fy * p[:, 1] / z + K.cy
    ok = (z >= sensor.z_min) & (z <= sensor.z_max) & (u >= 0) & (u <= K.width) & (v >= 0) & (v <= K.height)
    return BoardSight(int(np.count_nonzero(ok)), float(z[-1]), where)


def table_top(cell: Cell) -> tuple[float, float, float, float, float]:
    """(x0, x1, y0, y1, z) of the table top's surface (axis-aligned, without the safety margin)."""
    top = cell.table_top_shape()
    sd = cell.config.safety_distance
    c, half = top.joint_T_shape[:3, 3], np.asarray(top.dims) / 2.0 - sd
    return (float(c[0] - half[0]), float(c[0] + half[0]), float(c[1] - half[1]), float(c[1] + half[1]),
            cell.table_surface_z)


def directions(rng_phi0: float = 0.0) -> list[tuple[float, float]]:
    """(theta, phi) [rad] of the checked viewing directions."""
    return [(math.radians(t), rng_phi0 + 2.0 * math.pi * k / AZIMUTHS) for t in THETAS for k in range(AZIMUTHS)]


def reachable_directions(cell: Cell, focus: np.ndarray, distance: float, rng: np.random.Generator,
                         times: list[float] | None = None) -> int:
    """Viewing directions of a focus point with a collision-free IK solution."""
    count = 0
    for theta, phi in directions():
        try:
            T = cell.view_pose(View((float(focus[0]), float(focus[1]), float(focus[2])), distance, theta, phi))
            cell.check_camera_position(T)
        except ReconError:
            continue
        result = cell.ik.solve(T, rng, options=IK)
        if times is not None:
            times.append(result.seconds)
        count += result.ok
    return count


def check_cell(cell: Cell, rng: np.random.Generator, step: float = 0.1, focus_height: float = 0.08,
               progress: Callable[[int, int], None] | None = None) -> CellCheck:
    """Check a cell (see the module docstring); ``step`` [m] is the reachability grid's spacing."""
    cf = cell.config.cell_file
    check_layout(cell)
    sensor = cell_sensor(cf)
    home = cf.pose("home", cell.joint_names) if "home" in dict(cf.poses) else cell.kin.neutral()
    margin = float(np.min(cell.limits.margin_to_soft(home)))
    collisions = cell.collision.check(home).pairs
    distance = cell.collision.distance(home)
    points = board_corners(cell)
    sight_home = board_sight(cell.kin.world_T_camera(home), points, sensor, "home")
    d = sensor.default_distance
    above = None
    centre = points[-1]
    for alpha in np.radians([0.0, 90.0, 180.0, 270.0]):  # the camera's roll above the board
        try:
            T = cell.view_pose(View(tuple(float(v) for v in centre), d, 0.0, 0.0, float(alpha)))  # type: ignore[arg-type]
            cell.check_camera_position(T)
        except ReconError:
            continue
        if cell.ik.solve(T, rng, options=IK).ok:
            above = board_sight(T, points, sensor, "above the board")
            break

    x0, x1, y0, y1, z = table_top(cell)
    nx, ny = max(1, round((x1 - x0) / step)), max(1, round((y1 - y0) / step))  # cells of about step
    xs = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
    ys = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
    counts = np.zeros((len(ys), len(xs)), dtype=int)
    total = len(xs) * len(ys) + 1
    times: list[float] = []
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            counts[j, i] = reachable_directions(cell, np.array([x, y, z + focus_height]), d, rng, times)
            if progress is not None:
                progress(j * len(xs) + i + 1, total)
    obj = np.asarray(cf.object_position, dtype=float)
    object_count = reachable_directions(cell, obj + np.array([0.0, 0.0, focus_height]), d, rng, times)
    if progress is not None:
        progress(total, total)
    base = cell.kin.frame_pose(home, cf.base_link)[:3, 3]
    reach = Reachability(xs, ys, counts, len(directions()), d, focus_height, (x0, x1, y0, y1),
                         (float(base[0]), float(base[1])), points[:4, :2], (float(obj[0]), float(obj[1])),
                         object_count, float(np.median(times) * 1e3) if times else math.nan)

    problems = []
    if margin < 0:
        problems.append(f"the home pose is outside the soft joint limits by {-margin:.3g} (rad or m)")
    if collisions:
        a, b = collisions[0]
        problems.append(f"the home pose collides ({len(collisions)} pairs, e.g. {a} with {b})")
    if not sight_home.seen and (above is None or not above.seen):
        problems.append("the camera sees the whole board neither from home nor from a view above it at "
                        f"{d:.3g} m")
    if object_count < MIN_OBJECT_SHARE * reach.directions:
        problems.append(f"the object position is reachable from {object_count} of {reach.directions} "
                        f"directions at {d:.3g} m (fewer than {MIN_OBJECT_SHARE:.0%})")
    return CellCheck(cf.name, str(cf.path), joint_rows(cell), sensor, home, margin, collisions, distance,
                     sight_home, above, reach, tuple(problems))


def reachability_png(path, check: CellCheck) -> None:
    """The reachability picture: reachable directions over the table top, with the table, the
    board, the robot base and the object position."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Polygon, Rectangle

    r = check.reach
    fig, ax = plt.subplots(figsize=(7.5, 6.0), dpi=110)
    x0, x1, y0, y1 = r.table
    extent = (x0, x1, y0, y1)  # the grid's cells tile the table top
    im = ax.imshow(r.counts, origin="lower", extent=extent, cmap="viridis", vmin=0, vmax=r.directions,
                   interpolation="nearest")
    fig.colorbar(im, ax=ax, label=f"reachable viewing directions (of {r.directions})")
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec="black", lw=1.5))
    ax.add_patch(Polygon(r.board, closed=True, fill=False, ec="white", lw=1.5, ls="--"))
    ax.plot(*r.base, marker="s", color="red", ms=9, label="robot base (home)")
    ax.plot(*r.object_xy, marker="*", color="orange", ms=14,
            label=f"object position: {r.object_count} of {r.directions}")
    pad = 0.1
    ax.set_xlim(min(x0, r.base[0]) - pad, max(x1, r.base[0]) + pad)
    ax.set_ylim(min(y0, r.base[1]) - pad, max(y1, r.base[1]) + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("world x [m]")
    ax.set_ylabel("world y [m]")
    thetas = ", ".join(f"{t:g}" for t in THETAS)
    ax.set_title(f"{check.name}: camera at {r.distance:.3g} m from a point {r.focus_height * 100:.0f} cm above "
                 f"the table,\npolar angles {thetas} deg x {AZIMUTHS} azimuths", fontsize=10)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
