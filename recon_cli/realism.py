"""Realism profiles: how the simulated cell differs from the model recon works with.

recon plans, reads joints and registers with a *model* of the cell (robot/cell.urdf.xacro
with its nominal arguments, the sensor's nominal pinhole camera). A realism profile makes
the simulated cell (the "true" plant and camera) differ from that model the way a real cell
does; ``ideal`` (the default) makes them equal, as every simulation before the profiles::

    kinematics   encoder zero offsets (constant per session) and noise, elastic sag under
                 gravity (deflection = compliance x gravity torque), robot base pose error,
                 hand-eye error: the true robot is the same xacro with other arguments
    camera       the actual camera's intrinsics and lens distortion; the camera recon is
                 told about (``assumed``: nominal, or a calibration)
    depth        structured-light artefacts: flying pixels at depth edges, dropout at grazing
                 incidence and on dark or saturated surfaces, multipath bias in concave
                 corners, depth quantization
    image        what matters for board detection: exposure, blur, pixel noise

Profiles are YAML files (robot/realism/NAME.yaml for the built-in ones, or any file),
angles in degrees and lengths in millimetres at the edge (the key names say which), SI
units inside. ``extends: NAME`` starts a profile from a built-in one: each key the profile
gives in a section replaces that key of the built-in profile as a whole, the rest is
inherited (``lab`` is ``thesis`` with the cell's own camera). Every number a profile draws
(offsets, error directions, pixel effects) comes from generators spawned from the session's
generator, so a seed gives the same cell and the same images. A profile error is one line
naming ``FILE: key``.

This module is light (numpy, yaml on demand): the configuration imports it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon_cli.errors import InputError, UnknownNameError
from recon_cli.inputs.numbers import described
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import parse_yaml, read_text, shown_key, unknown_key_text
from recon_cli.paths import ROBOT_DIR
from recon_cli.perception.camera_model import Intrinsics

REALISM_DIR = ROBOT_DIR / "realism"
BUILT_IN = ("ideal", "thesis", "lab")
PROFILE_FORMAT = 1
#: the sections of a profile, which ``extends`` merges key by key
SECTIONS = ("kinematics", "camera", "depth", "image")


@dataclass(frozen=True)
class PoseError:
    """A rigid error of fixed size in a random (seeded) direction."""

    translation: float = 0.0  # [m]
    rotation: float = 0.0  # [rad]


@dataclass(frozen=True)
class KinematicErrors:
    """The true robot against the model (kinematics section of a profile)."""

    joint_offset_std: float = 0.0  # [rad] revolute encoder zero offset, drawn once per session
    axis_offset_std: float = 0.0  # [m] prismatic (linear axis) encoder zero offset
    encoder_noise_std: float = 0.0  # [rad] revolute, per reading
    axis_noise_std: float = 0.0  # [m] prismatic, per reading
    stiffness: tuple[tuple[str, float], ...] = ()  # joint -> [N m/rad or N/m]; absent: rigid
    base: PoseError = field(default_factory=PoseError)  # the iiwa base in its mount
    hand_eye: PoseError = field(default_factory=PoseError)  # the optical frame in the flange

    def compliance(self, joint_names) -> list[float]:
        """1 / stiffness per joint (0: rigid) [rad/(N m) or m/N]."""
        k = dict(self.stiffness)
        return [1.0 / k[n] if k.get(n, 0.0) > 0 else 0.0 for n in joint_names]


@dataclass(frozen=True)
class CameraSpec:
    """Pinhole intrinsics [px] at width x height and OpenCV distortion (k1, k2, p1, p2, k3)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int = 1600
    height: int = 1200
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def intrinsics(self, width: int, height: int) -> Intrinsics:
        """The same camera at another image size (pixel centres at integers)."""
        sx, sy = width / self.width, height / self.height
        return Intrinsics(width, height, self.fx * sx, self.fy * sy, (self.cx + 0.5) * sx - 0.5,
                          (self.cy + 0.5) * sy - 0.5)

    @property
    def distorted(self) -> bool:
        return any(v != 0.0 for v in self.distortion)


@dataclass(frozen=True)
class CameraErrors:
    """actual: the camera the images are made with; assumed: the camera recon is told about
    (scan.json; a calibration result goes here). None: the sensor's nominal pinhole."""

    actual: CameraSpec | None = None
    assumed: CameraSpec | None = None


