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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.planning.options import PlanOptions
from recon_cli.realism import IDEAL, RealismProfile
from recon_cli.reconstruction.options import RegisterOptions
from recon_cli.robot.description import CellConfig

CONFIG_FORMAT = 1


@dataclass(frozen=True)
class SceneConfig:
    """What is scanned: a built-in object, a YCB object, a mesh file, or "auto" (the YCB
    drill where the shared data is present, else the built-in bottle)."""

    object_name: str = "auto"
    object_scale: float = 1.0  # of a mesh file (0.001 for millimetres)
    box_margin: float = 0.01  # [m] object bounding box margin (collision and crop box)


@dataclass(frozen=True)
class SensorConfig:
    noise: bool = True  # depth and colour noise of the simulated sensor
    resolution: float = 1.0  # image size relative to the sensor's 1600 x 1200


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

    def __post_init__(self) -> None:
        from recon_cli.errors import InputError

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
    seed: int = 0
    realism: RealismProfile = IDEAL  # the simulation only (a hardware station is as real as it is)

    def replace(self, **sections) -> Config:
        return dataclasses.replace(self, **sections)

    def to_dict(self) -> dict:
        return {"format": CONFIG_FORMAT, **_plain(dataclasses.asdict(self))}


DEFAULTS = Config()


def _plain(value):
    """YAML-friendly: enums by value, tuples and arrays as lists, paths as strings."""
    import enum

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
    if isinstance(value, Path):
        return str(value)
    return value


def write_config(folder: Path, config: Config, **extra) -> Path:
    """The effective configuration of a run as ``folder/config.yaml`` (with what else
    describes the run: command, script, object, ...)."""
    import yaml

    from recon_cli.outputs import atomic_write_text

    data = config.to_dict()
    if extra:
        data["run"] = _plain(extra)
    return atomic_write_text(Path(folder) / "config.yaml", yaml.safe_dump(data, sort_keys=False))
