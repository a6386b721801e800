"""The one configuration object: every default of a run, in nested sections.

    cell          which cell, safety distance, table lift      (robot.description.CellConfig)
    scene         object, its scale, the margin of its box     (SceneConfig)
    sensor        image noise and resolution                   (SensorConfig)
    planner       planner, time limit, scalings, checks        (planning.planner.PlanOptions)
    registration  board, pose graph, surface                   (reconstruction.pipeline.RegisterOptions)
    viewplan      N, d_c, potential field, our additions       (ViewPlanConfig)
    realism       how the simulated cell differs from the model (realism.RealismProfile)

Each section is the typed options object its module already takes, so the defaults live in
one place (the section's dataclass); CLI options and script elements take their defaults
from :data:`DEFAULTS`, and a test checks that the XSD's attribute defaults are the same
numbers. Every run folder gets the effective configuration as ``config.yaml``, so a run can
be repeated from its folder.
"""

from __future__ import annotations

import dataclasses
import enum
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from recon_cli.errors import FileError, InputError
from recon_cli.inputs import files
from recon_cli.inputs.numbers import described
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import line_of, plain, read_yaml
from recon_cli.outputs import atomic_write_text
from recon_cli.perception.charuco import BoardSpec
from recon_cli.planning.options import PlanOptions
from recon_cli.randomness import DEFAULT_SEED, SEED_RANGE
from recon_cli.realism import IDEAL, RealismProfile
from recon_cli.reconstruction.crop import CropBox
from recon_cli.reconstruction.options import RegisterOptions
from recon_cli.robot.description import CellConfig

CONFIG_FORMAT = 1

#: the largest scale of a mesh file (0.001 for millimetres; meshes are read up to 1000 m after it)
MAX_SCALE = 1000.0
#: [m] the margin of the object's bounding box (collision and crop box)
BOX_MARGIN_RANGE = (0.0, 1.0)
#: the image scale of the simulated sensor, relative to its 1600 x 1200 pixels
RESOLUTION_RANGE = (0.05, 1.0)


def _check_range(what: str, value: float, bounds: tuple[float, float], unit: str = "",
                 example: str | None = None) -> None:
    """One-line InputError unless lo <= value <= hi (NaN too)."""
    lo, hi = bounds
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        example = f", e.g. {example}" if example else ""
        shown = f"{value:g}" if isinstance(value, int | float) and not isinstance(value, bool) else described(value)
        raise InputError(f"{what} = {shown}{unit} is outside {lo:g} ... {hi:g}{unit}",
                         hint=f"choose {what} within {lo:g} ... {hi:g}{unit}{example}")


@dataclass(frozen=True)
class SceneConfig:
    """What is scanned: a built-in object, a YCB object, a mesh file, or "auto" (the YCB
    drill where the shared data is present, else the built-in bottle)."""

    object_name: str = "auto"
    object_scale: float = 1.0  # of a mesh file (0.001 for millimetres)
    box_margin: float = 0.01  # [m] object bounding box margin (collision and crop box)

    def __post_init__(self) -> None:
        if not isinstance(self.object_name, str) or not self.object_name:
            raise InputError("the object name is empty or not a text",
                             hint="give a built-in object, a YCB object, a mesh file or 'auto'")
        scale = self.object_scale
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 < scale <= MAX_SCALE:
            shown = repr(scale) if isinstance(scale, int | float) and not isinstance(scale, bool) else described(scale)
            raise InputError(f"object scale {shown} is not a positive number up to {MAX_SCALE:g}",
                             hint="e.g. 0.001 for millimetres")
        _check_range("box margin", self.box_margin, BOX_MARGIN_RANGE, " m")


@dataclass(frozen=True)
class SensorConfig:
    noise: bool = True  # depth and colour noise of the simulated sensor
    resolution: float = 1.0  # image size relative to the sensor's 1600 x 1200 (RESOLUTION_RANGE)

    def __post_init__(self) -> None:
        if not isinstance(self.noise, bool):
            raise InputError("sensor noise is not true or false", hint="write true or false")
        _check_range("image scale", self.resolution, RESOLUTION_RANGE, example="0.5 for 800 x 600")


