"""Options shared by several commands and the parsers of their values.

Defaults come from :data:`recon_cli.config.DEFAULTS` (a light import: no planner, no
Open3D), so ``recon --help`` shows the same numbers a run uses.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Literal

import typer

from recon_cli.config import (
    DEFAULTS,
    MAX_SCALE,
    RESOLUTION_RANGE,
    RUN_KEY,
    SEED_RANGE,
    VIEWPLAN_DC,
    VIEWPLAN_N,
    Config,
    ConfigFile,
    load_config_file,
)
from recon_cli.errors import InputError, UnknownNameError
from recon_cli.geometry.view import MAX_COORDINATE, MAX_RADIUS, Frame, View
from recon_cli.inputs.numbers import described
from recon_cli.objects import BUILTIN, ycb_names
from recon_cli.outputs import OutputMode, claim_output
from recon_cli.planning.options import PLANNERS, SIMPLIFICATIONS
from recon_cli.realism import BUILT_IN, load_profile
from recon_cli.recording import require_rerun
from recon_cli.robot.cell import Cell
from recon_cli.robot.cell_file import shipped_cells
from recon_cli.robot.collision import ObjectBox
from recon_cli.robot.description import CellConfig, CellName

D = DEFAULTS

if TYPE_CHECKING:  # a checker sees the option's value, a name; typer takes the choices from the Literal
    PlannerName = str
    SimplificationName = str
else:
    PlannerName = Literal[PLANNERS]  # one of PLANNERS
    SimplificationName = Literal[SIMPLIFICATIONS]  # one of SIMPLIFICATIONS

#: bounds of the view options, the same as a script's (README "limits"; the scripts' XSD and
#: recon_cli.scripts.build.ANGLE_BOUNDS_DEG): focus coordinates within ±MAX_COORDINATE [m]
#: and the radius (the lower bound stands for "positive") as a View takes them, polar angle,
#: azimuth and roll [deg]
RADIUS_RANGE = (0.001, MAX_RADIUS)
MAX_THETA = 180.0
MAX_TURN = 720.0
#: planner time limits [s] (a script's <planner time> is at most 3600 s too)
PLANNING_TIME_RANGE = (0.1, 3600.0)
#: the safety distance [m] (robot.description.CellConfig checks the same range)
SAFETY_RANGE = (0.0, 0.2)
#: the longest edge [m] of a box given on the command line (--object-box, --box)
MAX_BOX_EDGE = 10.0
#: the scale of a mesh file (0.001 for millimetres; meshes are read up to MAX_SCALE x 1 m
#: after it); the lower bound stands for "positive"
SCALE_RANGE = (1e-6, MAX_SCALE)


def _focus(value: str | None) -> str | None:
    """--focus: three finite coordinates within ±MAX_COORDINATE m (a usage error, exit 2)."""
    if value is None:
        return value
    try:
        x = parse_vector(value, 3, "--focus", "metres")
    except InputError:
        raise typer.BadParameter(f"{value!r} is not 3 numbers; give x,y,z in metres, e.g. 0,0,0.78") from None
    worst = max(abs(v) for v in x)
    if worst > MAX_COORDINATE:
        raise typer.BadParameter(f"a coordinate of {worst:.4g} m is outside ±{MAX_COORDINATE:g} m; "
                                 "give x,y,z in metres, e.g. 0,0,0.78")
    return value


def names_of(values: Iterable) -> tuple[str, ...]:
    """The names of enum members (their values) or of plain names."""
    return tuple(str(getattr(v, "value", v)) for v in values)


def names_text(names: Iterable[str], last: str = "or") -> str:
    """'a, b or c'."""
    names = tuple(names)
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} {last} {names[-1]}"


def name_list(allowed: Callable[[], Iterable[str]], *, keyword: str | None = None,
              files: bool = False) -> Callable[[str | None], str | None]:
    """The callback of an option that takes comma-separated names, each one of ``allowed()``
    (called when a command line is parsed, not for --help), ``keyword`` alone, or (``files``)
    a file path: anything else is a usage error (exit 2) naming the choices."""

    def check(value: str | None) -> str | None:
        if value is None or (keyword is not None and value.strip() == keyword):
            return value
        names = tuple(allowed())
        chosen = split_names(value)
        if not chosen:
            raise typer.BadParameter(f"{value!r} names nothing; give one or more of {', '.join(names)}")
        for name in chosen:
            if name not in names and not (files and looks_like_file(name)):
                alternatives = [*names, *([keyword] if keyword else []), *(["a mesh FILE"] if files else [])]
                raise typer.BadParameter(f"{name!r} is not one of {names_text(alternatives)}")
        return value

    return check


def split_names(text: str) -> list[str]:
    """'a, b' -> ['a', 'b']."""
    return [x.strip() for x in text.split(",") if x.strip()]


def looks_like_file(name: str) -> bool:
    """A name that can only be a file path (a separator, a dot or a suffix in it)."""
    return any(ch in name for ch in "/\\.") or bool(Path(name).suffix)


def object_names(auto: bool) -> tuple[str, ...]:
    """The objects recon knows by name (built-in and YCB, present here or not), and 'auto'."""

    return (*BUILTIN, *ycb_names(), *(("auto",) if auto else ()))


def object_option(auto: bool) -> Callable[[str | None], str | None]:
    """The callback of --object: a known object (built-in or YCB, present or not), 'auto'
    where the command takes it, or a mesh file; anything else is a usage error."""
    check = name_list(lambda: object_names(auto), files=True)

    def one(value: str | None) -> str | None:
        if value is not None and "," in value:
            raise typer.BadParameter(f"{value!r} is more than one object; give one name or mesh FILE")
        return check(value)

    return one


def object_metavar(auto: bool) -> str:
    return "<" + "|".join((*object_names(auto), "FILE")) + ">"


def _realism(value: str | None) -> str | None:
    """--realism: a built-in profile or a YAML file (load_profile reads it when the command runs)."""

    if value is None or value in BUILT_IN or Path(value).suffix.lower() in (".yaml", ".yml") or Path(value).exists():
        return value
    raise typer.BadParameter(f"{value!r} is not one of {', '.join(BUILT_IN)} or a profile FILE.yaml")


def _realism_metavar() -> str:

    return "<" + "|".join((*BUILT_IN, "FILE.yaml")) + ">"


def cell_metavar() -> str:
    return _cell_metavar()


def cell_option(value: str | None) -> str | None:
    """--cell where it is optional (overrides): the same check as CellOpt's."""
    return _cell(value)


