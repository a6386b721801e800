"""The typed state of a script run, its options, command reports and outcomes.

The run loop (:mod:`recon_cli.workflows.script_run`) owns a :class:`RunState`; command
handlers (:mod:`recon_cli.scripts.handlers`) read and change it. Everything a run writes
goes into ``RunState.out``::

    <out>/scans/                 the scan store (one atomic folder per scan)
    <out>/reconstruction/        registration and surface results (cloud, mesh, report)
    <out>/script.expanded.xml    the script after xacro
    <out>/config.yaml            the effective configuration
    <out>/run_report.json        every command: where it was written, status, time, message
    <out>/report.html            the run's page (recon_cli.report), pictures in report_files/

A script that turns the object over (``<turn_over/>``) keeps each side's scans and results
apart, ``<out>/side_1/`` and ``<out>/side_2/`` (each with ``scans/`` and ``reconstruction/``),
and writes the merged model into ``<out>/reconstruction/`` with ``<out>/sides_report.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.backends.base import Capabilities
from recon_cli.backends.hardware.station import preflight
from recon_cli.backends.station_file import load_station
from recon_cli.both_sides import Ask, MergedSides, SideModel, Turn
from recon_cli.config import DEFAULTS, Config
from recon_cli.errors import FileError
from recon_cli.geometry.view import Frame
from recon_cli.objects import SceneObject
from recon_cli.outputs import inside
from recon_cli.realism import RealismProfile
from recon_cli.reconstruction.pipeline import CloudMemo
from recon_cli.robot.cell import Cell
from recon_cli.robot.collision import ObjectBox
from recon_cli.scripts import commands as C
from recon_cli.session import Backend, Mode, Session, SessionSpec, open_session

#: exit codes of ``recon run`` (README, "Exit codes")
EXIT_DONE, EXIT_ERROR, EXIT_USAGE, EXIT_FAILED, EXIT_ABORTED = 0, 1, 2, 3, 4


class OnFailure(StrEnum):
    SKIP = "skip"  # report, skip the scans of a failed move, go on
    ABORT = "abort"  # stop the run at the first failed command


class SequenceMethod(StrEnum):
    OURS = "ours"  # local search over the view graph
    THESIS = "thesis"  # lazy minimum-spanning-tree tour (Tables 2.2/2.3)


class CommandStatus(StrEnum):
    DONE = "done"
    FAILED = "failed"
    SKIPPED = "skipped"
    PLANNED = "planned"  # dry run: the move was planned, not executed
    RECORDED = "recorded"  # display instructions of the thesis' GUI
    INTERRUPTED = "interrupted"


class RunStatus(StrEnum):
    DONE = "done"
    FAILED = "failed"  # finished, some commands failed
    ABORTED = "aborted"  # stopped by a failed command (on_failure="abort")
    INTERRUPTED = "interrupted"  # stopped by a signal


@dataclass(frozen=True)
class RunOptions:
    out: Path
    backend: Backend | None = None  # overrides the script's <cell backend=...>
    config: Config = DEFAULTS  # what the script's elements start from (its seed is the run's)
    dry_run: bool = False
    object_name: str | None = None  # simulated object (overrides the script's <object>)
    optimize: bool | None = None  # sequence optimization (None: as the script says)
    sequence_method: SequenceMethod = SequenceMethod.OURS
    append: bool = False  # add scans to the scan store already in ``out``
    station: Path | None = None  # a station file: robot and camera adapters (and the cell)
    realism: RealismProfile | None = None  # overrides the script's <cell realism=...>
    cell: str | None = None  # a shipped cell's name or a cell file: overrides the script's <cell kind=...>
    record: bool = False  # write a 3D recording of the run (recording.rrd in ``out``)
    page: bool = True  # write the run's report page (report.html) at its end
    run: dict = field(default_factory=dict)  # what config.yaml's run: section records to repeat the run
    ask: Ask | None = None  # asks the operator to turn the object over on a real cell (None: in the terminal)


@dataclass
class CommandReport:
    source: str
    command: str
    status: CommandStatus = CommandStatus.DONE
    seconds: float = 0.0
    message: str = ""
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"source": self.source, "command": self.command, "status": self.status.value,
                "seconds": round(self.seconds, 4), "message": self.message, **self.details}


@dataclass(frozen=True)
class SequenceReport:
    """One run of moves reordered by the sequence optimizer."""

    moves: int
    method: SequenceMethod
    ik_draws: int
    order: list[str]
    planned_duration_s: float
    planning_requests: int
    script_order_lower_bound_s: float
    seconds: float

    def to_dict(self) -> dict:
        return {"moves": self.moves, "method": self.method.value, "ik_draws": self.ik_draws, "order": self.order,
                "planned_duration_s": self.planned_duration_s, "planning_requests": self.planning_requests,
                "script_order_lower_bound_s": self.script_order_lower_bound_s, "seconds": self.seconds}


@dataclass(frozen=True)
class Turned:
    """A run after its ``<turn_over/>``: side 1's model, how the object was turned, side 2's set-up."""

    command: C.TurnOver
    side_1: SideModel
    first: SceneObject  # the object as side 1 saw it
    turn: Turn  # its scene_object: where the object lies now (simulation; None: turned by the operator)
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None  # side 2's box on a real cell
    started: float  # time.perf_counter() when side 2 began [s]


@dataclass
class RunState:
    """What a run knows at the current command."""

    script: C.Script
    options: RunOptions
    config: Config
    rng: np.random.Generator
    backend: Backend = Backend.SIM  # the script's (or --backend), then the session's
    box_command: C.SetBox | None = None
    session: Session | None = None
    cell: Any = None  # robot.cell.Cell, once the session (or a dry run's cell) is open
    q_planned: np.ndarray | None = None  # dry run: where the previous planned move ended
    last_view: tuple[C.Command, np.ndarray] | None = None  # the move the next scan belongs to, its goal pose
    move_failed: bool = False
    registered: Any = None  # reconstruction.pipeline.RegisterResult of the current scans
    memo: CloudMemo = field(default_factory=CloudMemo)  # the current store's scans, made at scan time
    reconstruction: dict[str, Path] = field(default_factory=dict)
    fragments: dict[str, Any] = field(default_factory=dict)  # thesis dialect: name -> Open3D cloud
    fragment_box: Any = None  # crop box of fragments (marker frame)
    outputs: dict[str, str] = field(default_factory=dict)
    sequences: list[SequenceReport] = field(default_factory=list)
    recorder: Any = None  # recording.recorder.Recorder of a recorded run
    station_checked: bool = False  # the station file passed the check of `recon station check`
    started: float = 0.0  # time.perf_counter() when the run began [s]
    turned: Turned | None = None  # after the <turn_over/>: side 2 is being scanned
    merged: MergedSides | None = None  # the sides merged at the end of the run
    two_sided: bool = field(init=False)  # the script turns the object over

    def __post_init__(self) -> None:
        self.two_sided = any(isinstance(c, C.TurnOver) for c in self.script.commands)

    @property
    def out(self) -> Path:
        return Path(self.options.out)

    @property
    def side(self) -> int:
        """The side being scanned (2 after the ``<turn_over/>``)."""
        return 1 if self.turned is None else 2

    @property
    def side_out(self) -> Path:
        """Where the scans and results of the side being scanned go: the run folder, or its
        ``side_1/`` or ``side_2/`` when the script turns the object over."""
        return self.out / f"side_{self.side}" if self.two_sided else self.out

    @property
    def dry_run(self) -> bool:
        return self.options.dry_run

    @property
    def station(self):
        return None if self.session is None else self.session.station

    @property
    def store(self):
        return None if self.session is None else self.session.store

    @property
    def acquisition(self):
        return None if self.session is None else self.session.acquisition

    @property
    def scene_object(self):
        return None if self.session is None else self.session.scene_object

    @property
    def capabilities(self) -> Capabilities | None:
        """The station's (None before the session is open, and in a dry run)."""
        return None if self.session is None else self.session.capabilities

    def scan_count(self) -> int:
        """Completed scans of the run (of both sides)."""
        earlier = 0 if self.turned is None else self.turned.side_1.scans
        return earlier + (0 if self.store is None else len(self.store))

    def begin_side_2(self, turned: Turned) -> None:
        """After the turn: the next command that needs the robot opens side 2's session (the
        turned object, its own scan store); side 1's results are not side 2's."""
        self.turned = turned
        self.session = None
        self.registered = None
        self.memo = CloudMemo()  # side 2's store names its scans anew
        self.reconstruction = {}
        self.last_view = None
        self.move_failed = False

    # ------------------------------------------------------------------ session
    def ensure_session(self) -> Session:
        """Open the session at the first command that needs the cell or the robot (a dry
        run opens the cell only); the open session."""
        if self.session is not None:
            return self.session
        turned = self.turned
        spec = SessionSpec(self.side_out / "scans", self.config, Mode.SCRIPT, self.backend,
                           box=self._explicit_box() or (None if turned is None else turned.box),
                           script=self.script.path, append=self.options.append, run_folder=self.out,
                           run={"command": "run", "dialect": self.script.dialect, **self.options.run},
                           station=self.options.station, recorder=None if self.dry_run else self.recorder,
                           station_checked=self.station_checked,
                           scene_object=None if turned is None else turned.turn.scene_object)
        self.session = open_session(spec, self.rng, plan_only=self.dry_run)
        self.backend = self.session.spec.backend  # a station file's adapters decide
        self.cell = self.session.cell
        self.q_planned = self.session.start
        return self.session

    def planned_start(self) -> np.ndarray:
        """Dry run: where the previous planned move ended (the session's start before any)."""
        if self.q_planned is None:
            raise RuntimeError("no session is open (ensure_session opens it)")
        return self.q_planned

    def check_station(self) -> None:
        """The check of ``recon station check`` on the station file, before the first command:
        a station that fails it ends the run with one line before anything moves (a dry run
        moves nothing and opens no station)."""
        if self.options.station is None or self.dry_run:
            return

        preflight(load_station(self.options.station), self.config.seed)
        self.station_checked = True

    def _explicit_box(self):
        """The <box> with centre and size, in the world frame (None: the object's own box)."""
        b = self.box_command
        if b is None or b.center is None:
            return None
        center = np.asarray(b.center, dtype=float)
        if b.frame == Frame.MARKER.value:
            center = (self.world_T_marker() @ np.r_[center, 1.0])[:3]
        return tuple(center), tuple(b.size)

    def object_box(self):
        """The collision box of the object: the <box>, or the object's box grown by its margin."""

        explicit = self._explicit_box()
        if explicit is not None:
            return ObjectBox(*explicit)
        return None if self.scene_object is None else self.scene_object.bounding_box(self.config.scene.box_margin)

    def world_T_marker(self) -> np.ndarray:

        return (self.cell or Cell(self.config.cell)).world_T_marker

    def set_config(self, **sections) -> None:
        self.config = replace(self.config, **sections)

    # ------------------------------------------------------------------ helpers of handlers
    def goal_pose(self, cmd: C.Move) -> np.ndarray:
        if isinstance(cmd, C.MoveView):
            return self.cell.view_pose(cmd.view)
        if not isinstance(cmd, C.MovePose):
            raise TypeError(f"{type(cmd).__name__} has no goal pose")
        from scipy.spatial.transform import Rotation

        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(cmd.orientation).as_matrix()
        T[:3, 3] = cmd.position
        return self.cell.world_T_marker @ T if cmd.frame == Frame.MARKER.value else T

    def skipped_in_dry_run(self, report: CommandReport) -> bool:
        """A dry run plans moves only: every other command is reported as skipped."""
        if self.dry_run:
            report.status, report.message = CommandStatus.SKIPPED, "dry run"
        return self.dry_run

    def out_path(self, name: str, cmd: C.Command, report: CommandReport) -> Path:
        """Where an export goes: inside the output folder after resolving links, else refused.
        An absolute path (thesis dialect only; the loader refuses it in recon's) is written
        into the output folder under its file name, and the report says so."""

        if Path(name).is_absolute():
            report.message = f"absolute path {name} written into the output folder as {Path(name).name}"
            name = Path(name).name
        try:
            target = inside(self.out, name, "export")
        except FileError as exc:
            raise FileError(f"{cmd.source}: {exc.message}", hint=exc.hint) from None
        target.parent.mkdir(parents=True, exist_ok=True)
        return target

    def close(self) -> None:
        """Stop the robot and free the station, then finish the recording."""
        try:
            if self.session is not None:
                self.session.close()
        finally:
            if self.recorder is not None:
                self.recorder.close()
