"""Typed commands of an automation script (both dialects compile to these).

Every command knows where it was written (``Source``), so a failure at run time points to
the line of the script (or of the macro) that asked for it. Angles are radians, lengths
metres, whatever the script's units were.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from recon_cli.geometry.view import View
from recon_cli.reconstruction.options import COVERAGE_TOLERANCE, SurfaceOptions

_SURFACE = SurfaceOptions()


@dataclass(frozen=True)
class Source:
    file: str
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"


@dataclass(frozen=True)
class Command:
    source: Source

    @property
    def keyword(self) -> str:
        return type(self).__name__

    def describe(self) -> str:
        return self.keyword


# --------------------------------------------------------------------- set-up
@dataclass(frozen=True)
class SetCell(Command):
    """Defaults of the attributes: recon_cli.config.DEFAULTS (the builder fills them in)."""

    kind: str
    safety_distance: float | None  # None: the cell file's
    backend: str
    resolution: float
    noise: bool
    realism: str  # realism profile of the simulation: a built-in name or a YAML file

    def describe(self) -> str:
        safety = "the cell file's" if self.safety_distance is None else f"{self.safety_distance:g} m"
        return (f"cell {self.kind}, safety distance {safety}, backend {self.backend}, "
                f"image scale {self.resolution:g}, noise {'on' if self.noise else 'off'}, realism {self.realism}")


@dataclass(frozen=True)
class SetObject(Command):
    name: str
    scale: float

    def describe(self) -> str:
        name = "the drill if the YCB data is here, else the bottle" if self.name == "auto" else self.name
        return f"object {name}" + (f" (scale {self.scale:g})" if self.scale != 1.0 else "")


@dataclass(frozen=True)
class SetBox(Command):
    """Object bounding box (collision object and crop box). Without centre and size: the
    simulated object's own box grown by ``margin``."""

    center: tuple[float, float, float] | None
    size: tuple[float, float, float] | None
    frame: str
    margin: float

    def describe(self) -> str:
        if self.center is None:
            return f"box around the object (margin {self.margin:g} m)"
        return f"box centre {self.center} size {self.size} ({self.frame})"


@dataclass(frozen=True)
class SetPlanner(Command):
    name: str
    time: float
    velocity_scale: float
    acceleration_scale: float

    def describe(self) -> str:
        return (f"planner {self.name}, {self.time:g} s, velocity x{self.velocity_scale:g}, "
                f"acceleration x{self.acceleration_scale:g}")


# --------------------------------------------------------------------- motion
@dataclass(frozen=True)
class Move(Command):
    """A move the sequence optimizer may reorder (a camera goal)."""


@dataclass(frozen=True)
class MoveView(Move):
    view: View = field(default=None)  # type: ignore[assignment]

    def describe(self) -> str:
        v = self.view
        return (f"move to f = {tuple(round(x, 4) for x in v.focus)}, r = {v.radius:g} m, "
                f"theta {np.degrees(v.theta):.1f}°, phi {np.degrees(v.phi):.1f}°, alpha {np.degrees(v.alpha):.1f}° "
                f"({v.frame.value})")


@dataclass(frozen=True)
class MovePose(Move):
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # x y z w
    frame: str = "world"

    def describe(self) -> str:
        return f"move camera to {self.position} quaternion {self.orientation} ({self.frame})"


@dataclass(frozen=True)
class MoveJoints(Command):
    """Joint goal; revolute joints in ``unit`` (rad or deg), linear axes always in metres."""

    values: tuple[float, ...] = ()
    unit: str = "rad"

    def describe(self) -> str:
        return "move joints to " + " ".join(f"{v:g}" for v in self.values) + f" ({self.unit}; axes in m)"


@dataclass(frozen=True)
class MoveHome(Command):
    def describe(self) -> str:
        return "move home"


@dataclass(frozen=True)
class Scan(Command):
    name: str | None = None

    def describe(self) -> str:
        return "scan" + (f" {self.name}" if self.name else "")


@dataclass(frozen=True)
class Wait(Command):
    seconds: float = 0.0

    def describe(self) -> str:
        return f"wait {self.seconds:g} s"


# --------------------------------------------------------------------- two sides
@dataclass(frozen=True)
class TurnOver(Command):
    """The object turned over: the scans before it are side 1, those after it side 2. The
    robot parks at its home posture; in simulation physics turns the object (drawn from
    ``seed``, None: the run's seed), on a real cell the operator."""

    seed: int | None = None

    def describe(self) -> str:
        seed = "" if self.seed is None else f", seed {self.seed}"
        return f"turn the object over (robot parked at home; by physics in simulation{seed}, else by the operator)"