#: bounds of the view planner's numbers (ViewPlanConfig checks them; the command line states
#: them): scans in total, camera distance [m], preliminary samples per view (each is compared
#: with every earlier sample, so memory grows with m x the samples so far) and the
#: regularization of the potential field
VIEWPLAN_N = (2, 200)
VIEWPLAN_DC = (0.2, 1.5)
VIEWPLAN_M = (1, 1000)
VIEWPLAN_SIGMA = (1e-12, 1.0)


@dataclass(frozen=True)
class ViewPlanConfig:
    """The non-model-based view planner (thesis Table 2.1) and our additions."""

    n: int = 16  # scans in total, the initial one included
    d_c: float = 0.55  # [m] camera distance to the ellipsoid
    m: int = 200  # preliminary samples per view (thesis: 200)
    sigma: float = 1e-5  # regularization of the potential field (thesis: 1e-5)
    lift: bool = True  # raise infeasible views toward the vertical (ours; False: as the thesis)
    min_height: float = 0.05  # [m] lowest camera height above the board plane (thesis: above it)
    min_axis_ratio: float = 0.3  # ours: no semi-axis below this share of the largest (0: the thesis)
    partial_voxel: float = 0.002  # [m] down-sampling of each scan's points added to the partial object

    def __post_init__(self) -> None:
        for name, (lo, hi), unit in (("n", VIEWPLAN_N, ""), ("d_c", VIEWPLAN_DC, " m"), ("m", VIEWPLAN_M, ""),
                                     ("sigma", VIEWPLAN_SIGMA, "")):
            value = getattr(self, name)
            if not lo <= value <= hi:  # NaN too
                raise InputError(f"view planner {name} = {value:g}{unit} is outside {lo:g} ... {hi:g}{unit}",
                                 hint=f"choose {name} within {lo:g} ... {hi:g}{unit}")


@dataclass(frozen=True)
class Config:
    cell: CellConfig = field(default_factory=CellConfig)
    scene: SceneConfig = field(default_factory=SceneConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    planner: PlanOptions = field(default_factory=PlanOptions)
    registration: RegisterOptions = field(default_factory=RegisterOptions)
    viewplan: ViewPlanConfig = field(default_factory=ViewPlanConfig)
    seed: int = DEFAULT_SEED
    realism: RealismProfile = IDEAL  # the simulation only (a hardware station is as real as it is)

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) \
                or not SEED_RANGE[0] <= self.seed <= SEED_RANGE[1]:
            seed = self.seed
            shown = seed if isinstance(seed, int) and not isinstance(seed, bool) else described(seed)
            raise InputError(f"seed {shown} is not a whole number within {SEED_RANGE[0]} ... 2^32-1",
                             hint="choose a seed within 0 ... 4294967295")

    def replace(self, **sections) -> Config:
        return dataclasses.replace(self, **sections)

    def with_values(self, values: dict) -> Config:
        """A copy with ``{"section.field": value}`` set (``"seed"`` for the seed)."""
        out, values = self, dict(values)
        if "cell.kind" in values:  # another cell comes with its own default safety distance
            kind, safety = values.pop("cell.kind"), values.pop("cell.safety_distance", None)
            out = dataclasses.replace(out, cell=dataclasses.replace(out.cell, kind=kind, safety_distance=safety))
        for path, value in values.items():
            out = _set(out, path.split("."), value)
        return out

    def to_dict(self) -> dict:
        return {"format": CONFIG_FORMAT, **_plain(dataclasses.asdict(self))}

    @classmethod
    def from_dict(cls, data: dict, where: str = "config.yaml") -> Config:
        """The inverse of :meth:`to_dict` (see :func:`config_from_dict`)."""
        return config_from_dict(data, where)


DEFAULTS = Config()


def _set(obj, keys: list[str], value):
    if len(keys) == 1:
        return dataclasses.replace(obj, **{keys[0]: value})
    return dataclasses.replace(obj, **{keys[0]: _set(getattr(obj, keys[0]), keys[1:], value)})


def _plain(value):
    """YAML-friendly: enums by value, tuples and arrays as lists, paths as strings."""

    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, (Path, str)):  # a path, or a str subclass (a cell's name)
        return str(value)
    return value


