"""Expanding the cell's xacro description (robot/cell.urdf.xacro) into URDF text.

The one description feeds every consumer: pinocchio (kinematics, dynamics), the FCL
collision model and the MuJoCo scene. Expansion is cached per process, keyed by the
arguments and the content of every file under robot/.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import math
from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from recon_cli.errors import InputError, UnknownNameError
from recon_cli.paths import ROBOT_DIR

CELL_XACRO = ROBOT_DIR / "cell.urdf.xacro"

#: the thesis planned with a 3 cm safety distance (MoveIt planning context, CELL_FACTS 3.4)
DEFAULT_SAFETY_DISTANCE = 0.03
#: [m] the camera bracket frame camera_link_0 above the flange (robot/parts/camera.xacro)
BRACKET_HEIGHT = 0.0723


class CellKind(StrEnum):
    """The two cells of the thesis."""

    GANTRY = "gantry"  #: 9 DoF: two linear axes + iiwa (Figures 1.1, 2.7)
    CEILING = "ceiling"  #: 7 DoF: iiwa fixed under the roof (section 5.1)

    @classmethod
    def parse(cls, name: str) -> CellKind:
        aliases = {"9dof": cls.GANTRY, "7dof": cls.CEILING}
        key = str(name).strip().lower()
        if key in aliases:
            return aliases[key]
        try:
            return cls(key)
        except ValueError:
            raise UnknownNameError(
                "cell", name, [c.value for c in cls] + list(aliases)
            ) from None


@dataclass(frozen=True)
class CellConfig:
    """Arguments of the cell description.

    kind: which cell
    safety_distance: inflation of every collision shape [m] (thesis 2.2.4)
    table_lift: extension of the telescoping table [m]
    ceiling_xy: base position of the ceiling cell in the world [m]
    flange_T_camera: hand-eye transform, the camera's optical frame in the flange (arm_link_7)
        frame, 16 numbers row by row [m]; None: the thesis' calibration in the description
    mount_T_base: the iiwa base (arm_link_0) in its mount (gantry carriage or ceiling plate),
        16 numbers row by row [m]; None: the nominal mount of the description (a realism
        profile gives the simulated robot another one: base pose error)
    """

    kind: CellKind = CellKind.GANTRY
    safety_distance: float = DEFAULT_SAFETY_DISTANCE
    table_lift: float = 0.0
    ceiling_xy: tuple[float, float] = (0.0, 0.0)
    flange_T_camera: tuple[float, ...] | None = None
    mount_T_base: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.mount_T_base is not None:
            object.__setattr__(self, "mount_T_base", _rigid(self.mount_T_base, "the robot base pose mount_T_base"))
        if self.flange_T_camera is not None:
            object.__setattr__(self, "flange_T_camera",
                               _rigid(self.flange_T_camera, "the hand-eye transform flange_T_camera"))
        if not isinstance(self.kind, CellKind):
            object.__setattr__(self, "kind", CellKind.parse(self.kind))
        if not (math.isfinite(self.safety_distance) and 0.0 <= self.safety_distance <= 0.2):
            raise InputError(
                f"safety distance {self.safety_distance} m is outside 0 ... 0.2 m",
                hint="give it in metres, e.g. 0.03",
            )
        if not (math.isfinite(self.table_lift) and 0.0 <= self.table_lift <= 0.65):
            raise InputError(
                f"table lift {self.table_lift} m is outside the table's 0 ... 0.65 m",
                hint="give it in metres",
            )

    def xacro_args(self) -> dict[str, str]:
        return {
            "cell": self.kind.value,
            "sd": repr(float(self.safety_distance)),
            "table_lift": repr(float(self.table_lift)),
            "ceiling_x": repr(float(self.ceiling_xy[0])),
            "ceiling_y": repr(float(self.ceiling_xy[1])),
            **self._camera_args(),
            **self._base_args(),
        }

    def _base_args(self) -> dict[str, str]:
        """The iiwa base in its mount (only when it differs from the description's)."""
        if self.mount_T_base is None:
            return {}
        from scipy.spatial.transform import Rotation

        m = self.mount_T_base
        rpy = Rotation.from_matrix([m[0:3], m[4:7], m[8:11]]).as_euler("xyz")
        return {"base_xyz": " ".join(repr(float(v)) for v in (m[3], m[7], m[11])),
                "base_rpy": " ".join(repr(float(v)) for v in rpy)}

    def _camera_args(self) -> dict[str, str]:
        """The optical frame in the camera bracket frame (BRACKET_HEIGHT above the flange)."""
        if self.flange_T_camera is None:
            return {}
        from scipy.spatial.transform import Rotation

        m = self.flange_T_camera
        R = [m[0:3], m[4:7], m[8:11]]
        xyz = (m[3], m[7], m[11] - BRACKET_HEIGHT)
        rpy = Rotation.from_matrix(R).as_euler("xyz")  # fixed axes x, y, z: URDF's rpy
        return {"camera_xyz": " ".join(repr(float(v)) for v in xyz),
                "camera_rpy": " ".join(repr(float(v)) for v in rpy)}


#: largest |R^T R - I| entry a given rotation may have: 5 decimals written by hand are
#: off by about 1e-5; the rotation used is then the nearest true one
RIGID_TOLERANCE = 1e-4
#: below this the rotation is taken as written (calibration output, 9 decimals)
_EXACT = 1e-9


def _rigid(values: Iterable[float], what: str) -> tuple[float, ...]:
    """16 numbers of a rigid 4 x 4 transform (row by row), or a one-line InputError. A
    rotation orthonormal within :data:`RIGID_TOLERANCE` is replaced by the nearest rotation
    (polar decomposition), so that a matrix written with 5 decimals is accepted."""

    m = [float(v) for v in values]
    ok = len(m) == 16 and all(math.isfinite(v) for v in m) and m[12:] == [0.0, 0.0, 0.0, 1.0]
    if ok:
        R = np.array([m[0:3], m[4:7], m[8:11]])
        error = float(np.max(np.abs(R.T @ R - np.eye(3))))
        ok = error <= RIGID_TOLERANCE and float(np.linalg.det(R)) > 0  # a mirror is orthonormal too, but no pose
        if ok and error > _EXACT:
            u, _, vt = np.linalg.svd(R)
            R = u @ vt
            for i in range(3):
                m[4 * i: 4 * i + 3] = [float(v) for v in R[i]]
    if not ok:
        raise InputError(f"{what} is not a rigid 4 x 4 transform",
                         hint=f"give 16 numbers row by row with a rotation (orthonormal within {RIGID_TOLERANCE:g}, "
                              "determinant +1) and 0 0 0 1 last")
    return tuple(m)


def _robot_dir_digest() -> str:
    h = hashlib.sha256()
    for path in sorted(ROBOT_DIR.rglob("*")):
        if path.is_file() and path.suffix in {".xacro", ".yaml", ".urdf"}:
            h.update(str(path.relative_to(ROBOT_DIR)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def expand_urdf(config: CellConfig = CellConfig()) -> str:  # noqa: B008 (frozen)
    """URDF text of the cell for the given arguments."""
    return _expand(tuple(sorted(config.xacro_args().items())), _robot_dir_digest())


@functools.lru_cache(maxsize=16)
def _expand(args: tuple[tuple[str, str], ...], digest: str) -> str:
    import xacro

    # xacro reports harmless notes on stderr; keep library output quiet
    with contextlib.redirect_stderr(io.StringIO()):
        doc = xacro.process_file(str(CELL_XACRO), mappings=dict(args))
    text: str = doc.toprettyxml(indent="  ")
    return text