def _cell(value: str | None) -> str | None:
    """--cell: a shipped cell's name or a cell FILE.yaml (read when the command runs)."""

    if value is None:
        return value
    try:
        return CellName.parse(value)
    except UnknownNameError:
        names = ", ".join(repr(n) for n in shipped_cells())
        raise typer.BadParameter(f"{value!r} is not one of {names} or a cell FILE.yaml") from None


def _cell_metavar() -> str:

    return "<" + "|".join((*shipped_cells(), "FILE.yaml")) + ">"


CellOpt = Annotated[str, typer.Option("--cell", metavar=_cell_metavar(), callback=_cell,
                                      help="The cell: a shipped cell (gantry: 9 DoF with linear axes, ceiling: "
                                           "7 DoF, fr3: Franka FR3, ur5e: UR5e) or a cell FILE.yaml "
                                           "(docs/cells.md).")]
SafetyOpt = Annotated[float | None, typer.Option("--safety", min=SAFETY_RANGE[0], max=SAFETY_RANGE[1],
                                                 help="Safety distance [m] that inflates every collision shape "
                                                      "(default: the cell file's).")]
SeedOpt = Annotated[int, typer.Option("--seed", min=SEED_RANGE[0], max=SEED_RANGE[1],
                                      help="Seed of the random number generator (0 ... 2^32-1).")]
FocusOpt = Annotated[str, typer.Option("--focus", callback=_focus, help="Focus point f as x,y,z [m], each "
                                                                        f"within ±{MAX_COORDINATE:g} m.")]
