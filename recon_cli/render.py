"""Terminal rendering of results (tables); the CLI calls these after the library ran."""

from __future__ import annotations

import math

import numpy as np
from rich.table import Table

from recon_cli.cell_check import CellCheck, Direction
from recon_cli.geometry.transforms import invert
from recon_cli.robot.cell import Cell
from recon_cli.robot.ik import IKResult


def joint_value(value: float, prismatic: bool) -> str:
    return f"{value:+.4f} m" if prismatic else f"{math.degrees(value):+8.3f}°"


def pose_text(T: np.ndarray) -> str:
    p = T[:3, 3]
    z = T[:3, 2]
    return (f"position ({p[0]:+.4f}, {p[1]:+.4f}, {p[2]:+.4f}) m, "
            f"viewing direction ({z[0]:+.3f}, {z[1]:+.3f}, {z[2]:+.3f})")


def cell_tables(cell: Cell, q_show: np.ndarray, q_label: str) -> list:
    lim = cell.limits
    out = []
    joints = Table(title=f"joints of the {cell.config.name} cell ({lim.n} DoF)")
    for col in ("joint", "type", "hard limits", "soft limits", "velocity", "acceleration"):
        joints.add_column(col)
    for i, name in enumerate(lim.names):
        p = bool(lim.prismatic[i])
        unit = "m" if p else "°"
        k = 1.0 if p else 180.0 / math.pi
        joints.add_row(
            name, "prismatic" if p else "revolute",
            f"{lim.lower[i] * k:+.4g} … {lim.upper[i] * k:+.4g} {unit}",
            f"{lim.soft_lower[i] * k:+.4g} … {lim.soft_upper[i] * k:+.4g} {unit}",
            f"{lim.velocity[i] * k:.4g} {unit}/s", f"{lim.acceleration[i] * k:.4g} {unit}/s²",
        )
    out.append(joints)

    shapes = Table(title=f"collision shapes (inflated by the safety distance "
                         f"{cell.config.safety_distance:.3f} m)")
    for col in ("side", "link", "shape", "kind", "size (m)"):
        shapes.add_column(col)
    for side, group in (("robot", cell.collision.robot_shapes), ("environment", cell.collision.env_shapes)):
        for s in group:
            if s.kind == "box":
                size = " × ".join(f"{d:.4g}" for d in s.dims)
            elif s.kind in ("capsule", "cylinder"):
                size = f"r {s.dims[0]:.4g}, length {s.dims[1]:.4g}"
            else:
                size = f"r {s.dims[0]:.4g}"
            shapes.add_row(side, s.link, s.name, s.kind, size)
    out.append(shapes)

    cam = Table(title="camera and marker frames")
    cam.add_column("frame")
    cam.add_column("pose")
    flange_link = cell.config.cell_file.flange_link
    flange = cell.kin.frame_pose(q_show, flange_link)
    T_cam = cell.kin.world_T_camera(q_show)
    f_T_c = invert(flange) @ T_cam
    cam.add_row(f"camera in flange ({flange_link})", pose_text(f_T_c))
    cam.add_row(f"camera in world at {q_label}", pose_text(T_cam))
    m = cell.world_T_marker
    cam.add_row("marker in world", f"origin ({m[0, 3]:+.4f}, {m[1, 3]:+.4f}, {m[2, 3]:+.4f}) m, x "
                f"({m[0, 0]:+.0f}, {m[1, 0]:+.0f}, {m[2, 0]:+.0f}), z ({m[0, 2]:+.0f}, {m[1, 2]:+.0f}, {m[2, 2]:+.0f})")
    out.append(cam)
    return out


def _short(pair: tuple[str, str]) -> str:
    return " ↔ ".join(label.split("/")[-1] for label in pair)


#: what python-fcl's distance query returns for shapes that touch or overlap when it computes no
#: depth for them (boxes, cylinders; capsules and spheres get their depth as a negative distance)
FCL_NO_DEPTH = -1.0


def distance_text(distance: float, pair: tuple[str, str], what: str) -> str:
    """A smallest distance of a DistanceReport in words: in mm with its pair; "none checked"
    when no pair of the kind is checked; the pair touching or overlapping where FCL gives no
    depth."""
    if not math.isfinite(distance):
        return f"no {what} pairs checked"
    if distance == FCL_NO_DEPTH:
        return f"touching or overlapping ({_short(pair)}; no depth computed for these shapes)"
    if distance < 0:
        return f"overlapping by {-distance * 1e3:.1f} mm ({_short(pair)})"
    return f"{distance * 1e3:.1f} mm ({_short(pair)})"


