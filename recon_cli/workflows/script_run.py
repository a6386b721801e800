"""``recon run``: an automation script's commands in order (the script manager, thesis 3.4).

The loop owns the policy (on_failure skip or abort), the reports, sequence optimization of
movable groups, and interruptions; each command is done by its handler
(:mod:`recon_cli.scripts.handlers`) on the typed run state (:mod:`recon_cli.scripts.state`).
A move that fails (unreachable view, no path) is reported and either skips the scans that
belong to it (``on_failure="skip"``) or stops the run (``"abort"``); scans already written
stay. Ctrl-C or SIGTERM stops the robot, keeps every completed scan, and the report says
which command was interrupted. A dry run plans every move from the previous planned
configuration but moves nothing and scans nothing. A script that turns the object over
(``<turn_over/>``) ends with the two sides registered by shape and merged (the command
:class:`~recon_cli.scripts.commands.MergeSides`, reported at the turn's line).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from recon_cli.both_sides import MergedSides
from recon_cli.errors import ReconError, RobotFault, RunInterrupted, ScriptAborted
from recon_cli.interrupts import exit_code, signal_name
from recon_cli.outputs import atomic_write_text, keep_earlier, refuse_links
from recon_cli.recording import open_recorder
from recon_cli.report import write_page_after_run
from recon_cli.runs import script_run as run_file
from recon_cli.runs.codec import from_json, plain
from recon_cli.runs.script_run import RUN_REPORT, Interruption
from recon_cli.scripts import commands as C
from recon_cli.scripts.checks import ACTIONS, check_script
from recon_cli.scripts.handlers import handler_for
from recon_cli.scripts.handlers.motion import execute_planned
from recon_cli.scripts.optimize import movable_groups, plan_tour, units
from recon_cli.scripts.state import (
    EXIT_ABORTED,
    EXIT_DONE,
    EXIT_FAILED,
    CommandReport,
    CommandStatus,
    OnFailure,
    RunOptions,
    RunState,
    RunStatus,
    SequenceReport,
)
from recon_cli.session import Backend

if TYPE_CHECKING:
    from recon_cli.planning.trajectory import Trajectory

Progress = Callable[[str, int, int], None]


@dataclass
class RunResult:
    out: Path
    script: C.Script
    reports: list[CommandReport]
    scans: int
    seconds: float
    outputs: dict[str, str]
    aborted: str = ""
    sequences: list[SequenceReport] = field(default_factory=list)
    page: Path | None = None  # report.html (None: not written)
    sides: MergedSides | None = None  # the two sides merged (a script that turned the object over)

    @property
    def failed(self) -> list[CommandReport]:
        return [r for r in self.reports if r.status is CommandStatus.FAILED]

    @property
    def exit_code(self) -> int:
        """0 when every command did its work, 3 when some failed (or were skipped for it)."""
        return EXIT_FAILED if self.failed else EXIT_DONE


class ScriptRunner:
    def __init__(self, script: C.Script, options: RunOptions, progress: Progress | None = None) -> None:
        check_script(script, object_override=options.object_name, cell_override=options.cell, append=options.append)
        self.script = script
        self.options = options
        self.progress = progress or (lambda *a: None)
        base = options.config
        scene = base.scene if options.object_name is None else replace(base.scene, object_name=options.object_name)
        config = base.replace(scene=scene, realism=options.realism or base.realism)
        self.state = RunState(script, options, config, np.random.default_rng(config.seed),
                              backend=options.backend or Backend.SIM)
        self.on_failure = OnFailure(script.on_failure)
        self.reports: list[CommandReport] = []
        self.current: C.Command | None = None  # the command in progress (for interruptions)
        self.page: Path | None = None  # the run's report page, once written
        optimize = script.optimize if options.optimize is None else options.optimize
        self.groups = movable_groups(script.commands) if optimize else {}

    @property
    def out(self) -> Path:
        return self.state.out

    # ------------------------------------------------------------------ run
    def run(self) -> RunResult:

        t0 = self.state.started = time.perf_counter()
        self.state.check_station()  # before anything moves or is written
        self.out.mkdir(parents=True, exist_ok=True)
        if self.options.append:
            refuse_links(self.out)
            self._keep_earlier(RUN_REPORT, "script.expanded.xml", "config.yaml", "recording.rrd")
        atomic_write_text(self.out / "script.expanded.xml", self.script.expanded_xml)
        if self.options.record and not self.options.dry_run:

            self.state.recorder = open_recorder(self.out, f"recon run {self.script.name}")
        aborted, interrupted = "", None
        commands = self.script.commands
        n = len(commands)
        try:
            k = 0
            while k < n:
                if k in self.groups:
                    end = self.groups[k]
                    self._run_group(commands[k:end])
                    k = end
                else:
                    self._run_command(commands[k])
                    k += 1
                self.progress("script", k, n)
            if self.state.turned is not None:  # the two sides merged into one model
                self._run_command(C.MergeSides(self.state.turned.command.source))
        except ScriptAborted as exc:
            aborted = str(exc)
            raise
        except KeyboardInterrupt as exc:
            interrupted = self._interruption(signal_name(exc))
            aborted = interrupted.reason
        finally:
            self.state.close()  # stops the robot first
            self._write_report(time.perf_counter() - t0, aborted, interrupted)
            self._write_page()
        if interrupted is not None:
            scans = self.state.side_out / "scans"
            where = f"{self.out / 'side_1' / 'scans'} and {scans}" if self.state.turned is not None else str(scans)
            raise RunInterrupted(f"{interrupted.reason}; {interrupted.scans_kept} completed scan(s) kept in {where}",
                                 signal=interrupted.signal, scans_kept=interrupted.scans_kept,
                                 hint=f"run_report.json records it; recon register {scans} works on the kept scans")
        return RunResult(self.out, self.script, self.reports, self.state.scan_count(), time.perf_counter() - t0,
                         dict(self.state.outputs), aborted, list(self.state.sequences), self.page, self.state.merged)

    def _keep_earlier(self, *names: str) -> None:
        """--append: an earlier run's report, script and configuration stay, as NAME-1, NAME-2, ..."""

        keep_earlier(self.out, *names)

    def _interruption(self, signal: str) -> Interruption:
        cmd = self.current
        where = "between commands" if cmd is None else f"during {cmd.source} ({cmd.describe()})"
        return Interruption(signal, f"interrupted by {signal} {where}", None if cmd is None else str(cmd.source),
                            self.state.scan_count())

    def _run_command(self, cmd: C.Command, planned: Trajectory | Literal[False] | None = None, note: str = "") -> None:
        report = CommandReport(str(cmd.source), cmd.describe(), message=note)
        t = time.perf_counter()
        self.current = cmd
        try:
            if planned is None:
                handler_for(cmd)(self.state, cmd, report)
            else:
                assert isinstance(cmd, C.Move)  # a planned trajectory belongs to a move of an optimized sequence
                execute_planned(self.state, cmd, planned, report)
        except KeyboardInterrupt:
            report.status = CommandStatus.INTERRUPTED
            report.message = "stopped by a signal; the robot was commanded to stop"
            report.seconds = time.perf_counter() - t
            self.reports.append(report)
            raise
        except ReconError as exc:
            report.status, report.message = CommandStatus.FAILED, exc.one_line()
            if isinstance(cmd, ACTIONS) and not isinstance(cmd, C.Scan):
                self.state.move_failed = True
            if self.on_failure is OnFailure.ABORT or isinstance(exc, RobotFault) or isinstance(cmd, C.TurnOver):
                report.seconds = time.perf_counter() - t
                self.reports.append(report)
                why = ("a robot fault ends the run" if isinstance(exc, RobotFault)
                       else "a failed turn ends the run (what follows would not scan side 2)"
                       if isinstance(cmd, C.TurnOver) else "the script says on_failure=\"abort\"")
                raise ScriptAborted(f"{cmd.source}: {exc.one_line()}", source=str(cmd.source),
                                    hint=f"{why}; earlier scans are kept") from None
        report.seconds = time.perf_counter() - t
        self.reports.append(report)
        self.current = None

    # ------------------------------------------------------------------ sequence optimization
    def _run_group(self, commands: tuple[C.Command, ...]) -> None:
        """Moves with their scans, reordered by the sequence optimizer (thesis 2.3); the
        planned paths are executed as planned."""
        tour = plan_tour(self.state, units(commands))
        for move, scans, exc in tour.failed:
            self._fail_unit(move, scans, exc)
        if tour.report is not None:
            self.state.sequences.append(tour.report)
        prev = 0
        for position, step in enumerate(tour.steps, start=1):
            note = f"sequence position {position} of {len(tour.steps)}"
            self._run_command(step.move, planned=tour.trajectory(prev, step.vertex), note=note)
            for scan in step.scans:
                self._run_command(scan)
            prev = step.vertex if not self.state.move_failed else prev

    def _fail_unit(self, move: C.Command, scans: list[C.Command], exc: ReconError) -> None:
        self.reports.append(CommandReport(str(move.source), move.describe(), CommandStatus.FAILED,
                                          message=exc.one_line()))
        for scan in scans:
            self.reports.append(CommandReport(str(scan.source), scan.describe(), CommandStatus.SKIPPED,
                                              message="the move before it failed"))
        if self.on_failure is OnFailure.ABORT:
            raise ScriptAborted(f"{move.source}: {exc.one_line()}", source=str(move.source),
                                hint="the script says on_failure=\"abort\"; earlier scans are kept")

    # ------------------------------------------------------------------ report
    def _write_page(self) -> None:
        """The run's page, however the run ended (with what it wrote)."""
        if self.options.page:

            page = write_page_after_run(self.out)
            self.page = None if page is None else page.path

    def _write_report(self, seconds: float, aborted: str, interrupted: Interruption | None) -> None:

        failed = any(r.status is CommandStatus.FAILED for r in self.reports)
        if interrupted is not None:
            status, code = RunStatus.INTERRUPTED, exit_code(interrupted.signal)
        elif aborted:
            status, code = RunStatus.ABORTED, EXIT_ABORTED
        else:
            status, code = (RunStatus.FAILED, EXIT_FAILED) if failed else (RunStatus.DONE, EXIT_DONE)
        run_file.write(self.out, run_file.ScriptRunReport(
            script=self.script.path, name=self.script.name, dialect=self.script.dialect,
            on_failure=self.on_failure.value, dry_run=self.options.dry_run, backend=self.state.backend.value,
            seed=self.state.config.seed, seconds=seconds, scans=self.state.scan_count(), status=status.value,
            exit_code=code, aborted=aborted or None, interrupted=interrupted, append=self.options.append,
            outputs=dict(self.state.outputs),
            sequence_optimization=tuple(from_json(run_file.SequenceOptimization, plain(s.to_dict()))
                                        for s in self.state.sequences),
            commands=tuple(from_json(run_file.Command, plain(r.to_dict())) for r in self.reports)))
