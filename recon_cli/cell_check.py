"""``recon cell check``: is a cell file fit to scan with?

Loads the cell (its description, kinematics, collision model and sensor) and answers what a
user writing a cell file for their own robot needs to know before the first scan:

- the joints and their limits as recon reads them (URDF values and the cell file's overrides);
- the home pose: inside the soft limits, free of self-collision and of collision with the
  table and everything else of the cell, with its clearances;
- the board: is it in the camera's view from home, and from a view straight above it at the
  camera's scan distance (registration needs the board, or the kinematics alone);
- the simulation: the MuJoCo scene of the cell is built (a description MuJoCo refuses is one
  error line) and renders one small depth frame from home, its camera at the cell's camera
  frame;
- reachability over the table top: on a grid of points, a focus point ``focus_height`` above
  the table top, the number of viewing directions (polar angles :data:`THETAS` x
  :data:`AZIMUTHS` azimuths, at the sensor's scan distance) with a collision-free IK
  solution: where an object can be scanned from how many sides, and why the other directions
  fail (the camera inside an obstacle, every IK solution in collision, no IK solution). The
  cell file's object position is one of the points reported, each of its directions with its
  reason (no IK solution split into out of reach and held by a joint limit).

A problem (home in collision or outside the soft limits, the board in view from no checked
view, the object position seen from less than :data:`MIN_OBJECT_SHARE` of the directions)
makes the check fail; everything else is information.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from recon_cli.backends.sim.camera import render_rgbd, world_T_camera_gl
from recon_cli.backends.sim.scene import build_scene, mujoco
from recon_cli.errors import InputError, ReconError
from recon_cli.geometry.transforms import invert, pose_error, transform_points
from recon_cli.geometry.view import View
from recon_cli.perception.camera_model import opencv_from_opengl
from recon_cli.perception.charuco import cell_board
from recon_cli.perception.sensor import SensorModel, cell_sensor
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import descendant_links, rigid_mount
from recon_cli.robot.collision import DistanceReport
from recon_cli.robot.ik import IKOptions, IKStatus
from recon_cli.robot.shapes import CollisionShape

#: polar angles of the checked viewing directions [deg] (0: looking straight down)
THETAS = (20.0, 40.0, 60.0)
#: azimuths per polar angle
AZIMUTHS = 8
#: IK effort per direction: a few seeds find a reachable view, an unreachable one costs little
IK = IKOptions(max_solutions=1, max_attempts=10)
#: the cell fails the check when its object position is reachable from fewer directions
MIN_OBJECT_SHARE = 0.5
#: descents from which a direction without IK solution is told apart: out of reach or held by a limit
DIAGNOSIS_DESCENTS = 3
#: [px] width of the depth frame the check renders (it proves the scene renders, not the image)
SIM_WIDTH = 160
#: [m], [rad] the simulated camera lies at the kinematics' camera frame within these
SIM_POSE_TOLERANCE = 1e-6

#: why a viewing direction has no collision-free IK solution
INSIDE = "camera inside an obstacle"
COLLIDES = "in collision"
NO_IK = "no IK solution"
OUT_OF_REACH = "unreachable by IK"
AT_LIMIT = "held by a joint limit"


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
class Direction:
    """One viewing direction of a focus point and what became of it: ``failure`` "" (reached) or
    one of :data:`INSIDE`, :data:`COLLIDES`, :data:`NO_IK` (:data:`OUT_OF_REACH` and
    :data:`AT_LIMIT` when told apart); ``detail``: the obstacle, the colliding pair, the joint
    at its limit or how far the nearest IK attempt ends from the goal."""

    theta: float  # [rad]
    phi: float  # [rad]
    failure: str = ""
    detail: str = ""

    @property
    def reached(self) -> bool:
        return not self.failure

    @property
    def where(self) -> str:
        return f"theta {math.degrees(self.theta):.0f} deg, phi {math.degrees(self.phi):.0f} deg"


def failure_summary(directions: list[Direction] | tuple[Direction, ...]) -> str:
    """"8 out of reach, 2 in collision (e.g. a with b)": the failed directions by reason, most
    frequent first, each with its first detail."""
    groups: dict[str, list[Direction]] = {}
    for d in directions:
        if not d.reached:
            groups.setdefault(d.failure, []).append(d)
    parts = []
    for failure, group in sorted(groups.items(), key=lambda kv: -len(kv[1])):
        detail = next((d.detail for d in group if d.detail), "")
        parts.append(f"{len(group)} {failure}" + (f" (e.g. {detail})" if detail else ""))
    return ", ".join(parts) if parts else "none failed"


@dataclass(frozen=True)
class SimulationCheck:
    """The cell's MuJoCo scene at home: its camera against the kinematics' camera frame, and a
    small depth frame."""

    camera_offset: float  # [m]
    camera_turn: float  # [rad]
    width: int  # [px] of the rendered depth frame
    height: int
    depth_share: float  # of its pixels with a depth inside the sensor's working range

    @property
    def camera_agrees(self) -> bool:
        return self.camera_offset <= SIM_POSE_TOLERANCE and self.camera_turn <= SIM_POSE_TOLERANCE


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
    #: the grid's failed directions by reason (over all points)
    failures: tuple[tuple[str, int], ...] = ()
    #: the grid's reached directions per polar angle [deg] (share over all points)
    by_theta: tuple[tuple[float, float], ...] = ()
    #: the object position's directions, each with its reason
    object_directions: tuple[Direction, ...] = ()
    #: the grid's failed directions, first of each reason (for the examples)
    grid_examples: tuple[Direction, ...] = ()


@dataclass(frozen=True)
class CellCheck:
    name: str
    file: str
    joints: tuple[JointRow, ...]
    sensor: SensorModel
    home: np.ndarray
    home_margin: float  # [rad or m] smallest distance to a soft limit (negative: outside)
    home_margin_joint: str  # the joint of home_margin
    home_outside: tuple[str, ...]  # one text per joint of home outside its soft limits
    home_collisions: tuple[tuple[str, str], ...]
    home_distance: DistanceReport
    board_home: BoardSight
    board_above: BoardSight | None  # None: no collision-free view above the board
    reach: Reachability
    problems: tuple[str, ...]
    simulation: SimulationCheck | None = None


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
    """The camera's own parts (bracket, housing, optical frame): the links fixed under the link
    where the camera frame and the flange meet on their rigid body (the flange itself when the
    camera hangs below it)."""
    cf = cell.config.cell_file
    mount = rigid_mount(cell.urdf, cf.flange_link, cf.camera_frame)
    return descendant_links(cell.urdf, mount if mount and not mount.startswith("joint ") else cf.flange_link,
                            fixed_only=True)


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


def _pair(pair: tuple[str, str]) -> str:
    return " with ".join(label.split("/")[-1] for label in pair)


def _unit(cell: Cell, i: int, value: float) -> str:
    """A joint value in the unit the cell file writes it in (deg, m for linear axes)."""
    return f"{value:.4g} m" if cell.limits.prismatic[i] else f"{math.degrees(value):.4g} deg"


def _no_solution(cell: Cell, T: np.ndarray, rng: np.random.Generator) -> tuple[str, str]:
    """Why a camera pose has no IK solution: a few descents, the one ending nearest the goal
    tells (a joint held at its soft limit, or out of reach and how far)."""
    lim = cell.limits
    best = None
    for attempt in range(DIAGNOSIS_DESCENTS):
        q, _, ep, er = cell.ik.descend(T, cell.ik.start(attempt, T, rng, None), IK)
        if best is None or ep + 0.1 * er < best[1] + 0.1 * best[2]:
            best = (q, ep, er)
    assert best is not None
    q, ep, er = best
    at_lo = np.isclose(q, lim.soft_lower, rtol=0.0, atol=1e-9)
    at_hi = np.isclose(q, lim.soft_upper, rtol=0.0, atol=1e-9)
    held = [f"{lim.names[i]} at its soft {'lower' if at_lo[i] else 'upper'} limit "
            f"{_unit(cell, int(i), float(q[i]))}" for i in np.nonzero(at_lo | at_hi)[0]]
    if held:
        return AT_LIMIT, ", ".join(held)
    return OUT_OF_REACH, (f"the nearest attempt ends {ep * 1e3:.0f} mm, {math.degrees(er):.0f} deg off, no joint "
                          "at a limit")


def direction_results(cell: Cell, focus: np.ndarray, distance: float, rng: np.random.Generator,
                      times: list[float] | None = None, diagnose: bool = False) -> list[Direction]:
    """Each viewing direction of a focus point: reached (a collision-free IK solution) or why
    not; ``diagnose``: a direction without IK solution is told out of reach or held by a limit
    (a few descents more)."""
    out = []
    for theta, phi in directions():
        try:
            T = cell.view_pose(View((float(focus[0]), float(focus[1]), float(focus[2])), distance, theta, phi))
        except ReconError:
            out.append(Direction(theta, phi, INSIDE, "no camera pose"))
            continue
        try:
            cell.check_camera_position(T)
        except ReconError:
            inside = cell.collision.point_inside_environment(T[:3, 3])
            out.append(Direction(theta, phi, INSIDE, inside.split("/")[-1] if inside else
                                 f"below the table top {cell.config.cell_file.table_shape}"))
            continue
        result = cell.ik.solve(T, rng, options=IK)
        if times is not None:
            times.append(result.seconds)
        if result.ok:
            out.append(Direction(theta, phi))
        elif result.status is IKStatus.COLLIDING:
            out.append(Direction(theta, phi, COLLIDES, _pair(result.colliding_pairs[0])
                                 if result.colliding_pairs else ""))
        elif diagnose:
            out.append(Direction(theta, phi, *_no_solution(cell, T, rng)))
        else:
            out.append(Direction(theta, phi, NO_IK))
    return out


def reachable_directions(cell: Cell, focus: np.ndarray, distance: float, rng: np.random.Generator,
                         times: list[float] | None = None) -> int:
    """Viewing directions of a focus point with a collision-free IK solution."""
    return sum(d.reached for d in direction_results(cell, focus, distance, rng, times))


def check_simulation(cell: Cell, q: np.ndarray) -> SimulationCheck:
    """Build the cell's MuJoCo scene (one error line when MuJoCo cannot load the description)
    and render a :data:`SIM_WIDTH` px wide depth frame at ``q``."""
    scene = build_scene(cell.config)
    data = mujoco.MjData(scene.model)
    data.qpos[scene.qpos_index] = q
    mujoco.mj_forward(scene.model, data)
    offset, turn = pose_error(opencv_from_opengl(world_T_camera_gl(data, scene.camera_id)),
                              cell.kin.world_T_camera(q))
    sensor = scene.sensor
    K = sensor.intrinsics(SIM_WIDTH / sensor.width)
    renderer = mujoco.Renderer(scene.model, K.height, K.width)
    try:
        _, depth = render_rgbd(renderer, data, scene.camera_id)
    finally:
        renderer.close()
    share = float(np.mean((depth >= sensor.z_min) & (depth <= sensor.z_max)))
    return SimulationCheck(offset, turn, K.width, K.height, share)


def check_cell(cell: Cell, rng: np.random.Generator, step: float = 0.1, focus_height: float = 0.08,
               progress: Callable[[int, int], None] | None = None) -> CellCheck:
    """Check a cell (see the module docstring); ``step`` [m] is the reachability grid's spacing."""
    cf = cell.config.cell_file
    check_layout(cell)
    sensor = cell_sensor(cf)
    home = cf.pose("home", cell.joint_names) if "home" in dict(cf.poses) else cell.kin.neutral()
    simulation = check_simulation(cell, home)
    lim = cell.limits
    margins = lim.margin_to_soft(home)
    tightest = int(np.argmin(margins))
    margin = float(margins[tightest])
    outside = tuple(
        f"{n} at {_unit(cell, i, float(home[i]))} is {_unit(cell, i, float(-margins[i]))} "
        f"{'below its soft lower' if home[i] < lim.soft_lower[i] else 'above its soft upper'} limit "
        f"{_unit(cell, i, float(lim.soft_lower[i] if home[i] < lim.soft_lower[i] else lim.soft_upper[i]))}"
        for i, n in enumerate(lim.names) if margins[i] < 0)
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
    grid: list[Direction] = []
    for j, y in enumerate(ys):
        for i, x in enumerate(xs):
            results = direction_results(cell, np.array([x, y, z + focus_height]), d, rng, times)
            counts[j, i] = sum(r.reached for r in results)
            grid += results
            if progress is not None:
                progress(j * len(xs) + i + 1, total)
    obj = np.asarray(cf.object_position, dtype=float)
    at_object = direction_results(cell, obj + np.array([0.0, 0.0, focus_height]), d, rng, times, diagnose=True)
    object_count = sum(r.reached for r in at_object)
    if progress is not None:
        progress(total, total)
    base = cell.kin.frame_pose(home, cf.base_link)[:3, 3]
    failures: dict[str, int] = {}
    examples: dict[str, Direction] = {}
    for r in grid:
        if not r.reached:
            failures[r.failure] = failures.get(r.failure, 0) + 1
            examples.setdefault(r.failure, r)
    by_theta = tuple((t, float(np.mean([r.reached for r in grid if math.isclose(math.degrees(r.theta), t)])))
                     for t in THETAS)
    reach = Reachability(xs, ys, counts, len(directions()), d, focus_height, (x0, x1, y0, y1),
                         (float(base[0]), float(base[1])), points[:4, :2], (float(obj[0]), float(obj[1])),
                         object_count, float(np.median(times) * 1e3) if times else math.nan,
                         tuple(sorted(failures.items(), key=lambda kv: -kv[1])), by_theta, tuple(at_object),
                         tuple(examples.values()))

    problems = []
    if outside:
        problems.append(f"the home pose is outside the soft joint limits: {'; '.join(outside)}")
    if collisions:
        a, b = collisions[0]
        problems.append(f"the home pose collides ({len(collisions)} pairs, e.g. {a} with {b})")
    if not sight_home.seen and (above is None or not above.seen):
        problems.append("the camera sees the whole board neither from home nor from a view above it at "
                        f"{d:.3g} m")
    if object_count < MIN_OBJECT_SHARE * reach.directions:
        problems.append(f"the object position is reachable from {object_count} of {reach.directions} "
                        f"directions at {d:.3g} m (fewer than {MIN_OBJECT_SHARE:.0%}); not reached: "
                        f"{failure_summary(at_object)}")
    if not simulation.camera_agrees:
        problems.append(f"the simulated camera lies {simulation.camera_offset * 1e3:.3g} mm and "
                        f"{math.degrees(simulation.camera_turn):.3g} deg from the camera frame {cf.camera_frame}")
    return CellCheck(cf.name, str(cf.path), joint_rows(cell), sensor, home, margin, lim.names[tightest], outside,
                     collisions, distance, sight_home, above, reach, tuple(problems), simulation)


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