def ik_table(cell: Cell, result: IKResult) -> Table:
    lim = cell.limits
    table = Table(title=f"{len(result.solutions)} IK solution(s) in {result.seconds * 1e3:.1f} ms "
                        f"({result.attempts} seeds, {result.converged} converged, "
                        f"{result.rejected_collision} colliding)")
    table.add_column("joint")
    for k in range(len(result.solutions)):
        table.add_column(f"#{k + 1}", justify="right")
    for i, name in enumerate(lim.names):
        table.add_row(name, *[joint_value(s.q[i], bool(lim.prismatic[i])) for s in result.solutions])
    margins, clear, selfd = [], [], []
    for s in result.solutions:
        m = lim.margin_to_soft(s.q)
        j = int(np.argmin(m / (lim.soft_upper - lim.soft_lower)))  # tightest relative to range
        margins.append(f"{joint_value(m[j], bool(lim.prismatic[j])).strip()} ({lim.names[j]})")
        d = cell.collision.distance(s.q)
        clear.append(distance_text(d.environment, d.environment_pair, "robot-environment"))
        selfd.append(distance_text(d.self_, d.self_pair, "self-collision"))
    table.add_section()
    table.add_row("limit margin", *margins)
    table.add_row("clearance", *clear)
    table.add_row("self distance", *selfd)
    return table


def cell_check_report(check: CellCheck) -> list:
    """The tables and lines of ``recon cell check``."""
    out: list = [f"cell {check.name} ({check.file})"]
    joints = Table(title="planning joints (deg and deg/s, m and m/s for linear axes)")
    for col in ("joint", "type", "lower", "upper", "soft lower", "soft upper", "velocity", "acceleration", "effort"):
        joints.add_column(col, justify="left" if col in ("joint", "type") else "right")
    for j in check.joints:
        k = 1.0 if j.prismatic else 180.0 / math.pi
        joints.add_row(j.name, "linear" if j.prismatic else "revolute",
                       *(f"{v * k:.4g}" for v in (j.lower, j.upper, j.soft_lower, j.soft_upper, j.velocity,
                                                  j.acceleration)), f"{j.effort:.4g}")
    out.append(joints)
    d = check.home_distance
    home = "collision-free" if not check.home_collisions else \
        f"IN COLLISION ({', '.join(_short(p) for p in check.home_collisions[:3])})"
    j = next(row for row in check.joints if row.name == check.home_margin_joint)
    margin = f"{check.home_margin:.4g} m" if j.prismatic else f"{math.degrees(check.home_margin):.4g} deg"
    out.append(f"home: {home}; limit margin {margin} ({j.name}"
               + (", outside its soft limits" if check.home_margin < 0 else "") + "); clearance "
               f"{distance_text(d.environment, d.environment_pair, 'robot-environment')}, self distance "
               f"{distance_text(d.self_, d.self_pair, 'self-collision')}")
    s = check.sensor
    out.append(f"camera: {s.name}, {s.width} x {s.height} px, hfov {math.degrees(s.hfov):.1f} deg, range "
               f"{s.z_min:g} ... {s.z_max:g} m, scan distance {s.default_distance:g} m")
    for sight in (check.board_home, check.board_above):
        if sight is None:
            out.append("board: no collision-free view straight above it at the scan distance")
            continue
        out.append(f"board from {sight.where}: {sight.points_in_view} of 5 points (corners, centre) in view"
                   f" at {sight.distance:.3f} m" + ("" if sight.seen else " (not all of it)"))
    sim = check.simulation
    if sim is not None:
        camera = ("its camera at the cell's camera frame" if sim.camera_agrees else
                  f"its camera {sim.camera_offset * 1e3:.3g} mm, {math.degrees(sim.camera_turn):.3g} deg off the "
                  "cell's camera frame")
        out.append(f"simulation: MuJoCo scene built, {camera}; depth frame from home ({sim.width} x {sim.height} "
                   f"px): {sim.depth_share:.0%} of the pixels within the working range")
    r = check.reach
    share = r.counts / r.directions
    out.append(f"reachability: {r.counts.size} points on the table top, {r.directions} directions each at "
               f"{r.distance:g} m: {np.mean(share):.0%} of all views reachable; {np.count_nonzero(share >= 0.75)} "
               f"points seen from >= 75 % of the directions; object position {r.object_count} of {r.directions}; "
               f"IK median {r.ik_ms_median:.1f} ms")
    if r.by_theta:
        out.append("reached by polar angle: " + ", ".join(f"theta {t:g} deg {s:.0%}" for t, s in r.by_theta))
    if r.failures:
        examples = {e.failure: e for e in r.grid_examples}
        out.append("not reached on the grid: " + ", ".join(
            f"{n} {failure} (e.g. {examples[failure].where}"
            + (f": {examples[failure].detail}" if examples[failure].detail else "") + ")"
            for failure, n in r.failures))
    missed: dict[str, list[Direction]] = {}
    for direction in r.object_directions:
        if not direction.reached:
            missed.setdefault(direction.failure, []).append(direction)
    if missed:
        groups = []
        for failure, group in sorted(missed.items(), key=lambda kv: -len(kv[1])):
            where = ", ".join(f"{math.degrees(d.theta):.0f}/{math.degrees(d.phi):.0f}" for d in group)
            example = next((d for d in group if d.detail), None)
            groups.append(f"{len(group)} {failure}: {where}"
                          + (f" (e.g. {example.where}: {example.detail})" if example else ""))
        out.append(f"object position, not reached ({sum(map(len, missed.values()))} of {r.directions}; "
                   f"theta/phi in deg): " + "; ".join(groups))
    return out