@dataclass(frozen=True)
class MergeSides(Command):
    """The end of a run that turned the object over (not written in a script: the runner adds
    it, with the source of the ``<turn_over/>``): the sides registered by shape and merged."""

    def describe(self) -> str:
        return "register the two sides by shape and merge them"


# --------------------------------------------------------------------- reconstruction (all scans)
@dataclass(frozen=True)
class Register(Command):
    local: bool
    board: bool
    loop_closures: str

    def describe(self) -> str:
        return (f"register all scans ({'ChArUco, else kinematics' if self.board else 'kinematics'}"
                + (f", pose graph, loop closures by {self.loop_closures}" if self.local else ", global only") + ")")


@dataclass(frozen=True)
class Reconstruct(Command):
    voxel: float
    depth: int
    trim: float

    def describe(self) -> str:
        return f"reconstruct (voxel {self.voxel:g} m, Poisson depth {self.depth}, trim {self.trim:g})"


@dataclass(frozen=True)
class Export(Command):
    cloud: str | None = None
    mesh: str | None = None

    def describe(self) -> str:
        return "export " + ", ".join(f"{k} to {v}" for k, v in (("cloud", self.cloud), ("mesh", self.mesh)) if v)


@dataclass(frozen=True)
class Evaluate(Command):
    reference: str = "ground_truth"
    tolerance: float = COVERAGE_TOLERANCE
    align: str = "none"

    def describe(self) -> str:
        return f"evaluate against {self.reference} (tolerance {self.tolerance:g} m, align {self.align})"


# --------------------------------------------------------------------- fragments (thesis dialect)
@dataclass(frozen=True)
class FragmentScan(Scan):
    """A scan that also becomes a named fragment (thesis ``scan``)."""

    path_color: str = ""
    path_depth: str = ""
    path_pose: str = ""


@dataclass(frozen=True)
class PairRegister(Command):
    source_fragment: str = ""
    target: str = ""
    method: str = "point_to_plane_icp"
    threshold: float = 0.01

    def describe(self) -> str:
        return f"register {self.source_fragment} onto {self.target} ({self.method}, {self.threshold:g} m)"


@dataclass(frozen=True)
class Multiway(Command):
    method: str = "point_to_plane_icp"
    threshold: float = 0.01

    def describe(self) -> str:
        return f"multiway registration of all fragments ({self.method}, {self.threshold:g} m)"


@dataclass(frozen=True)
class AddFragment(Command):
    fragment: str = ""
    target: str = ""

    def describe(self) -> str:
        return f"add {self.fragment} to {self.target}"


@dataclass(frozen=True)
class Downsample(Command):
    fragment: str = ""
    voxel: float = _SURFACE.voxel

    def describe(self) -> str:
        return f"down-sample {self.fragment} (voxel {self.voxel:g} m)"


@dataclass(frozen=True)
class TransformFragment(Command):
    fragment: str = ""
    matrix: tuple[tuple[float, ...], ...] = ()

    def describe(self) -> str:
        return f"transform {self.fragment}"


@dataclass(frozen=True)
class LoadFragment(Command):
    name: str = ""
    kind: str = "rgbd_image"
    path_color: str = ""
    path_depth: str = ""
    path_point_cloud: str = ""

    def describe(self) -> str:
        return f"load {self.name} ({self.kind})"


@dataclass(frozen=True)
class ExportFragment(Command):
    fragment: str = ""
    kind: str = "mesh"
    path: str = ""

    def describe(self) -> str:
        return f"export {self.fragment} as {self.kind.replace('_', ' ')} to {self.path}"


@dataclass(frozen=True)
class DeleteFragment(Command):
    fragment: str = ""

    def describe(self) -> str:
        return f"delete {self.fragment}"


@dataclass(frozen=True)
class Display(Command):
    """show / hide / color: a display instruction of the thesis' GUI, recorded only."""

    action: str = "show"
    fragment: str = ""
    rgb: tuple[float, float, float] | None = None

    def describe(self) -> str:
        return f"{self.action} {self.fragment} (display only, recorded)"


@dataclass(frozen=True)
class Script:
    path: str
    name: str
    dialect: str  # recon | thesis
    on_failure: str  # skip | abort
    optimize: bool
    commands: tuple[Command, ...]
    expanded_xml: str  # after xacro, for the record