RadiusOpt = Annotated[float, typer.Option("--radius", "-r", min=RADIUS_RANGE[0], max=RADIUS_RANGE[1],
                                          help="Camera distance r from f [m].")]
ThetaOpt = Annotated[float, typer.Option("--theta", min=-MAX_THETA, max=MAX_THETA,
                                         help="Polar angle from the vertical [deg].")]
PhiOpt = Annotated[float, typer.Option("--phi", min=-MAX_TURN, max=MAX_TURN, help="Azimuth [deg].")]
AlphaOpt = Annotated[float, typer.Option("--alpha", min=-MAX_TURN, max=MAX_TURN,
                                         help="Camera roll about its viewing axis [deg].")]
FrameOpt = Annotated[Frame, typer.Option("--frame", help="Frame of f and the angles.")]
ResolutionOpt = Annotated[float, typer.Option(min=RESOLUTION_RANGE[0], max=RESOLUTION_RANGE[1],
                                              help="Image size relative to 1600 x 1200.")]
ScaleOpt = Annotated[float, typer.Option("--scale", min=SCALE_RANGE[0], max=SCALE_RANGE[1],
                                         help="Scale of a mesh file (0.001 for millimetres).")]
PlanningTimeOpt = Annotated[float, typer.Option("--planning-time", min=PLANNING_TIME_RANGE[0],
                                                max=PLANNING_TIME_RANGE[1],
                                                help="Planning time limit per request [s].")]
DcOpt = Annotated[float | None, typer.Option("--dc", min=VIEWPLAN_DC[0], max=VIEWPLAN_DC[1],
                                             help="Camera distance to the ellipsoid [m] (default: the scan distance "
                                                  "of the cell's camera, 0.55 m on the thesis' cells).")]
REALISM_HELP = ("How real the simulated cell is: 'ideal' (the model itself), 'thesis' (errors of the thesis' cell), "
                "'lab' (the thesis' errors with the cell's own camera) or a profile FILE.yaml (docs/simulation.md).")


def realism_option(help_text: str = REALISM_HELP):
    """--realism: a built-in realism profile or a profile file."""
    return typer.Option("--realism", metavar=_realism_metavar(), callback=_realism, help=help_text)


RealismOpt = Annotated[str, realism_option()]
#: -n: the number of scans of a view-planning run (the thesis' n; ``--n`` as the thesis writes it)
ScansOpt = Annotated[int, typer.Option("--scans", "-n", "--n", min=VIEWPLAN_N[0], max=VIEWPLAN_N[1],
                                       help="Scans in total (the initial one included; the thesis' n).")]
ForceOpt = Annotated[bool, typer.Option("--force", help="Use a non-empty --out: first remove what recon wrote there "
                                                      "(links only as links; the rest stays; "
                                                      "docs/architecture.md); without it --out must be new or "
                                                      "empty.")]
ConfigOpt = Annotated[Path | None, typer.Option(
    "--config", help="Repeat a run: the config.yaml of its folder gives every setting (and what its 'run:' section "
                     "records, e.g. the script or the scan store); options given together with --config override "
                     "the file's values, the other options keep the file's.")]
RecordOpt = Annotated[bool, typer.Option("--record", help="Also write a 3D recording of the run (recording.rrd "
                                                         "in the output folder; recon view opens it; needs "
                                                         "recon-scan[viz]).")]

#: the example view of ``recon ik`` and ``recon capture``: the thesis' focus point above the board
FOCUS = "0,0,0.78"
RADIUS = 0.6  # [m]
THETA = 70.0  # [deg]


def parse_vector(text: str, n: int, option: str, unit: str) -> tuple[float, ...]:
    """Parse 'x,y,z' into n finite floats, or raise a one-line InputError."""
    parts = [p for p in text.replace(";", ",").split(",") if p.strip()]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != n or not all(math.isfinite(v) for v in values):
        example = ",".join(["0"] * (n - 1) + ["0.3"])
        raise InputError(f"{option} '{text}' is not {n} numbers",
                         hint=f"write {n} comma-separated values in {unit}, e.g. {example}")
    return values


