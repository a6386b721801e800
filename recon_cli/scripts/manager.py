"""The script manager (thesis 3.4): runs the typed commands of a script, in order, against
a cell with a simulation or hardware backend, and writes everything into one output folder.

    <out>/scans/                 the scan store (one atomic folder per scan)
    <out>/reconstruction/        registration and surface results (cloud, mesh, report)
    <out>/script.expanded.xml    the script after xacro
    <out>/run_report.json        every command: where it was written, status, time, message

A move that fails (unreachable view, no path) is reported and, by the script's policy,
either skips the scan that belongs to it (``on_failure="skip"``) or stops the run
(``"abort"``); scans already written stay. A dry run plans every move from the previous
planned configuration but moves nothing and scans nothing.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.geometry.view import Frame
from recon_cli.interrupts import exit_code, signal_name
from recon_cli.scripts import commands as C
from recon_cli.scripts.checks import ACTIONS, check_script, is_file_name, readable_file
from recon_cli.scripts.loader import ScriptError

Progress = Callable[[str, int, int], None]

#: exit codes of ``recon run`` (README "Exit codes")
EXIT_DONE, EXIT_ERROR, EXIT_USAGE, EXIT_FAILED, EXIT_ABORTED = 0, 1, 2, 3, 4


class ScriptAborted(ReconError):
    """A failed command under on_failure="abort"."""

    exit_code = EXIT_ABORTED
    label = "aborted"


class RunInterrupted(ReconError):
    """Ctrl-C or SIGTERM during a run: the robot is stopped, completed scans are kept."""

    label = "interrupted"

    def __init__(self, message: str, *, signal: str, hint: str | None = None) -> None:
        super().__init__(message, hint=hint)
        self.signal = signal
        self.exit_code = exit_code(signal)


class HardwareUnavailable(ReconError):
    pass


def movable_groups(commands: tuple[C.Command, ...]) -> dict[int, int]:
    """Runs of at least two camera moves, each followed only by its scans, whose order does
    not matter (scans are independent): {first index: end index}. Anything else (set-up,
    joint moves, waits, registration) keeps its place and splits the runs."""
    groups, k, n = {}, 0, len(commands)
    while k < n:
        start, moves = k, 0
        while k < n and isinstance(commands[k], C.Move):
            k += 1
            moves += 1
            while k < n and isinstance(commands[k], C.Scan):
                k += 1
        if moves >= 2:
            groups[start] = k
        k = max(k, start + 1) if moves == 0 else k
    return groups


def _units(commands) -> list[tuple[C.Command, list[C.Command]]]:
    units: list[tuple[C.Command, list[C.Command]]] = []
    for cmd in commands:
        if isinstance(cmd, C.Move):
            units.append((cmd, []))
        else:
            units[-1][1].append(cmd)
    return units


@dataclass(frozen=True)
class RunOptions:
    out: Path
    backend: str | None = None  # overrides the script's <cell backend=...>
    seed: int = 0
    dry_run: bool = False
    object_name: str | None = None  # simulated object (overrides the script's <object>)
    optimize: bool | None = None  # sequence optimization (None: as the script says)
    sequence_method: str = "ours"  # "ours" (local search) or "thesis" (Table 2.2 + 2.3)
    append: bool = False  # add scans to the scan store already in ``out``


@dataclass
class CommandReport:
    source: str
    command: str
    status: str  # done | failed | skipped | planned | recorded | interrupted
    seconds: float = 0.0
    message: str = ""
    details: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"source": self.source, "command": self.command, "status": self.status,
                "seconds": round(self.seconds, 4), "message": self.message, **self.details}


@dataclass
class RunResult:
    out: Path
    script: C.Script
    reports: list[CommandReport]
    scans: int
    seconds: float
    outputs: dict[str, str]
    aborted: str = ""
    sequences: list[dict] = field(default_factory=list)

    @property
    def failed(self) -> list[CommandReport]:
        return [r for r in self.reports if r.status == "failed"]

    @property
    def exit_code(self) -> int:
        """0 when every command did its work, 3 when some failed (or were skipped for it)."""
        return EXIT_FAILED if self.failed else EXIT_DONE


class ScriptRunner:
    def __init__(self, script: C.Script, options: RunOptions, progress: Progress | None = None) -> None:
        from recon_cli.planning.planner import PlanOptions
        from recon_cli.robot.description import CellConfig

        check_script(script, object_override=options.object_name)
        self.script = script
        self.options = options
        self.progress = progress or (lambda *a: None)
        self.rng = np.random.default_rng(options.seed)
        self.out = Path(options.out)
        self.cell_config = CellConfig()
        self.backend = options.backend or "sim"
        self.resolution, self.noise = 1.0, True
        self.object_name, self.object_scale = options.object_name or "auto", 1.0
        self.box_command: C.SetBox | None = None
        self.plan = PlanOptions()
        self.cell = self.station = self.acquisition = self.store = self.scene_object = None
        self.q_planned: np.ndarray | None = None
        self.move_failed = False
        self.registered = None
        self.reconstruction: dict[str, Path] = {}
        self.fragments: dict[str, object] = {}
        self._fragment_box = None  # crop box of fragments (marker frame), from the session
        self.outputs: dict[str, str] = {}
        self.reports: list[CommandReport] = []
        self.sequences: list[dict] = []
        self.current: C.Command | None = None  # the command in progress (for interruptions)
        optimize = script.optimize if options.optimize is None else options.optimize
        self.groups = movable_groups(script.commands) if optimize else {}

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:
        from recon_cli.outputs import atomic_write_text, refuse_links
        from recon_cli.planning.planner import seed_ompl

        t0 = time.perf_counter()
        seed_ompl(self.options.seed)
        self.out.mkdir(parents=True, exist_ok=True)
        if self.options.append:
            refuse_links(self.out)
            self._keep_earlier("run_report.json", "script.expanded.xml")
        atomic_write_text(self.out / "script.expanded.xml", self.script.expanded_xml)
        aborted, interrupted = "", None
        n = len(self.script.commands)
        try:
            k = 0
            while k < n:
                if k in self.groups:
                    end = self.groups[k]
                    self._run_group(self.script.commands[k:end])
                    k = end
                    self.progress("script", k, n)
                    continue
                self._run_command(self.script.commands[k])
                k += 1
                self.progress("script", k, n)
        except ScriptAborted as exc:
            aborted = str(exc)
            raise
        except KeyboardInterrupt as exc:
            interrupted = self._interruption(signal_name(exc))
            aborted = interrupted["reason"]
        finally:
            self._close()  # stops the robot first
            self._write_report(time.perf_counter() - t0, aborted, interrupted)
        if interrupted is not None:
            raise RunInterrupted(
                f"{interrupted['reason']}; {interrupted['scans_kept']} completed scan(s) kept in {self.out / 'scans'}",
                signal=interrupted["signal"],
                hint=f"run_report.json records it; recon register {self.out / 'scans'} works on the kept scans")
        return RunResult(self.out, self.script, self.reports, self._scan_count(), time.perf_counter() - t0,
                         dict(self.outputs), aborted, list(self.sequences))

    def _keep_earlier(self, *names: str) -> None:
        """--append: an earlier run's report and script stay, as NAME-1, NAME-2, ..."""
        for name in names:
            path = self.out / name
            if path.exists():
                k = 1
                while (self.out / f"{path.stem}-{k}{path.suffix}").exists():
                    k += 1
                path.rename(self.out / f"{path.stem}-{k}{path.suffix}")

    def _interruption(self, signal: str) -> dict:
        cmd = self.current
        where = "between commands" if cmd is None else f"during {cmd.source} ({cmd.describe()})"
        return {"signal": signal, "reason": f"interrupted by {signal} {where}",
                "command": None if cmd is None else str(cmd.source), "scans_kept": self._scan_count()}

    def _run_command(self, cmd: C.Command, planned=None, note: str = "") -> None:
        report = CommandReport(str(cmd.source), cmd.describe(), "done", message=note)
        t = time.perf_counter()
        self.current = cmd
        try:
            if planned is not None:
                self._execute_planned(cmd, planned, report)
            else:
                self._dispatch(cmd, report)
        except ScriptAborted:
            raise
        except KeyboardInterrupt:
            report.status, report.message = "interrupted", "stopped by a signal; the robot was stopped"
            report.seconds = time.perf_counter() - t
            self.reports.append(report)
            raise
        except ReconError as exc:
            report.status, report.message = "failed", exc.one_line()
            if isinstance(cmd, ACTIONS) and not isinstance(cmd, C.Scan):
                self.move_failed = True
            if self.script.on_failure == "abort":
                report.seconds = time.perf_counter() - t
                self.reports.append(report)
                raise ScriptAborted(f"{cmd.source}: {exc.one_line()}",
                                    hint="the script says on_failure=\"abort\"; earlier scans are kept") from None
        report.seconds = time.perf_counter() - t
        self.reports.append(report)
        self.current = None

    # ------------------------------------------------------------------ sequence optimization
    def _run_group(self, commands: tuple[C.Command, ...]) -> None:
        """Moves with their scans, reordered by the sequence optimizer (thesis 2.3); the
        planned paths are executed as planned (no edge is planned twice)."""
        from recon_cli.planning.lower_bound import duration_lower_bound
        from recon_cli.robot.ik import IKOptions
        from recon_cli.sequence.graph import ViewGraph
        from recon_cli.sequence.optimize import local_search_sequence, optimize_graph
        from recon_cli.sequence.tsp import lazy_mst_sequence

        units = _units(commands)
        self._ensure_station()
        q0 = self.q_planned if self.options.dry_run else self.station.robot.measured_joints()
        configs, kept, poses = [np.asarray(q0, dtype=float)], [], []
        for move, scans in units:
            try:  # each view's IK seeded with the previous view's solution (as the thesis)
                T = self._goal_pose(move)
                ik = self.cell.solve_pose(T, self.rng, seed=configs[-1], options=IKOptions(max_solutions=1))
            except ReconError as exc:  # reported in script order, like any failed move
                self._fail_unit(move, scans, exc)
                continue
            configs.append(ik.solutions[0].q)
            kept.append((move, scans))
            poses.append(T)
        if not kept:
            return
        lim, plan = self.cell.limits, self.plan

        def lower(a, b):
            return duration_lower_bound(a, b, lim.velocity, lim.acceleration, plan.velocity_scale,
                                        plan.acceleration_scale)

        def redraw(v):
            try:
                r = self.cell.solve_pose(poses[v - 1], self.rng, options=IKOptions(max_solutions=1))
            except ReconError:
                return None
            return r.solutions[0].q

        from recon_cli.planning.planner import MotionPlanner

        planner = MotionPlanner(self.cell, self.plan)

        def plan_edge(a, b):
            r = planner.plan_to_joints(a, b, seed=int(self.rng.integers(1 << 30)))
            return r.trajectory if r.ok else None

        t = time.perf_counter()
        graph, draws = optimize_graph(ViewGraph(configs, lower), redraw, k_max=120)
        if self.options.sequence_method == "thesis":
            result = lazy_mst_sequence(graph, plan_edge, beta=1.5)
        else:
            result = local_search_sequence(graph, plan_edge, beta=1.5, request_cost=10.0)
        script_order = list(range(graph.size))
        self.sequences.append({
            "moves": len(kept), "method": self.options.sequence_method, "ik_draws": draws,
            "order": [str(kept[v - 1][0].source) + f" #{v}" for v in result.order[1:]],
            "planned_duration_s": result.duration, "planning_requests": result.requests,
            "script_order_lower_bound_s": float(sum(graph.lower_bound(graph.configs[a], graph.configs[b])
                                                    for a, b in zip(script_order[:-1], script_order[1:],
                                                                    strict=True))),
            "seconds": time.perf_counter() - t})
        prev = 0
        for position, v in enumerate(result.order[1:], start=1):
            move, scans = kept[v - 1]
            traj = graph.trajectory(prev, v)
            note = f"sequence position {position} of {len(kept)}"
            self._run_command(move, planned=traj if traj is not None else False, note=note)
            for scan in scans:
                self._run_command(scan)
            prev = v if not self.move_failed else prev

    def _execute_planned(self, cmd: C.Move, traj, report: CommandReport) -> None:
        """A move of an optimized sequence: its planned trajectory, or (when the optimizer
        found no path, ``traj`` False) a normal planning request from where the robot is."""
        if traj is False:
            self._dispatch(cmd, report)
            return
        self.move_failed = False
        report.details.update(planner="sequence", trajectory_s=traj.duration)
        if self.options.dry_run:
            self.q_planned = traj.goal
            report.status = "planned"
            return
        q = self.station.robot.measured_joints()
        if np.max(np.abs(q - traj.start)) > 1e-3:  # not where the plan starts: plan afresh
            self._dispatch(cmd, report)
            return
        self.station.robot.execute(traj)
        self._last_view = (cmd, self._goal_pose(cmd))

    def _fail_unit(self, move: C.Command, scans: list[C.Command], exc: ReconError) -> None:
        self.reports.append(CommandReport(str(move.source), move.describe(), "failed", message=exc.one_line()))
        for scan in scans:
            self.reports.append(CommandReport(str(scan.source), scan.describe(), "skipped",
                                              message="the move before it failed"))
        if self.script.on_failure == "abort":
            raise ScriptAborted(f"{move.source}: {exc.one_line()}",
                                hint="the script says on_failure=\"abort\"; earlier scans are kept")

    def _scan_count(self) -> int:
        return 0 if self.store is None else len(self.store)

    def _write_report(self, seconds: float, aborted: str, interrupted: dict | None = None) -> None:
        from recon_cli.console import write_json

        failed = any(r.status == "failed" for r in self.reports)
        if interrupted is not None:
            status, code = "interrupted", exit_code(interrupted["signal"])
        elif aborted:
            status, code = "aborted", EXIT_ABORTED
        else:
            status, code = ("failed", EXIT_FAILED) if failed else ("done", EXIT_DONE)
        write_json(self.out / "run_report.json", {
            "script": self.script.path, "name": self.script.name, "dialect": self.script.dialect,
            "on_failure": self.script.on_failure, "dry_run": self.options.dry_run, "backend": self.backend,
            "seed": self.options.seed, "seconds": seconds, "scans": self._scan_count(),
            "status": status, "exit_code": code, "aborted": aborted or None, "interrupted": interrupted,
            "append": self.options.append,
            "outputs": self.outputs, "sequence_optimization": self.sequences,
            "commands": [r.to_dict() for r in self.reports],
        })

    def _close(self) -> None:
        if self.station is not None:
            self.station.close()
            self.station = None

    # ------------------------------------------------------------------ dispatch
    def _dispatch(self, cmd: C.Command, report: CommandReport) -> None:
        handler = getattr(self, f"_do_{cmd.keyword}", None)
        if handler is None:  # pragma: no cover - every command class has a handler
            raise ScriptError(f"{cmd.source}: {cmd.keyword} is not supported")
        handler(cmd, report)

    # set-up ------------------------------------------------------------
    def _do_SetCell(self, cmd: C.SetCell, report) -> None:  # noqa: N802
        from recon_cli.robot.description import CellConfig, CellKind

        self.cell_config = CellConfig(kind=CellKind.parse(cmd.kind), safety_distance=cmd.safety_distance)
        self.backend = self.options.backend or cmd.backend
        self.resolution, self.noise = cmd.resolution, cmd.noise

    def _do_SetObject(self, cmd: C.SetObject, report) -> None:  # noqa: N802
        from recon_cli.objects import load_object

        if self.options.object_name is not None:
            return
        name = cmd.name
        if is_file_name(name):
            name = str(readable_file(self.script, name, cmd.source, "object mesh"))
        if name != "auto":
            load_object(name, cmd.scale)  # fails now, with the line, if it cannot be loaded
        self.object_name, self.object_scale = name, cmd.scale

    def _do_SetBox(self, cmd: C.SetBox, report) -> None:  # noqa: N802
        self.box_command = cmd
        if self.cell is not None:
            self.cell.collision.set_object_box(self._object_box())

    def _do_SetPlanner(self, cmd: C.SetPlanner, report) -> None:  # noqa: N802
        from recon_cli.planning.planner import MotionPlanner

        self.plan = replace(self.plan, planner=cmd.name, time_limit=cmd.time, velocity_scale=cmd.velocity_scale,
                            acceleration_scale=cmd.acceleration_scale)
        if self.acquisition is not None:
            self.acquisition.planner = MotionPlanner(self.cell, self.plan)

    def _object_box(self):
        from recon_cli.robot.collision import ObjectBox

        b = self.box_command
        if b is None or b.center is None:
            margin = 0.01 if b is None else b.margin
            return None if self.scene_object is None else self.scene_object.bounding_box(margin)
        center = np.asarray(b.center, dtype=float)
        if b.frame == Frame.MARKER.value:
            center = (self._world_T_marker() @ np.r_[center, 1.0])[:3]
        return ObjectBox(tuple(center), tuple(b.size))

    def _world_T_marker(self) -> np.ndarray:
        from recon_cli.robot.cell import Cell

        cell = self.cell or Cell(self.cell_config)
        return cell.world_T_marker

    # station -----------------------------------------------------------
    def _ensure_station(self) -> None:
        if self.station is not None or (self.options.dry_run and self.cell is not None):
            return
        from recon_cli.acquisition import Acquisition
        from recon_cli.capture import write_ground_truth_mesh
        from recon_cli.objects import available_objects, load_object
        from recon_cli.perception.sensor import motioncam_3d_m
        from recon_cli.robot.cell import Cell
        from recon_cli.robot.poses import named_configuration

        if self.backend == "hardware":
            raise HardwareUnavailable(
                "no hardware adapter is configured on this machine (robot and camera drivers)",
                hint="run with the simulation (backend sim) here; on the cell, install the adapters for "
                     "RobotBackend/CameraBackend (recon_cli/backends/base.py)")
        name = self.object_name
        if name == "auto":
            name = "drill" if "drill" in available_objects() else "bottle"
        self.scene_object = load_object(name, self.object_scale)
        self.cell = Cell(self.cell_config, object_box=self._object_box())
        start = named_configuration(self.cell_config.kind, "home", self.cell.joint_names)
        self.q_planned = start
        if self.options.dry_run:
            return
        from recon_cli.backends.sim.station import SimStation

        sensor = motioncam_3d_m()
        box = self.cell.collision.object_box
        crop_center, crop_size = self.scene_object.crop_box(0.01 if self.box_command is None
                                                              else self.box_command.margin)
        if self.box_command is not None and self.box_command.center is not None:
            crop_center, crop_size = box.center, box.size
        session = {
            "backend": self.backend, "script": self.script.path,
            "cell": {"kind": self.cell_config.kind.value, "safety_distance": self.cell_config.safety_distance},
            "sensor": sensor.name, "noise": self.noise, "seed": self.options.seed,
            "object": {"name": self.scene_object.name, "world_T_object": self.scene_object.world_T_object},
            "object_box": None if box is None else {"frame": "world", "center": list(box.center),
                                                     "size": list(box.size)},
            "crop_box": {"frame": "world", "center": list(crop_center), "size": list(crop_size)},
            "world_T_marker": self.cell.world_T_marker,
        }
        self.store = self._open_store(session)
        write_ground_truth_mesh(self.out / "scans", self.scene_object)
        self.station = SimStation(self.cell, self.scene_object, start, self.rng, noise=self.noise,
                                  resolution=self.resolution)
        self.acquisition = Acquisition(self.cell, self.station.robot, self.station.camera, self.store, self.rng,
                                       self.plan, depth_scale=sensor.depth_scale,
                                       ground_truth=self.station.ground_truth)

    def _open_store(self, session: dict):
        """A new scan store, or (``--append``) the one already in the output folder when it
        was recorded with the same cell, object and backend."""
        from recon_cli.errors import FileError
        from recon_cli.reconstruction.scan_store import ScanStore

        root = self.out / "scans"
        if not (self.options.append and (root / "session.json").exists()):
            return ScanStore.create(root, session)
        store = ScanStore(root)
        old = store.session()
        for key, label in (("backend", "backend"), ("cell", "cell"), ("object", "object")):
            mine, theirs = session.get(key), old.get(key)
            if key == "cell":
                mine, theirs = (mine or {}).get("kind"), (theirs or {}).get("kind")
            elif key == "object":
                mine, theirs = (mine or {}).get("name"), (theirs or {}).get("name")
            if mine != theirs:
                raise FileError(f"--append: the scans in {root} were recorded with {label} {theirs!r}, this run "
                                f"uses {mine!r}", hint="append only runs of the same cell and object, or choose a "
                                                       "new output folder")
        return store

    # motion ------------------------------------------------------------
    def _goal_pose(self, cmd: C.Move) -> np.ndarray:
        if isinstance(cmd, C.MoveView):
            return self.cell.view_pose(cmd.view)
        from scipy.spatial.transform import Rotation

        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(cmd.orientation).as_matrix()
        T[:3, 3] = cmd.position
        return self.cell.world_T_marker @ T if cmd.frame == Frame.MARKER.value else T

    def _move_report(self, report: CommandReport, plan) -> None:
        report.details.update(planner=plan.planner, plan_time_s=plan.total_time,
                              trajectory_s=None if plan.trajectory is None else plan.trajectory.duration)

    def _do_MoveView(self, cmd, report) -> None:  # noqa: N802
        self._move_to_pose(cmd, report)

    def _do_MovePose(self, cmd, report) -> None:  # noqa: N802
        self._move_to_pose(cmd, report)

    def _move_to_pose(self, cmd: C.Move, report: CommandReport) -> None:
        from recon_cli.acquisition import PlanningError
        from recon_cli.planning.planner import MotionPlanner

        self._ensure_station()
        self.move_failed = False
        T = self._goal_pose(cmd)
        if self.options.dry_run:
            plan = MotionPlanner(self.cell, self.plan).plan_to_pose(self.q_planned, T, self.rng)
            if not plan.ok:
                raise PlanningError(f"cannot plan the move: {plan.status.value} ({plan.message})",
                                    hint="try another view or a longer planning time")
            self.q_planned = plan.trajectory.goal
            report.status = "planned"
            self._move_report(report, plan)
            return
        move = self.acquisition.move_to_pose(T, what="view")
        self._last_view = (cmd, T)
        self._move_report(report, move.plan)

    def _do_MoveJoints(self, cmd: C.MoveJoints, report) -> None:  # noqa: N802
        from recon_cli.acquisition import PlanningError
        from recon_cli.planning.planner import MotionPlanner

        self._ensure_station()
        self.move_failed = False
        q = np.asarray(cmd.values, dtype=float)
        if len(q) != self.cell.kin.nq:
            raise ScriptError(f"{cmd.source}: <joints> has {len(q)} values, the {self.cell_config.kind.value} "
                              f"cell has {self.cell.kin.nq} joints", hint="one value per joint, in URDF order")
        if cmd.unit == "deg":
            q = np.where(self.cell.limits.prismatic, q, np.radians(q))
        start = self.q_planned if self.options.dry_run else self.station.robot.measured_joints()
        plan = MotionPlanner(self.cell, self.plan).plan_to_joints(start, q, seed=int(self.rng.integers(1 << 30)))
        if not plan.ok:
            raise PlanningError(f"cannot move to the joint goal: {plan.status.value} ({plan.message})",
                                hint="check the values against the soft joint limits and the collision model")
        self._move_report(report, plan)
        if self.options.dry_run:
            self.q_planned = plan.trajectory.goal
            report.status = "planned"
            return
        self.station.robot.execute(plan.trajectory)
        self._last_view = None

    def _do_MoveHome(self, cmd: C.MoveHome, report) -> None:  # noqa: N802
        from recon_cli.robot.poses import named_configuration

        self._ensure_station()
        home = named_configuration(self.cell_config.kind, "home", self.cell.joint_names)
        self._do_MoveJoints(C.MoveJoints(cmd.source, tuple(home), "rad"), report)

    def _do_Scan(self, cmd: C.Scan, report) -> None:  # noqa: N802
        from recon_cli.acquisition import view_record

        if self.move_failed:
            report.status, report.message = "skipped", "the move before it failed"
            return
        if self._skipped_in_dry_run(report):
            return
        self._ensure_station()
        last = getattr(self, "_last_view", None)
        view = last[0].view if last and isinstance(last[0], C.MoveView) else None
        T = last[1] if last else self.cell.kin.world_T_camera(self.station.robot.measured_joints())
        scan = self.acquisition.scan(view_record(view, T), name=cmd.name)
        report.details.update(scan=scan.index, points=int(np.count_nonzero(scan.depth > 0)))
        self.registered = None  # a new scan invalidates earlier registration results
        if isinstance(cmd, C.FragmentScan):
            self._make_fragment(cmd.name or f"scan_{scan.index:04d}", scan, report)

    def _do_FragmentScan(self, cmd, report) -> None:  # noqa: N802
        self._do_Scan(cmd, report)

    def _do_Wait(self, cmd: C.Wait, report) -> None:  # noqa: N802
        if self.backend == "sim" or self.options.dry_run:
            report.message = "simulation: the robot holds its pose; no wall-clock wait"
        else:  # pragma: no cover - hardware only
            time.sleep(cmd.seconds)

    # reconstruction (all scans) -----------------------------------------
    def _need_scans(self, cmd: C.Command) -> None:
        if self.store is None or len(self.store) == 0:
            raise ReconError(f"{cmd.source}: no scans to work on yet", hint="scan before registering")

    def _register(self, local=True, board=True, loop_closures="icp", mesh=False, surface=None):
        from recon_cli.reconstruction.pipeline import RegisterOptions, run_register

        opts = RegisterOptions(local=local, use_board=board, mesh=mesh, seed=self.options.seed)
        opts = replace(opts, multiway=replace(opts.multiway, loop_closure_init=loop_closures))
        if surface is not None:
            opts = replace(opts, surface=surface)
        self.registered = run_register(self.store.root, self.out / "reconstruction", opts)
        self.reconstruction = {"cloud": self.registered.cloud, "cloud_global": self.registered.cloud_global}
        return self.registered

    def _do_Register(self, cmd: C.Register, report) -> None:  # noqa: N802
        if self._skipped_in_dry_run(report):
            return
        self._need_scans(cmd)
        r = self._register(cmd.local, cmd.board, cmd.loop_closures)
        sources = {k: v for k, v in r.pose_sources.items() if v}
        report.details.update(pose_sources=sources, registered=len(r.used), scans=len(r.scans),
                              seconds_register=r.timings["total_s"])
        self.outputs.update(cloud=str(r.cloud), registration_report=str(r.report))

    def _do_Reconstruct(self, cmd: C.Reconstruct, report) -> None:  # noqa: N802
        from recon_cli.reconstruction.surface import SurfaceOptions, fuse, poisson_mesh, write_cloud, write_mesh

        if self._skipped_in_dry_run(report):
            return
        self._need_scans(cmd)
        surface = SurfaceOptions(voxel=cmd.voxel, poisson_depth=cmd.depth, density_quantile=cmd.trim)
        r = self.registered or self._register(surface=surface)
        fused = fuse(r.clouds, surface)
        folder = self.out / "reconstruction"
        cloud = write_cloud(folder / "cloud.ply", fused, r.out_T_marker)
        mesh, _ = poisson_mesh(fused, surface)
        mesh_path = write_mesh(folder / "mesh.ply", mesh, r.out_T_marker)
        self.reconstruction.update(cloud=cloud, mesh=mesh_path)
        self.outputs.update(cloud=str(cloud), mesh=str(mesh_path))
        report.details.update(points=len(fused.points), triangles=len(mesh.triangles))

    def _out_path(self, name: str, cmd: C.Command, report: CommandReport) -> Path:
        """Where an export goes: inside the output folder after resolving links, else refused.
        An absolute path (thesis dialect only; the loader refuses it in recon's) is written
        into the output folder under its file name, and the report says so."""
        from recon_cli.errors import FileError
        from recon_cli.outputs import inside

        if Path(name).is_absolute():
            report.message = f"absolute path {name} written into the output folder as {Path(name).name}"
            name = Path(name).name
        try:
            target = inside(self.out, name, "export")
        except FileError as exc:
            raise FileError(f"{cmd.source}: {exc.message}", hint=exc.hint) from None
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def _do_Export(self, cmd: C.Export, report) -> None:  # noqa: N802
        if self._skipped_in_dry_run(report):
            return
        for kind, name in (("cloud", cmd.cloud), ("mesh", cmd.mesh)):
            if not name:
                continue
            if kind not in self.reconstruction:
                raise ReconError(f"{cmd.source}: no {kind} to export yet",
                                 hint="put <register/> and <reconstruct/> before <export>")
            from recon_cli.outputs import atomic_write

            source = self.reconstruction[kind]
            target = atomic_write(self._out_path(name, cmd, report), lambda tmp, src=source: shutil.copyfile(src, tmp))
            self.outputs[f"export_{kind}"] = str(target)

    def _do_Evaluate(self, cmd: C.Evaluate, report) -> None:  # noqa: N802
        from recon_cli.reconstruction.assessment import run_evaluate

        if self._skipped_in_dry_run(report):
            return
        if "cloud" not in self.reconstruction:
            raise ReconError(f"{cmd.source}: nothing reconstructed to evaluate yet",
                             hint="put <register/> (and <reconstruct/>) before <evaluate>")
        if cmd.reference == "ground_truth":
            if self.scene_object is None or self.backend != "sim":
                raise ReconError(f"{cmd.source}: ground truth exists only in simulation",
                                 hint="give reference=\"path/to/mesh.ply\"")
            reference = self.out / "scans" / "ground_truth" / f"{self.scene_object.name}.ply"
        else:
            reference = readable_file(self.script, cmd.reference, cmd.source, "reference mesh")
        result = run_evaluate(self.reconstruction["cloud"], reference, cmd.tolerance,
                              self.out / "scans" if self.store else None, cmd.align,
                              out=self.out / "reconstruction")
        e = result.evaluation
        report.details.update(mean_mm=e.mean * 1e3, std_mm=e.std * 1e3, coverage=e.coverage,
                              coverage_visible=e.coverage_visible, tolerance_mm=e.tolerance * 1e3)
        self.outputs.update(evaluation=str(result.report), histogram=str(result.histogram))

    # fragments (thesis dialect) -------------------------------------------
    def _make_fragment(self, name: str, scan, report: CommandReport) -> None:
        from recon_cli.perception.charuco import thesis_board
        from recon_cli.reconstruction.global_registration import global_pose
        from recon_cli.reconstruction.pipeline import RegisterOptions, crop_box_marker, scan_cloud

        if self._fragment_box is None:
            self._fragment_box = crop_box_marker(RegisterOptions(), self.store.session())
        pose = global_pose(scan, thesis_board(), self.cell.world_T_marker)
        self.fragments[name] = scan_cloud(scan, pose, self._fragment_box, RegisterOptions().surface)
        report.details.update(fragment=name, pose_source=pose.source.value,
                              fragment_points=len(self.fragments[name].points))

    def _fragment(self, name: str, cmd: C.Command):
        if name not in self.fragments:
            known = ", ".join(sorted(self.fragments)) or "none yet"
            raise ReconError(f"{cmd.source}: no fragment named {name!r} (known: {known})",
                             hint="scan or load it first")
        return self.fragments[name]

    def _skipped_in_dry_run(self, report: CommandReport) -> bool:
        """A dry run plans moves only: every other command is reported as skipped."""
        if self.options.dry_run:
            report.status, report.message = "skipped", "dry run"
        return self.options.dry_run

    def _icp_options(self, method: str, threshold: float):
        from recon_cli.reconstruction.pose_graph import MultiwayOptions

        m = {"point_to_point_icp": "point_to_point", "point_to_plane_icp": "point_to_plane",
             "colored_point_cloud_registration": "colored"}[method]
        return MultiwayOptions(max_correspondence=threshold, scales=(1.0,), method=m, voxel=max(threshold / 4, 5e-4))

    def _do_PairRegister(self, cmd: C.PairRegister, report) -> None:  # noqa: N802
        from recon_cli.reconstruction.pose_graph import pairwise_icp, prepare

        if self._skipped_in_dry_run(report):
            return
        src, tgt = self._fragment(cmd.source_fragment, cmd), self._fragment(cmd.target, cmd)
        opts = self._icp_options(cmd.method, cmd.threshold)
        result = pairwise_icp(prepare(src, opts.voxel), prepare(tgt, opts.voxel), np.eye(4), opts)
        src.transform(result.transformation)
        report.details.update(fitness=result.fitness, rmse_m=result.inlier_rmse)

    def _do_Multiway(self, cmd: C.Multiway, report) -> None:  # noqa: N802
        from recon_cli.reconstruction.pose_graph import register_multiway

        if self._skipped_in_dry_run(report):
            return
        names = list(self.fragments)
        if len(names) < 2:
            raise ReconError(f"{cmd.source}: multiway registration needs two fragments or more "
                             f"({len(names)} now)", hint="scan more views first")
        opts = replace(self._icp_options(cmd.method, cmd.threshold), scales=(2.0, 1.0))
        result = register_multiway([self.fragments[n] for n in names], opts)
        for n, T in zip(names, result.poses, strict=True):
            self.fragments[n].transform(T)
        report.details.update(fragments=len(names), edges=len(result.edges), pruned=result.pruned)

    def _do_AddFragment(self, cmd: C.AddFragment, report) -> None:  # noqa: N802
        import open3d as o3d

        if self._skipped_in_dry_run(report):
            return
        src = self._fragment(cmd.fragment, cmd)
        target = self.fragments.setdefault(cmd.target, o3d.geometry.PointCloud())
        target += src

    def _do_Downsample(self, cmd: C.Downsample, report) -> None:  # noqa: N802
        if self._skipped_in_dry_run(report):
            return
        frag = self._fragment(cmd.fragment, cmd)
        if cmd.voxel > 0:
            self.fragments[cmd.fragment] = frag.voxel_down_sample(cmd.voxel)
        report.details.update(points=len(self.fragments[cmd.fragment].points))

    def _do_TransformFragment(self, cmd: C.TransformFragment, report) -> None:  # noqa: N802
        if self._skipped_in_dry_run(report):
            return
        self._fragment(cmd.fragment, cmd).transform(np.asarray(cmd.matrix, dtype=float))

    def _do_DeleteFragment(self, cmd: C.DeleteFragment, report) -> None:  # noqa: N802
        if self._skipped_in_dry_run(report):
            return
        self._fragment(cmd.fragment, cmd)
        del self.fragments[cmd.fragment]

    def _do_LoadFragment(self, cmd: C.LoadFragment, report) -> None:  # noqa: N802
        import cv2
        import open3d as o3d

        from recon_cli.errors import FileError
        from recon_cli.perception.sensor import motioncam_3d_m

        if self._skipped_in_dry_run(report):
            return
        if cmd.kind == "point_cloud":
            path = readable_file(self.script, cmd.path_point_cloud, cmd.source, "point cloud")
            cloud = o3d.io.read_point_cloud(str(path)) if path.is_file() else o3d.geometry.PointCloud()
            if len(cloud.points) == 0:
                raise FileError(f"{cmd.source}: {path} is missing or holds no points", hint="check path_point_cloud")
        else:
            color_path = readable_file(self.script, cmd.path_color, cmd.source, "colour image")
            depth_path = readable_file(self.script, cmd.path_depth, cmd.source, "depth image")
            depth = cv2.imread(str(depth_path), cv2.IMREAD_UNCHANGED)
            color = cv2.imread(str(color_path), cv2.IMREAD_COLOR)
            if depth is None or color is None:
                raise FileError(f"{cmd.source}: cannot read {color_path} and {depth_path}",
                                hint="check path_color and path_depth (PNG images)")
            sensor = motioncam_3d_m()
            K = sensor.intrinsics(depth.shape[1] / sensor.width)
            rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
                o3d.geometry.Image(np.ascontiguousarray(cv2.cvtColor(color, cv2.COLOR_BGR2RGB))),
                o3d.geometry.Image(depth.astype(np.float32) / sensor.depth_scale), depth_scale=1.0,
                depth_trunc=3.0, convert_rgb_to_intensity=False)
            cloud = o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, K.to_open3d())
            report.message = "camera frame; intrinsics and depth scale of the MotionCam-3D M model"
        self.fragments[cmd.name] = cloud
        report.details.update(points=len(cloud.points))

    def _do_ExportFragment(self, cmd: C.ExportFragment, report) -> None:  # noqa: N802
        import open3d as o3d

        from recon_cli.reconstruction.surface import SurfaceOptions, poisson_mesh, write_cloud, write_mesh

        if self._skipped_in_dry_run(report):
            return
        frag = self._fragment(cmd.fragment, cmd)
        T = self.cell.world_T_marker if self.store is not None else None  # scans are in the marker frame
        target = self._out_path(cmd.path, cmd, report)
        if cmd.kind == "point_cloud":
            write_cloud(target, frag, T)
        else:
            cloud = o3d.geometry.PointCloud(frag)
            if not cloud.has_normals():
                cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.004, max_nn=30))
                cloud.orient_normals_consistent_tangent_plane(20)
            mesh, _ = poisson_mesh(cloud, SurfaceOptions())
            write_mesh(target, mesh, T)
        self.outputs[f"export_{cmd.fragment}_{cmd.kind}"] = str(target)

    def _do_Display(self, cmd: C.Display, report) -> None:  # noqa: N802
        report.status = "recorded"
