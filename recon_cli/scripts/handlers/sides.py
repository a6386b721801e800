"""<turn_over/>: the object turned over between the two sides of a script, and the sides
merged at the end of the run.

At the turn the robot parks at its home posture and the station is released; side 1's model
is its last registration after its last scan (else the scans are registered as ``<register/>``
would); then the object is turned over (recon_cli/both_sides.py: by physics in simulation,
by the operator on a real cell) and the next command that needs the robot opens side 2's
session on the turned object. At the end of the run (:class:`~recon_cli.scripts.commands.MergeSides`)
side 2's model is made the same way, the sides are registered by shape and merged.
"""

from __future__ import annotations

import time

from recon_cli.both_sides import SideModel, any_way_up_box, confidence_line, merge_sides, turn_object, turn_rng
from recon_cli.errors import ReconError
from recon_cli.recording.results import record_sides
from recon_cli.scripts import commands as C
from recon_cli.scripts.handlers import handles
from recon_cli.scripts.handlers.motion import move_home
from recon_cli.scripts.handlers.reconstruction import register_scans
from recon_cli.scripts.state import CommandReport, RunState, Turned


def _side_model(state: RunState, started: float, where: C.Source) -> SideModel:
    """The model of the side being scanned: its last registration after its last scan, else
    its scans registered as ``<register/>`` would."""
    scans = 0 if state.store is None else len(state.store)
    if scans == 0:
        raise ReconError(f"{where}: side {state.side} has no scans (their moves failed): nothing to merge",
                         hint="see the failed moves in run_report.json; choose views the robot reaches")
    if state.registered is None:
        register_scans(state)
    return SideModel(state.registered.cloud, scans, time.perf_counter() - started)


@handles(C.TurnOver)
def turn_over(state: RunState, cmd: C.TurnOver, report: CommandReport) -> None:
    session = state.ensure_session()
    move_home(state, C.MoveHome(cmd.source), report)  # clear of the table: someone (or something) reaches in
    if state.dry_run:
        report.message = "dry run: the robot parks at its home posture; the object is not turned over"
        return
    first, caps = session.scene_object, session.capabilities
    assert first is not None and caps is not None  # an open session of a script has both
    session.close()  # the robot stopped and the station released while the object is turned
    side_1 = _side_model(state, state.started, cmd.source)
    turn = turn_object(first, caps.simulated, turn_rng(state.config.seed if cmd.seed is None else cmd.seed),
                       state.options.ask, side_1.cloud)
    box = None
    if turn.scene_object is None:  # a real cell: nobody measured how it lies
        box = any_way_up_box(side_1.cloud, state.config.scene.box_margin)
    state.begin_side_2(Turned(cmd, side_1, first, turn, box, time.perf_counter()))
    if state.recorder is not None:  # side 2's scans are numbered from 0 again: a group of their own
        state.recorder.begin_group("side_2")
    report.details.update(turn=turn.record, side_1_scans=side_1.scans)


@handles(C.MergeSides)
def merge(state: RunState, cmd: C.MergeSides, report: CommandReport) -> None:
    if state.skipped_in_dry_run(report):
        return
    turned = state.turned
    assert turned is not None  # the runner adds this command after a turn only
    side_2 = _side_model(state, turned.started, cmd.source)
    merged = state.merged = merge_sides(state.out, (turned.side_1, side_2), turned.first, turned.turn.scene_object,
                                        turned.turn.record, state.config.registration.surface, state.config.seed,
                                        state.started)
    reg = merged.registration
    if state.recorder is not None:  # the sides as registered onto each other
        record_sides(state.recorder, (turned.side_1.cloud, side_2.cloud), reg.side1_T_side2, confidence_line(reg))
    report.details.update(fitness=reg.fitness, fitness_reverse=reg.fitness_reverse, rmse_m=reg.rmse,
                          overlap=reg.overlap, ambiguous=reg.ambiguous, shape_ambiguous=reg.shape_ambiguous,
                          side_scans=[turned.side_1.scans, side_2.scans])
    if merged.truth is not None:
        report.details["truth"] = merged.truth
    if merged.coverage is not None:
        report.details["coverage_whole"] = merged.coverage
    state.outputs["sides_report"] = str(merged.report)
    if merged.cloud is not None:
        state.outputs["cloud"] = str(merged.cloud)
    if merged.mesh is not None:
        state.outputs["mesh"] = str(merged.mesh)
    if merged.error is not None:
        raise merged.error