def output_folder(out: Path | None, command: str, *, append: bool = False, force: bool = False,
                  append_hint: str | None = None, force_option: str = "--force", **claim):
    """Claim the output folder of a command (:func:`recon_cli.outputs.claim_output`) from its
    ``--out``, ``--append`` and ``--force``; before any planning, robot or registration work."""

    mode = OutputMode.of(append, force, force_option=force_option)
    return claim_output(out, mode, command=command, append=append_hint, force=force_option, **claim)


def check_record(record: bool) -> None:
    """--record: the recording library must be there before anything runs."""
    if record:

        require_rerun()


def realism_profile(text: str):
    """The realism profile of ``--realism`` (a built-in name or a YAML file)."""

    return load_profile(text)


def cell_config(cell: str, safety: float | None) -> CellConfig:
    """The cell of ``--cell`` with ``--safety`` (None: the cell file's safety distance)."""
    kind = CellName.parse(cell)
    return CellConfig(kind=kind) if safety is None else CellConfig(kind=kind, safety_distance=safety)


def make_cell(cell: str, safety: float | None, object_box: str | None = None):
    """The cell of ``--cell`` / ``--safety`` with an optional box 'sx,sy,sz' on the table centre."""

    c = Cell(cell_config(cell, safety))
    if object_box:
        size = parse_vector(object_box, 3, "--object-box", "metres")
        if min(size) <= 0:
            raise InputError(f"--object-box '{object_box}' has a non-positive edge",
                             hint="give the box edges in metres, e.g. 0.3,0.3,0.3")
        if max(size) > MAX_BOX_EDGE:
            raise InputError(f"--object-box '{object_box}' has an edge beyond {MAX_BOX_EDGE:g} m",
                             hint="give the box edges in metres, e.g. 0.3,0.3,0.3")
        x, y, _ = c.config.cell_file.object_position  # the box stands where the cell's objects stand
        c.set_object_box(ObjectBox.on_table(size, (x, y), table_top_z=c.table_surface_z))
    return c


def make_view(focus: str, radius: float, theta: float, phi: float, alpha: float, frame: str):
    """A camera view from the view options (angles in degrees)."""

    try:
        ref = Frame(frame.lower())
    except ValueError:
        raise UnknownNameError("frame", frame, [f.value for f in Frame]) from None
    return View.from_degrees(parse_vector(focus, 3, "--focus", "metres"), radius, theta, phi, alpha, ref)


def index_list(text: str, option: str, n: int) -> list[int]:
    """Parse '3,7' into [3, 7] (1-based indices up to n)."""
    out = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        if not part.isdigit() or not 1 <= int(part) <= n:
            raise InputError(f"{option} {text!r}: {part!r} is not a view number 1..{n}", hint="e.g. 3,7")
        out.append(int(part))
    return out


def positive(value: float, option: str, hint: str) -> float:
    if not math.isfinite(value) or value <= 0:
        raise InputError(f"{option} {value} is not a positive number", hint=hint)
    return value


@dataclass(frozen=True)
class OptionRange:
    """The range of a number option (its ``min`` and ``max``), for the values a --config
    file gives in its place."""

    flag: str
    lo: float
    hi: float
    whole: bool


def option_ranges(ctx: typer.Context) -> dict[str, OptionRange]:
    """The range of every number option of the command being run, by parameter name."""
    out = {}
    for param in ctx.command.params:
        lo, hi = getattr(param, "min", None), getattr(param, "max", None)
        if param.name and lo is not None and hi is not None and param.opts:
            annotation = getattr(getattr(param, "type_descriptor", None), "annotation", None)
            whole = annotation is int or int in getattr(annotation, "__args__", ())
            flag = max((o for o in param.opts if o.startswith("--")), key=len, default=param.opts[0])
            out[param.name] = OptionRange(flag, lo, hi, whole)
    return out