@dataclass(frozen=True)
class DepthArtefacts:
    """Structured-light artefacts of the depth image (see recon_cli/perception/sensor.py)."""

    flying_pixel_share: float = 0.0  # of the pixels at a depth edge, which get a mixed depth
    edge_jump: float = 0.01  # [m] a neighbourhood depth range above this is a depth edge
    grazing: tuple[float, float] | None = None  # [rad] dropout probability 0 at the first, 1 at the second
    dark_level: float = 0.0  # grey level below which returns are lost, most of them at black
    dark_dropout: float = 1.0  # dropout probability at black (grey level 0)
    saturated_level: float = 256.0  # grey level at or above which (specular highlight) nothing returns
    multipath_gain: float = 0.0  # depth bias = gain x how far a point lies behind its neighbourhood
    multipath_window: float = 0.02  # [m] that neighbourhood (and the largest bias counted)
    quantization: float = 0.0  # [m] depth step at the sensor's noise_z_ref (grows with z^2)


@dataclass(frozen=True)
class ImageEffects:
    """The colour image: exposure gain, Gaussian blur and pixel noise."""

    exposure: float = 1.0  # gain on the rendered intensities
    blur_sigma: float = 0.0  # [px at 1600 x 1200]
    noise_std: float | None = None  # [8-bit levels]; None: the sensor's (robot/camera.yaml)


@dataclass(frozen=True)
class RealismProfile:
    name: str = "ideal"
    source: str = ""  # the file it was read from
    kinematics: KinematicErrors = field(default_factory=KinematicErrors)
    camera: CameraErrors = field(default_factory=CameraErrors)
    depth: DepthArtefacts = field(default_factory=DepthArtefacts)
    image: ImageEffects = field(default_factory=ImageEffects)

    @property
    def is_ideal(self) -> bool:
        """No effect at all: the simulation of the model itself."""
        return (self.kinematics == KinematicErrors() and self.camera == CameraErrors()
                and self.depth == DepthArtefacts() and self.image == ImageEffects())

    @property
    def kinematic_errors(self) -> bool:
        return self.kinematics != KinematicErrors()

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def summary(self) -> dict[str, Any]:
        """What session.json records: the name, the file and which effects are on."""
        return {"name": self.name, "source": self.source or None, "ideal": self.is_ideal,
                "kinematics": self.kinematic_errors, "camera": self.camera != CameraErrors(),
                "depth": self.depth != DepthArtefacts(), "image": self.image != ImageEffects()}

    def with_assumed_camera(self, assumed: CameraSpec | None) -> RealismProfile:
        """The same cell, with recon told about another camera (e.g. a calibration)."""
        return dataclasses.replace(self, camera=dataclasses.replace(self.camera, assumed=assumed))


#: the default: the simulated cell is the model (robot/realism/ideal.yaml says the same)
IDEAL = RealismProfile(name="ideal", source="robot/realism/ideal.yaml")


# --------------------------------------------------------------------- loading
def load_profile(name_or_path: str | Path) -> RealismProfile:
    """A built-in profile by name (``ideal``, ``thesis``) or a profile YAML file."""
    text = str(name_or_path)
    if text in BUILT_IN:
        path = REALISM_DIR / f"{text}.yaml"
    else:
        path = Path(text)
        if path.suffix.lower() not in (".yaml", ".yml") and not path.exists():
            raise UnknownNameError("realism profile", text, [*BUILT_IN, "FILE.yaml"])

    raw = read_text(path, "realism profile",
                    hint=f"use {', '.join(BUILT_IN)} or a YAML file (docs/simulation.md)")
    profile = parse_profile(raw, str(path))
    if text in BUILT_IN:  # recorded by name, not by this machine's path
        profile = dataclasses.replace(profile, source=f"robot/realism/{text}.yaml")
    return profile


def parse_profile(text: str, where: str = "<profile>") -> RealismProfile:
    """Parse a profile's YAML text; ``where`` names it in errors."""

    r = _Reader(where)
    d = r.mapping(_profile_data(text, where, ()), "", ("format", "name", *SECTIONS))
    fmt = d.get("format", PROFILE_FORMAT)
    if fmt != PROFILE_FORMAT:
        r.fail("format", f"is {described(fmt) if isinstance(fmt, str) else fmt}, not {PROFILE_FORMAT}",
               "this recon reads profiles of format 1")
    name = str(d.get("name", Path(where).stem))
    return RealismProfile(name=name, source=where, kinematics=_kinematics(r, d.get("kinematics")),
                          camera=_camera(r, d.get("camera")), depth=_depth(r, d.get("depth")),
                          image=_image(r, d.get("image")))


