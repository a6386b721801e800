"""<cell>, <object>, <box>, <planner>: the set-up of a run (before the first move)."""

from __future__ import annotations

from dataclasses import replace

from recon_cli.config import SceneConfig, SensorConfig
from recon_cli.objects import load_object
from recon_cli.planning.planner import MotionPlanner
from recon_cli.realism import load_profile
from recon_cli.robot.description import CellConfig, CellName
from recon_cli.scripts import commands as C
from recon_cli.scripts.checks import is_file_name, readable_file, script_cell, script_realism
from recon_cli.scripts.handlers import handles
from recon_cli.scripts.state import CommandReport, RunState
from recon_cli.session import Backend


@handles(C.SetCell)
def set_cell(state: RunState, cmd: C.SetCell, report: CommandReport) -> None:

    realism = state.options.realism or load_profile(script_realism(state.script, cmd))
    # --cell runs the script on another cell, with that cell's own safety distance
    if state.options.cell is not None:
        cell = CellConfig(kind=CellName.parse(state.options.cell))
    elif cmd.safety_distance is None:
        cell = CellConfig(kind=CellName.parse(script_cell(state.script, cmd)))
    else:
        cell = CellConfig(kind=CellName.parse(script_cell(state.script, cmd)), safety_distance=cmd.safety_distance)
    state.set_config(cell=cell,
                     sensor=SensorConfig(noise=cmd.noise, resolution=cmd.resolution), realism=realism)
    state.backend = state.options.backend or Backend(cmd.backend)


@handles(C.SetObject)
def set_object(state: RunState, cmd: C.SetObject, report: CommandReport) -> None:

    if state.options.object_name is not None:
        return
    name = cmd.name
    if is_file_name(name):
        name = str(readable_file(state.script, name, cmd.source, "object mesh"))
    if name != "auto":
        load_object(name, cmd.scale)  # fails now, with the line, if it cannot be loaded
    state.set_config(scene=replace(state.config.scene, object_name=name, object_scale=cmd.scale))


@handles(C.SetBox)
def set_box(state: RunState, cmd: C.SetBox, report: CommandReport) -> None:
    state.box_command = cmd
    state.set_config(scene=SceneConfig(state.config.scene.object_name, state.config.scene.object_scale, cmd.margin))
    if state.cell is not None:
        state.cell.collision.set_object_box(state.object_box())


@handles(C.SetPlanner)
def set_planner(state: RunState, cmd: C.SetPlanner, report: CommandReport) -> None:

    state.set_config(planner=replace(state.config.planner, planner=cmd.name, time_limit=cmd.time,
                                     velocity_scale=cmd.velocity_scale, acceleration_scale=cmd.acceleration_scale))
    if state.acquisition is not None:
        state.acquisition.planner = MotionPlanner(state.cell, state.config.planner)