@dataclass(frozen=True)
class RunBase:
    """What a command starts from: the configuration and the ``run:`` section of ``--config
    FILE`` (else the defaults and nothing), and which options were given on the command line.

    A number the file gives in place of an option is refused outside that option's range
    (``ranges``), as on the command line: --config takes what the options take."""

    config: Config
    run: dict
    path: Path | None
    given: frozenset[str]
    file: ConfigFile | None = None
    command: str = ""
    ranges: dict[str, OptionRange] = field(default_factory=dict)

    def _checked(self, name: str, value, dotted: str):
        """``value``, given by the file at ``dotted`` for the option ``name``, within the
        option's range."""
        r = self.ranges.get(name)
        if r is None or self.file is None or value is None:
            return value
        at = self.file.at(dotted)
        kind = "a whole number" if r.whole else "a number"
        if isinstance(value, bool) or not isinstance(value, int | float) \
                or (r.whole and not (math.isfinite(value) and float(value).is_integer())):
            shown = f"= {value:g} is" if isinstance(value, float) else f"is {described(value)},"
            raise InputError(f"{at} {shown} not {kind} (the value of {r.flag})",
                             hint=f"write {kind} within {r.lo:g} ... {r.hi:g}")
        if not (math.isfinite(value) and r.lo <= value <= r.hi):
            raise InputError(f"{at} = {value:g} is outside {r.lo:g} ... {r.hi:g}, the range of {r.flag}",
                             hint=f"give a value the command line takes (recon {self.command} --help)")
        return value

    def pick(self, name: str, value, stored, at: str | None = None):
        """The option ``name``'s ``value`` where it was given or there is no --config file,
        else the file's ``stored`` value (at the key ``at`` of the file, by default
        ``run.NAME``), refused outside the option's range."""
        if self.path is None or name in self.given:
            return value
        return self._checked(name, stored, at or f"{RUN_KEY}.{name}")

    def picked(self, **options) -> dict:
        """``{config path: value}`` of the options that override the file (all without
        --config): ``options`` maps an option's parameter name to (dotted config path, value);
        a value may be a function, called only when it is used. The file's values of the
        other options are checked against the options' ranges."""
        out = {}
        for name, (path, value) in options.items():
            if self.path is None or name in self.given:
                out[path] = value() if callable(value) else value
            elif name in self.ranges:
                self._checked(name, functools.reduce(getattr, path.split("."), self.config), path)
        return out

    def stored(self, key: str, default=None):
        return self.run.get(key, default)


#: the commands that take --config FILE, and every command whose run folder holds a config.yaml
CONFIG_COMMANDS = ("autoscan", "capture", "register", "run")
CONFIG_WRITERS = (*CONFIG_COMMANDS, "calibrate", "bench registration", "bench viewplan", "bench sim")


def run_base(ctx: typer.Context, path: Path | None, command: str) -> RunBase:
    """The --config FILE of ``command`` (a one-line error when it was written by another
    command) and the options given on the command line beside it."""
    sources = {name: ctx.get_parameter_source(name) for name in ctx.params}
    given = frozenset(name for name, source in sources.items()
                      if source is not None and source.name not in ("DEFAULT", "DEFAULT_MAP"))
    if path is None:
        return RunBase(DEFAULTS, {}, None, given)

    file = load_config_file(path)
    written = file.run.get("command")
    if written is not None and written != command:
        if isinstance(written, str) and written in CONFIG_WRITERS:
            hint = (f"repeat it with recon {written} --config {path}" if written in CONFIG_COMMANDS
                    else f"give one written by recon {command} (its run folder's config.yaml)")
            raise InputError(f"{file.at(RUN_KEY + '.command')}: this config.yaml was written by recon {written}; "
                             f"give one written by recon {command}", hint=hint)
        raise InputError(f"{file.at(RUN_KEY + '.command')} names no command that writes a config.yaml "
                         f"(one of {', '.join(CONFIG_WRITERS)})",
                         hint=f"give the config.yaml of a recon {command} run folder")
    return RunBase(file.config, file.run, Path(path), given, file, command, option_ranges(ctx))