def _profile_data(text: str, where: str, chain: tuple[str, ...]) -> dict:
    """A profile's mapping, checked against the schema, with the built-in profile it
    ``extends`` filled in (``chain``: the built-in profiles already on the way)."""

    data = parse_yaml(text, where)
    check(data, "realism", where)
    own = dict(data) if isinstance(data, dict) else {}
    parent = own.pop("extends", None)
    if parent is None:
        return own
    if parent in chain:  # the built-in profiles are few: this bounds the chain
        _Reader(where).fail("extends", f"comes back to itself ({' -> '.join((*chain, parent))})",
                            "extend a built-in profile that does not extend this one")
    path = REALISM_DIR / f"{parent}.yaml"
    inherited = _profile_data(read_text(path, "realism profile"), str(path), (*chain, str(parent)))
    inherited.pop("name", None)  # the profile's own name, or its file's
    for key, value in own.items():
        if key in SECTIONS and isinstance(inherited.get(key), dict):
            inherited[key] = {**inherited[key], **(value or {})}  # an empty section changes nothing
        else:
            inherited[key] = value
    return inherited


class _Reader:
    """Typed access to a profile's mapping with one-line errors naming ``FILE: key``."""

    def __init__(self, where: str) -> None:
        self.where = where

    def fail(self, key: str, problem: str, hint: str | None = None):
        raise InputError(f"{self.where}: {key} {problem}", hint=hint)

    def mapping(self, value, key: str, known: tuple[str, ...]) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            self.fail(key or "the profile", "is not a mapping", "write 'key: value' lines under it")
        for k in value:
            if k not in known:
                raise InputError(f"{self.where}: " + unknown_key_text(key, k) if key else
                                 f"{self.where}: " + (f"{k} is not a known key" if shown_key(k) is not None
                                                      else "a key is not a known key (nor a plain name)"),
                                 hint=f"known keys: {', '.join(known)}")
        return value

    def number(self, d: dict, key: str, path: str, default: float, lo: float = -math.inf,
               hi: float = math.inf) -> float:
        if key not in d or d[key] is None:
            return default
        v = d[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.fail(f"{path}.{key}", f"is {described(v)}, not a number" if not isinstance(v, float)
                      else f"= {v} is not a finite number")
        if not lo <= v <= hi:
            self.fail(f"{path}.{key}", f"= {v} is outside {lo:g} ... {hi:g}")
        return float(v)

    def numbers(self, d: dict, key: str, path: str, n: int) -> tuple[float, ...] | None:
        if key not in d or d[key] is None:
            return None
        v = d[key]
        if (not isinstance(v, list) or len(v) != n
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v)):
            self.fail(f"{path}.{key}", f"is {described(v)}, not a list of {n} numbers")
        return tuple(float(x) for x in v)


def _pose_error(r: _Reader, value, path: str) -> PoseError:
    d = r.mapping(value, path, ("translation_mm", "rotation_deg"))
    return PoseError(r.number(d, "translation_mm", path, 0.0, 0.0, 100.0) * 1e-3,
                     math.radians(r.number(d, "rotation_deg", path, 0.0, 0.0, 10.0)))


def _kinematics(r: _Reader, value) -> KinematicErrors:
    p = "kinematics"
    d = r.mapping(value, p, ("joint_offset_std_deg", "axis_offset_std_mm", "encoder_noise_std_deg",
                             "axis_noise_std_mm", "joint_stiffness", "base_error", "hand_eye_error"))
    stiff = r.mapping(d.get("joint_stiffness"), f"{p}.joint_stiffness", tuple(d.get("joint_stiffness") or ()))
    stiffness = tuple((str(k), r.number(stiff, k, f"{p}.joint_stiffness", 0.0, 0.0)) for k in stiff)
    for k, v in stiffness:
        if v <= 0:
            r.fail(f"{p}.joint_stiffness.{shown_key(k) or '<key>'}", f"= {v} is not positive",
                   "leave a rigid joint out")
    return KinematicErrors(
        joint_offset_std=math.radians(r.number(d, "joint_offset_std_deg", p, 0.0, 0.0, 5.0)),
        axis_offset_std=r.number(d, "axis_offset_std_mm", p, 0.0, 0.0, 100.0) * 1e-3,
        encoder_noise_std=math.radians(r.number(d, "encoder_noise_std_deg", p, 0.0, 0.0, 1.0)),
        axis_noise_std=r.number(d, "axis_noise_std_mm", p, 0.0, 0.0, 10.0) * 1e-3,
        stiffness=stiffness, base=_pose_error(r, d.get("base_error"), f"{p}.base_error"),
        hand_eye=_pose_error(r, d.get("hand_eye_error"), f"{p}.hand_eye_error"))


