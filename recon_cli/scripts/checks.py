"""Static checks of a loaded script: everything that can be known wrong before anything moves.

Shared by ``recon validate`` and ``recon run`` (which checks before it opens the station):

* the cell and the object are chosen before the first move or scan;
* joint goals have one value per joint of the chosen cell and lie within its soft limits;
* scan and fragment names are unique; registration, reconstruction, exports and
  evaluation come after a scan of their side (and exports/evaluation after what they need);
* at most one ``<turn_over/>``, with scans before and after it (not with ``--append``);
* fragments are defined (scanned, loaded or added) before they are used;
* files a script reads (realism profiles, object meshes, reference meshes, loaded images
  and clouds) lie inside the script's folder or scripts_xml/ and exist (the rule of
  :func:`recon_cli.expansion.readable.readable`, which the commands apply again when they run);
  a realism profile file also parses.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.backends.base import Backend
from recon_cli.errors import HardwareUnavailable, JointLimitError, ReconError, ScriptError
from recon_cli.expansion.readable import readable, readable_roots
from recon_cli.objects import BUILTIN, available_objects, ycb_names
from recon_cli.paths import CELLS_DIR, ROBOT_DIR
from recon_cli.realism import BUILT_IN, load_profile
from recon_cli.robot.cell_file import DEFAULT_CELL, load_cell
from recon_cli.robot.description import CellConfig, CellName, expand_urdf
from recon_cli.robot.limits import limits_from_urdf
from recon_cli.scripts import commands as C

if TYPE_CHECKING:
    from recon_cli.robot.limits import JointLimits

SETUP = (C.SetCell, C.SetObject)
ACTIONS = (C.Move, C.MoveJoints, C.MoveHome, C.Scan)
_TAGS = {"SetCell": "cell", "SetObject": "object", "Register": "register", "Reconstruct": "reconstruct",
         "Export": "export", "Evaluate": "evaluate", "Multiway": "multiway"}


def tag(cmd: C.Command) -> str:
    return _TAGS.get(cmd.keyword, cmd.keyword)


def readable_file(script: C.Script, name: str, src: C.Source, what: str) -> Path:
    """A file a script reads, by the rule of :func:`recon_cli.expansion.readable.readable`:
    a relative path beside the script (or in scripts_xml/) that stays inside those folders
    after resolving links."""
    return readable(name, Path(script.path).resolve().parent, src, what)


def script_realism(script: C.Script, cmd: C.SetCell) -> str | Path:
    """The realism profile of a ``<cell>``: a built-in name, or the profile file it names
    (a readable file, see :func:`readable_file`)."""

    if cmd.realism in BUILT_IN:
        return cmd.realism
    if not is_file_name(cmd.realism):
        raise ScriptError(f"{cmd.source}: unknown realism profile {cmd.realism!r}",
                          hint=f"choose one of: {', '.join(BUILT_IN)}, or a profile FILE.yaml beside the script",
                          source=str(cmd.source))
    return readable_file(script, cmd.realism, cmd.source, "realism profile")


def script_cell(script: C.Script, cmd: C.SetCell) -> str:
    """The cell of a ``<cell kind=...>``: a shipped cell's name, or the real path of a cell file
    the script may read (:func:`readable_file`) whose every file, xacro includes and loads
    too, lies inside the script's folder, scripts_xml/ or recon's shipped cells and robot
    descriptions: a script reads nothing else."""
    if not is_file_name(cmd.kind):
        return cmd.kind
    path = readable_file(script, cmd.kind, cmd.source, "cell file")
    roots = (*readable_roots(Path(script.path).resolve().parent), CELLS_DIR.resolve(), ROBOT_DIR.resolve())
    try:
        cell = load_cell(str(path))
        files = list(cell.sources)
        expand_urdf(CellConfig(kind=CellName(str(path))))  # the description, its includes and meshes
    except ScriptError:
        raise
    except ReconError as exc:
        raise ScriptError(f"{cmd.source}: {exc.message}", hint=exc.hint, source=str(cmd.source)) from None
    for name in files:
        if not any(Path(name).resolve().is_relative_to(r) for r in roots):
            raise ScriptError(f"{cmd.source}: the cell file {cmd.kind} names {name}, outside the script's folder, "
                              "scripts_xml/ and recon's shipped cells", source=str(cmd.source),
                              hint="keep the cell file and the files it names beside the script, or run the "
                                   "script with recon run --cell FILE")
    return str(path)


def _check_realism(script: C.Script, cmd: C.SetCell) -> None:

    try:
        load_profile(script_realism(script, cmd))
    except ScriptError:
        raise
    except ReconError as exc:
        raise ScriptError(f"{cmd.source}: {exc.message}", hint=exc.hint, source=str(cmd.source)) from None


def is_file_name(name: str) -> bool:
    """An object name that names a mesh file (not a built-in or YCB object)."""
    return any(ch in name for ch in "/\\") or bool(Path(name).suffix)


@functools.lru_cache(maxsize=4)
def _joint_limits(kind: str) -> JointLimits:

    config = CellConfig(kind=CellName.parse(kind))
    urdf = expand_urdf(config)
    return limits_from_urdf(urdf, config.cell_file.planning_joints, config.cell_file.limits)


def _check_joints(cmd: C.MoveJoints, kind: str) -> None:
    lim = _joint_limits(kind)
    q = np.asarray(cmd.values, dtype=float)
    if len(q) != lim.n:
        raise ScriptError(f"{cmd.source}: <joints> has {len(q)} values, the {kind} cell has {lim.n} joints "
                          f"({', '.join(lim.names)})", hint="one value per joint, in this order")
    if cmd.unit == "deg":
        q = np.where(lim.prismatic, q, np.radians(q))
    for k, name in enumerate(lim.names):
        if not lim.soft_lower[k] - 1e-9 <= q[k] <= lim.soft_upper[k] + 1e-9:
            unit, f = ("m", 1.0) if lim.prismatic[k] else (cmd.unit, 1.0 if cmd.unit == "rad" else 180 / math.pi)
            raise JointLimitError(f"{cmd.source}: <joints> {name} = {q[k] * f:g} {unit} is outside its soft limits "
                                  f"{lim.soft_lower[k] * f:g} ... {lim.soft_upper[k] * f:g} {unit}",
                                  hint="linear axes in metres, arm joints in the element's unit (rad unless "
                                       "unit=\"deg\")", joint=name, value=q[k] * f, lower=lim.soft_lower[k] * f,
                                  upper=lim.soft_upper[k] * f, unit=unit, source=str(cmd.source))


def _check_object(script: C.Script, cmd: C.SetObject) -> None:

    if cmd.name == "auto" or cmd.name in BUILTIN:
        return
    if cmd.name in ycb_names():
        if cmd.name not in available_objects():
            raise ScriptError(f"{cmd.source}: the YCB object {cmd.name!r} needs the shared YCB data, which is not "
                              "here", hint="use a built-in object (recon objects) or a mesh file beside the script")
        return
    if is_file_name(cmd.name):
        readable_file(script, cmd.name, cmd.source, "object mesh")
        return
    raise ScriptError(f"{cmd.source}: unknown object {cmd.name!r}",
                      hint="choose one of: " + ", ".join([*available_objects(), "auto", "<mesh file>"]))


def check_script(script: C.Script, *, object_override: str | None = None, cell_override: str | None = None,
                 append: bool = False) -> None:
    """Raise a ScriptError (file:line: what; what to do) for the first problem found."""
    started: C.Command | None = None
    kind = cell_override or DEFAULT_CELL
    scans = 0
    turn: C.TurnOver | None = None
    registered = reconstructed = False
    names: dict[str, C.Source] = {}
    fragments: set[str] = set()
    for cmd in script.commands:
        if isinstance(cmd, ACTIONS) and started is None:
            started = cmd
        if isinstance(cmd, SETUP) and started is not None:
            raise ScriptError(f"{cmd.source}: <{tag(cmd)}> after the first move or scan ({started.source})",
                              hint="choose the cell and the object at the top of the script")
        if isinstance(cmd, C.SetCell):
            kind = cell_override or script_cell(script, cmd)
            _check_realism(script, cmd)
        elif isinstance(cmd, C.SetObject) and object_override is None:
            _check_object(script, cmd)
        elif isinstance(cmd, C.MoveJoints):
            _check_joints(cmd, kind)
        elif isinstance(cmd, C.TurnOver):
            if turn is not None:
                raise ScriptError(f"{cmd.source}: a second <turn_over/> (the first is at {turn.source})",
                                  hint="a script scans two sides: one <turn_over/> between them",
                                  source=str(cmd.source))
            if scans == 0:
                raise ScriptError(f"{cmd.source}: <turn_over/> before any scan", source=str(cmd.source),
                                  hint="scan the first side before turning the object over")
            if append:
                raise ScriptError(f"{cmd.source}: --append cannot add to the scans of a script that turns the object "
                                  "over", hint="run it into a new output folder", source=str(cmd.source))
            turn, scans = cmd, 0
            registered = reconstructed = False  # what follows works on side 2
        elif isinstance(cmd, C.Scan):
            scans += 1
            registered = reconstructed = False
            if cmd.name:
                if cmd.name in names:
                    raise ScriptError(f"{cmd.source}: scan name {cmd.name!r} is used already at {names[cmd.name]}",
                                      hint="give every scan its own name")
                names[cmd.name] = cmd.source
            if isinstance(cmd, C.FragmentScan) and cmd.name is not None:  # the schema requires it
                fragments.add(cmd.name)
        elif isinstance(cmd, (C.Register, C.Reconstruct, C.Export, C.Evaluate)):
            if scans == 0:
                raise ScriptError(f"{cmd.source}: <{tag(cmd)}> before any scan", hint="scan before registering")
            if isinstance(cmd, C.Register):
                registered = True
            elif isinstance(cmd, C.Reconstruct):
                registered = reconstructed = True
            elif isinstance(cmd, C.Export):
                if cmd.mesh and not reconstructed:
                    raise ScriptError(f"{cmd.source}: <export mesh> before <reconstruct/>",
                                      hint="put <reconstruct/> before the export")
                if cmd.cloud and not registered:
                    raise ScriptError(f"{cmd.source}: <export cloud> before <register/> or <reconstruct/>",
                                      hint="put <register/> before the export")
            elif isinstance(cmd, C.Evaluate):
                if not registered:
                    raise ScriptError(f"{cmd.source}: <evaluate> before <register/> or <reconstruct/>",
                                      hint="put <register/> before the evaluation")
                if cmd.reference != "ground_truth":
                    readable_file(script, cmd.reference, cmd.source, "reference mesh")
        elif isinstance(cmd, C.LoadFragment):
            if cmd.name in names:
                raise ScriptError(f"{cmd.source}: fragment name {cmd.name!r} is used already at {names[cmd.name]}",
                                  hint="give every fragment its own name")
            names[cmd.name] = cmd.source
            if cmd.kind == "point_cloud":
                readable_file(script, cmd.path_point_cloud, cmd.source, "point cloud")
            else:
                readable_file(script, cmd.path_color, cmd.source, "colour image")
                readable_file(script, cmd.path_depth, cmd.source, "depth image")
            fragments.add(cmd.name)
        elif isinstance(cmd, C.Multiway):
            if len(fragments) < 2:
                raise ScriptError(f"{cmd.source}: <multiway> needs two fragments or more ({len(fragments)} before it)",
                                  hint="scan or load more fragments first")
        else:
            used = [getattr(cmd, a) for a in ("source_fragment", "target", "fragment") if hasattr(cmd, a)]
            if isinstance(cmd, C.AddFragment):
                used = [cmd.fragment]
            for name in used:
                if name not in fragments:
                    known = ", ".join(sorted(fragments)) or "none yet"
                    raise ScriptError(f"{cmd.source}: no fragment named {name!r} at this point (known: {known})",
                                      hint="scan, load or add it before using it")
            if isinstance(cmd, C.AddFragment):
                fragments.add(cmd.target)
            elif isinstance(cmd, C.DeleteFragment):
                fragments.discard(cmd.fragment)
    if turn is not None and scans == 0:
        raise ScriptError(f"{turn.source}: no scan after <turn_over/>: the second side is never scanned",
                          hint="move and scan the turned object after <turn_over/>", source=str(turn.source))



def check_backend(script: C.Script, backend: str | None, station: Path | None, dry_run: bool = False) -> None:
    """A run on the hardware backend needs a station file; refuse before anything is written."""

    cells = [c for c in script.commands if isinstance(c, C.SetCell)]
    wanted = Backend(backend or (cells[-1].backend if cells else Backend.SIM))
    if wanted is Backend.HARDWARE and station is None and not dry_run:

        where = f"{cells[-1].source}: " if backend is None and cells else ""
        raise HardwareUnavailable(
            f"{where}the hardware backend needs a station file (which robot and camera adapters, how to reach them)",
            hint="pass --station cell.yaml (docs/hardware.md has a complete example), or --backend sim")
