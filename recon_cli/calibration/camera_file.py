"""A calibrated camera (pinhole intrinsics and lens distortion) and its YAML file.

The file is what ``recon calibrate intrinsics`` writes and what ``recon calibrate handeye
--camera-file`` (and a realism profile's ``camera.assumed``) reads::

    format: 1
    camera:              # exactly the keys of a realism profile's camera.assumed
      width: 1600        # [px] the image size the numbers belong to
      height: 1200
      fx: 1738.93        # [px]
      fy: 1739.91
      cx: 799.59
      cy: 602.95
      distortion: [k1, k2, p1, p2, k3]   # OpenCV's model
    calibration: {...}   # how it was obtained (RMS, views, ...); informational

Other image sizes of the same camera scale the numbers (pixel centres at integers).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from recon_cli.errors import InputError
from recon_cli.inputs.numbers import described
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import line_of, plain, read_yaml, unknown_key_text
from recon_cli.outputs import atomic_write_text
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.realism import BUILT_IN, REALISM_DIR, CameraSpec, parse_profile
from recon_cli.serialization import to_jsonable

CAMERA_FILE_FORMAT = 1
CAMERA_KEYS = ("width", "height", "fx", "fy", "cx", "cy", "distortion")


@dataclass(frozen=True)
class CameraCalibration:
    """Intrinsics [px] and OpenCV distortion coefficients (k1, k2, p1, p2, k3)."""

    intrinsics: Intrinsics
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def distortion_array(self) -> np.ndarray:
        return np.asarray(self.distortion, dtype=np.float64)

    def at_size(self, width: int, height: int) -> CameraCalibration:
        """The same camera at another image size (a resized image; distortion unchanged,
        being a function of normalized coordinates)."""
        K = self.intrinsics
        if (width, height) == (K.width, K.height):
            return self
        sx, sy = width / K.width, height / K.height
        return CameraCalibration(Intrinsics(width, height, K.fx * sx, K.fy * sy, (K.cx + 0.5) * sx - 0.5,
                                            (K.cy + 0.5) * sy - 0.5), self.distortion)

    def to_mapping(self) -> dict:
        K = self.intrinsics
        return {"width": K.width, "height": K.height, "fx": float(K.fx), "fy": float(K.fy), "cx": float(K.cx),
                "cy": float(K.cy), "distortion": [float(v) for v in self.distortion]}

    @classmethod
    def from_mapping(cls, d, where: str) -> CameraCalibration:
        if not isinstance(d, dict):
            raise InputError(f"{where} is not a mapping", hint=f"give {', '.join(CAMERA_KEYS)}")
        for key in d:
            if key not in CAMERA_KEYS:
                raise InputError(unknown_key_text(where, key), hint=f"known keys: {', '.join(CAMERA_KEYS)}")
        values = {}
        for key in CAMERA_KEYS[:6]:
            v = d.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                shown = f"{v:g}" if isinstance(v, int | float) and not isinstance(v, bool) else described(v)
                raise InputError(f"{where}.{key} is {shown}, not a positive number",
                                 hint="width, height, fx, fy, cx, cy in pixels")
            values[key] = v
        dist = d.get("distortion", [0.0] * 5)
        if (not isinstance(dist, list) or len(dist) not in (4, 5)
                or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                           for x in dist)):
            raise InputError(f"{where}.distortion is {described(dist)}, not [k1, k2, p1, p2] or [k1, k2, p1, p2, k3] "
                             "(finite numbers)")
        dist = [float(x) for x in dist] + [0.0] * (5 - len(dist))
        K = Intrinsics(int(values["width"]), int(values["height"]), float(values["fx"]), float(values["fy"]),
                       float(values["cx"]), float(values["cy"]))
        return cls(K, tuple(dist))

    def to_camera_spec(self):
        """The realism profile's CameraSpec (recon_cli.realism) of this camera."""

        K = self.intrinsics
        return CameraSpec(K.fx, K.fy, K.cx, K.cy, K.width, K.height, tuple(self.distortion))


def camera_file_text(camera: CameraCalibration, calibration: dict | None = None, comment: str = "") -> str:



    head = "".join(f"# {line}\n" for line in comment.splitlines()) if comment else ""
    body = {"format": CAMERA_FILE_FORMAT, "camera": camera.to_mapping()}
    if calibration:
        body["calibration"] = json.loads(json.dumps(calibration, default=to_jsonable))  # plain types
    return head + yaml.safe_dump(body, sort_keys=False)


def write_camera_file(path: Path, camera: CameraCalibration, calibration: dict | None = None,
                      comment: str = "") -> Path:

    return atomic_write_text(Path(path), camera_file_text(camera, calibration, comment))


def load_camera_file(path: Path) -> CameraCalibration:
    """Read a camera file (see the module docstring); errors name ``FILE: key``."""

    path = Path(path)
    data = read_yaml(path, "camera file", hint="write one with recon calibrate intrinsics (its intrinsics.yaml)")
    if not isinstance(data, dict):  # named by its kind: a message never shows what a file holds
        kind = "nothing" if data is None else "a list" if isinstance(data, list) else "a text or a number"
        raise InputError(f"{path}: the camera file holds {kind}, not a mapping (key: value lines)",
                         hint="write one with recon calibrate intrinsics (its intrinsics.yaml)")
    check(data, "camera", path)
    line = line_of(data, "camera")
    return CameraCalibration.from_mapping(data["camera"], f"{path}:{line}: camera" if line else f"{path}: camera")


def write_calibrated_profile(profile: str | Path, camera: CameraCalibration, path: Path) -> Path:
    """A copy of a realism profile (built-in name or YAML file) whose ``camera.assumed`` is
    this camera: simulated sessions run with it (``--realism path``) detect and back-project
    with the calibration instead of the nominal camera."""


    source = REALISM_DIR / f"{profile}.yaml" if str(profile) in BUILT_IN else Path(profile)
    data = plain(read_yaml(source, "realism profile", hint=f"give {', '.join(BUILT_IN)} or a profile YAML file")) or {}
    if not isinstance(data, dict):
        raise InputError(f"{source}: the profile is not a mapping", hint="see docs/simulation.md")
    camera_section = data.get("camera")
    if not isinstance(camera_section, dict):
        camera_section = {}
    data["camera"] = {**camera_section, "assumed": camera.to_mapping()}
    data["name"] = f"{data.get('name', source.stem)}, calibrated camera"
    text = (f"# {source.name} with camera.assumed from recon calibrate intrinsics (the rest as in the source;\n"
            "# its comments, with the source of each number, are in the source file)\n"
            + yaml.safe_dump(data, sort_keys=False))
    parse_profile(text, str(path))  # it must be a valid profile
    return atomic_write_text(Path(path), text)