def _camera_spec(r: _Reader, value, path: str) -> CameraSpec | None:
    if value is None or value == "nominal":
        return None
    d = r.mapping(value, path, ("fx", "fy", "cx", "cy", "width", "height", "distortion"))
    for key in ("fx", "fy", "cx", "cy"):
        if key not in d:
            r.fail(f"{path}.{key}", "is missing", "give fx, fy, cx, cy [px] (and width, height), or 'nominal'")
    width = int(r.number(d, "width", path, 1600, 1, 65535))
    height = int(r.number(d, "height", path, 1200, 1, 65535))
    dist = d.get("distortion")
    if dist is not None and (not isinstance(dist, list) or len(dist) not in (4, 5)):
        r.fail(f"{path}.distortion", f"is {described(dist)}, not [k1, k2, p1, p2] or [k1, k2, p1, p2, k3]")
    coeffs: tuple[float, ...] = ()
    if dist is not None:
        coeffs = r.numbers({"distortion": dist}, "distortion", path, len(dist)) or ()
    coeffs = coeffs + (0.0,) * (5 - len(coeffs))
    return CameraSpec(r.number(d, "fx", path, 0.0, 1.0), r.number(d, "fy", path, 0.0, 1.0),
                      r.number(d, "cx", path, 0.0), r.number(d, "cy", path, 0.0), width, height, coeffs)


def _camera(r: _Reader, value) -> CameraErrors:
    d = r.mapping(value, "camera", ("actual", "assumed"))
    return CameraErrors(_camera_spec(r, d.get("actual"), "camera.actual"),
                        _camera_spec(r, d.get("assumed"), "camera.assumed"))


def _depth(r: _Reader, value) -> DepthArtefacts:
    p = "depth"
    d = r.mapping(value, p, ("flying_pixel_share", "edge_jump_mm", "grazing_dropout_deg", "dark_level",
                             "dark_dropout", "saturated_level", "multipath_gain", "multipath_window_mm",
                             "quantization_mm"))
    grazing = r.numbers(d, "grazing_dropout_deg", p, 2)
    if grazing is not None and not 0.0 <= grazing[0] < grazing[1] <= 90.0:
        r.fail(f"{p}.grazing_dropout_deg", f"= {list(grazing)} is not two increasing angles in 0 ... 90")
    return DepthArtefacts(
        flying_pixel_share=r.number(d, "flying_pixel_share", p, 0.0, 0.0, 1.0),
        edge_jump=r.number(d, "edge_jump_mm", p, 10.0, 0.1, 1000.0) * 1e-3,
        grazing=None if grazing is None else (math.radians(grazing[0]), math.radians(grazing[1])),
        dark_level=r.number(d, "dark_level", p, 0.0, 0.0, 255.0),
        dark_dropout=r.number(d, "dark_dropout", p, 1.0, 0.0, 1.0),
        saturated_level=r.number(d, "saturated_level", p, 256.0, 1.0, 256.0),
        multipath_gain=r.number(d, "multipath_gain", p, 0.0, 0.0, 1.0),
        multipath_window=r.number(d, "multipath_window_mm", p, 20.0, 1.0, 200.0) * 1e-3,
        quantization=r.number(d, "quantization_mm", p, 0.0, 0.0, 10.0) * 1e-3)


def _image(r: _Reader, value) -> ImageEffects:
    p = "image"
    d = r.mapping(value, p, ("exposure", "blur_sigma_px", "noise_std"))
    noise = d.get("noise_std")
    return ImageEffects(exposure=r.number(d, "exposure", p, 1.0, 0.05, 20.0),
                        blur_sigma=r.number(d, "blur_sigma_px", p, 0.0, 0.0, 20.0),
                        noise_std=None if noise is None else r.number(d, "noise_std", p, 0.0, 0.0, 100.0))