def write_config(folder: Path, config: Config, **extra) -> Path:
    """The effective configuration of a run as ``folder/config.yaml`` (with what else
    describes the run: command, script, object, ...)."""


    data = config.to_dict()
    if extra:
        data["run"] = _plain(extra)
    return atomic_write_text(Path(folder) / "config.yaml", yaml.safe_dump(data, sort_keys=False))


#: the keys of config.yaml besides the sections: the format and what describes the run
RUN_KEY = "run"


def _hints(cls) -> dict:
    """The resolved field types of a section's dataclass."""


    return typing.get_type_hints(cls, vars(sys.modules[cls.__module__]),
                                 {"BoardSpec": BoardSpec, "CropBox": CropBox})


def _build(tp, value):
    """``value`` (plain YAML data, already checked by the schema) as the type ``tp``."""

    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        return _build(next(a for a in args if a is not type(None)), value)
    if dataclasses.is_dataclass(tp):
        hints = _hints(tp)
        return tp(**{f.name: _build(hints[f.name], value[f.name]) for f in dataclasses.fields(tp)
                     if f.init and f.name in value})
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_build(args[0], v) for v in value)
        return tuple(_build(a, v) for a, v in zip(args, value, strict=True))
    if tp is np.ndarray:
        return np.asarray(value, dtype=float)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return tp(value)
    if tp is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def config_from_dict(data: dict, where: str = "config.yaml") -> Config:
    """The Config of ``data`` (what :meth:`Config.to_dict` wrote, or a part of it: a missing
    key keeps its default). ``data`` is checked against schemas/config.schema.json first; a
    value a section refuses is named with ``where:line`` too."""

    check(data, "config", where)
    hints = _hints(Config)
    sections = {}
    for f in dataclasses.fields(Config):
        if f.name not in data:
            continue
        try:
            sections[f.name] = _build(hints[f.name], data[f.name])
        except InputError as exc:
            line = line_of(data, f.name)
            at = f"{where}:{line}" if line else where
            raise InputError(f"{at}: {f.name}: {exc.message}", hint=exc.hint) from None
    return Config(**sections)


@dataclass(frozen=True)
class ConfigFile:
    """A ``config.yaml`` as read: its configuration, its ``run`` section and the document
    itself (which knows the line of every key, for messages about its values)."""

    path: Path
    config: Config
    run: dict
    doc: dict

    def line(self, dotted: str) -> int | None:
        """The line of the key ``a.b.c`` (of its nearest parent written in the file)."""
        node, line = self.doc, None
        for key in dotted.split("."):
            if not isinstance(node, dict) or key not in node:
                break
            line = line_of(node, key) or line
            node = node[key]
        return line

    def at(self, dotted: str) -> str:
        """``FILE:LINE: a.b.c``."""
        line = self.line(dotted)
        return f"{self.path}:{line}: {dotted}" if line else f"{self.path}: {dotted}"


def read_config(path: Path) -> tuple[Config, dict]:
    """The configuration of a run folder's ``config.yaml`` and its ``run`` section (see
    :func:`load_config_file`)."""
    file = load_config_file(path)
    return file.config, file.run


def load_config_file(path: Path) -> ConfigFile:
    """A run folder's ``config.yaml`` (through the YAML reader and the schema) with its ``run``
    section (what else repeats the run: command, script, store, ...); a file that is a link
    leading out of its folder is refused before it is read."""

    hint = "give the config.yaml of a run folder (recon writes one into each)"
    path = Path(path)
    link = files.link_out_of(path, path.parent)
    if link is not None:  # refused before it is read, as every file read back from a run folder
        raise FileError(files.outside_text(files.Refusal(files.OUTSIDE, path, 0, root=path.parent, link=link),
                                           "configuration file"), hint=files.OUTSIDE_HINT)
    data = read_yaml(path, "configuration file", hint=hint, root=path.parent)
    if data is None:
        raise InputError(f"{path} is empty", hint=hint)
    config = config_from_dict(data, str(path))
    return ConfigFile(path, config, plain(data.get(RUN_KEY) or {}), data)
