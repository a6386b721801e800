"""A hand-eye data set made by anyone: board images and the robot pose of each image, in the
forms people log them (docs/calibration.md, "Calibrating from your own data").

Where the poses are (:func:`read_dataset`; the first that applies):

    an index file        a YAML/JSON list of {image, pose} pairs (``data:``), the pose a file
                         or inline values, e.g. ros-industrial's cal_data.yaml (its
                         ``intrinsics``, ``target_finder`` and ``static_camera`` are read too)
    one CSV file         a row per image, a column naming the image
    one file per image   poses/3.yaml (or .yml, .json) for images/3.png, matched by stem, or
                         side by side (0001.png beside 0001.json)
    a folder per view    pose_00/{image.png, data.json}, ... in natural order

The camera (:func:`view_camera`): each pose file's intrinsics and distortion by key (K,
camera_matrix, intrinsics, camera_intrinsics, ...; D, dist_coeffs, ...), else a camera file at
the top of the data set (intrinsics.yaml, camera_info.json, ...).

What a pose is (:class:`PoseMapping`, from a mapping file, CLI options or the keys of the
first pose): joint positions (forward kinematics of a cell to its flange), a 4x4 matrix
(row- or column-major: libfranka's O_T_EE is column-major), xyz + quaternion (xyzw or wxyz)
or xyz + roll-pitch-yaw (URDF's: R = Rz(yaw) Ry(pitch) Rx(roll)); lengths in m or mm,
angles in rad or deg. Every pose becomes ``base_T_flange`` (4, 4) [m].

A view that cannot be used (no pose file, no board in the image, a quaternion that is not
normalised, a translation that looks like millimetres when the mapping says metres, ...) is
skipped with one line naming its file and what to do; the others still calibrate.

Every file the data set names (images, pose files, the index, a mapping's board file) must
lie inside the data set folder, links resolved, before it is read; the number of views,
image and pose files and the bytes of every file are bounded before they are read; every
number is checked finite and inside its range where it is read, with its key path; no
message shows what a file holds (its values or text), only where and what was expected.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from enum import StrEnum
from pathlib import Path, PurePath
from typing import Any

import numpy as np
import yaml

from recon_cli.calibration.camera_file import CameraCalibration
from recon_cli.calibration.intrinsics import SkippedImage
from recon_cli.calibration.setups import CornerView, Setup
from recon_cli.errors import FileError, InputError, ReconError
from recon_cli.geometry.transforms import invert, rpy_to_matrix
from recon_cli.inputs import files
from recon_cli.inputs.images import native_output_captured, read_color
from recon_cli.inputs.jsonfile import load_json
from recon_cli.inputs.numbers import in_range
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import LIMITS, line_of, read_yaml
from recon_cli.perception.boards import BOARD_KINDS, Board, BoardMissing, find_pose, parse_board
from recon_cli.perception.camera_model import Intrinsics
from recon_cli.perception.charuco import BoardSpec

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
POSE_SUFFIXES = (".yaml", ".yml", ".json")
#: columns that name the image in a CSV file, when the mapping names none
IMAGE_COLUMNS = ("image", "image_file", "filename", "file", "img", "name")
#: bytes of one pose file (libfranka's whole robot state is about 6 kB), of all pose files of a
#: data set together, of the index and of a CSV file
MAX_POSE_BYTES = 64 * 2**10
MAX_POSES_BYTES = 16 * 2**20
MAX_INDEX_BYTES = 1_000_000
MAX_CSV_BYTES = 16 * 2**20
#: values (numbers, texts, lists, mappings) of one YAML pose file
MAX_POSE_VALUES = 2_000
#: columns of a CSV file
MAX_CSV_COLUMNS = 1_000
#: views (image and pose pairs) in one data set; image files and pose files of a folder
MAX_VIEWS = 1_000
#: entries of one folder of the data set, counted before any is looked at
MAX_FOLDER_ENTRIES = 100_000
#: YAML/JSON files at the top of a data set folder looked into for an index
MAX_TOP_FILES = 20
#: characters of a file name an index or CSV file gives
MAX_NAME = 4_096
#: numbers of one key (a 4x4 matrix is 16, a robot's joints fewer than 64)
MAX_NUMBERS = 64
#: [m] a robot pose further from the base than this is not in metres
MAX_TRANSLATION = 10.0
#: a quaternion whose norm is off 1 by more than this is refused; less is normalised
QUATERNION_TOLERANCE = 1e-3
#: largest |R^T R - I| of a matrix's rotation part that is orthonormalised, not refused
ROTATION_TOLERANCE = 1e-3
#: [rad] an angle beyond this, in a mapping that says radians, is in degrees
MAX_RADIANS = 2 * math.pi + 1e-6
#: [deg] an angle beyond this, in a mapping that says degrees, is refused
MAX_DEGREES = 360.0 + 1e-6
#: [px] focal lengths and principal point of an index file's intrinsics (as the mapping's camera)
FOCAL_RANGE = (1.0, 100_000.0)
CENTRE_RANGE = (-100_000.0, 100_000.0)
#: distortion coefficients of an index file's intrinsics: at most 5 (k1, k2, p1, p2, k3), each in
DISTORTION_RANGE = (-100.0, 100.0)
MIN_CORNERS = 8
MAPPING_HINT = "see docs/calibration.md, Calibrating from your own data"


class PoseFormat(StrEnum):
    """What a robot pose of the data set is."""

    XYZ_QUAT = "xyz-quat"  #: position and a unit quaternion
    XYZ_RPY = "xyz-rpy"  #: position and roll, pitch, yaw (URDF's fixed axes x, y, z)
    MATRIX = "matrix"  #: a 4x4 homogeneous matrix (16 numbers)
    JOINTS = "joints"  #: joint positions: the flange by forward kinematics of the cell


class LengthUnit(StrEnum):
    M = "m"
    MM = "mm"

    @property
    def metres(self) -> float:
        return 1.0 if self is LengthUnit.M else 1e-3


class AngleUnit(StrEnum):
    RAD = "rad"
    DEG = "deg"

    @property
    def radians(self) -> float:
        return 1.0 if self is AngleUnit.RAD else math.pi / 180.0


class QuaternionOrder(StrEnum):
    XYZW = "xyzw"  #: ROS, Eigen's coeffs(), scipy
    WXYZ = "wxyz"  #: Eigen's constructor, MuJoCo, many robot controllers


class MatrixOrder(StrEnum):
    ROW = "row"  #: 16 numbers row by row (numpy, most logs)
    COLUMN = "column"  #: column by column (libfranka's O_T_EE, OpenGL, Eigen's data())


#: (field, its enum) of the mapping's choices, for parsing from text
_CHOICES: dict[str, type[StrEnum]] = {"pose_format": PoseFormat, "length_unit": LengthUnit, "angle_unit": AngleUnit,
                                      "quaternion_order": QuaternionOrder, "matrix_order": MatrixOrder}


@dataclass(frozen=True)
class PoseMapping:
    """Which key of a pose holds what, and its units. A key is a name (``x``), a dotted path
    into nested values (``position.x``) or a CSV column; one key may hold all the numbers as
    a list (``t: [x, y, z]``). pose_format None: told by the keys of the first pose."""

    pose_format: PoseFormat | None = None
    position: tuple[str, ...] = ("x", "y", "z")
    quaternion: tuple[str, ...] | None = None  # None: qx, qy, qz, qw in quaternion_order's sequence
    quaternion_order: QuaternionOrder = QuaternionOrder.XYZW
    rpy: tuple[str, ...] = ("roll", "pitch", "yaw")
    matrix: tuple[str, ...] = ("matrix",)
    matrix_order: MatrixOrder | None = None  # None: told by where the numbers put [0, 0, 0, 1]
    joints: tuple[str, ...] = ("joints",)
    length_unit: LengthUnit = LengthUnit.M
    angle_unit: AngleUnit = AngleUnit.RAD

    @property
    def quaternion_keys(self) -> tuple[str, ...]:
        if self.quaternion is not None:
            return self.quaternion
        return tuple(f"q{c}" for c in self.quaternion_order.value)

    def keys(self) -> dict[str, tuple[str, ...]]:
        """The keys this mapping reads, by what they hold."""
        f = self.pose_format
        if f is PoseFormat.XYZ_QUAT:
            return {"position": self.position, "quaternion": self.quaternion_keys}
        if f is PoseFormat.XYZ_RPY:
            return {"position": self.position, "rpy": self.rpy}
        if f is PoseFormat.MATRIX:
            return {"matrix": self.matrix}
        if f is PoseFormat.JOINTS:
            return {"joints": self.joints}
        return {}

    def overridden(self, **values: Any) -> PoseMapping:
        """This mapping with the values that are not None (CLI options over the mapping file)."""
        return replace(self, **{k: v for k, v in values.items() if v is not None})

    def to_dict(self) -> dict:
        out: dict[str, Any] = {"pose_format": None if self.pose_format is None else self.pose_format.value}
        out.update({k: list(v) for k, v in self.keys().items()})
        if self.pose_format is PoseFormat.XYZ_QUAT:
            out["quaternion_order"] = self.quaternion_order.value
        if self.pose_format is PoseFormat.MATRIX:
            out["matrix_order"] = "told by the numbers" if self.matrix_order is None else self.matrix_order.value
        out["length_unit"], out["angle_unit"] = self.length_unit.value, self.angle_unit.value
        return out


def parse_choice(kind: str, value: str) -> StrEnum:
    """A mapping choice (``pose_format``, ``length_unit``, ...) from text."""
    enum = _CHOICES[kind]
    try:
        return enum(str(value).strip().lower())
    except ValueError:
        raise InputError(f"{kind} {value!r} is not one of {', '.join(m.value for m in enum)}",
                         hint=MAPPING_HINT) from None


@dataclass(frozen=True)
class CameraNumbers:
    """Intrinsics [px] and distortion (k1, k2, p1, p2, k3) given without an image size: those
    of the images as they are."""

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def at_size(self, width: int, height: int) -> CameraCalibration:
        return CameraCalibration(Intrinsics(width, height, self.fx, self.fy, self.cx, self.cy), self.distortion)


CameraSource = CameraCalibration | CameraNumbers
#: how many numbers a camera given on the command line takes: fx, fy, cx, cy [+ k1, k2, p1, p2 [+ k3]]
CAMERA_NUMBER_COUNTS = (4, 8, 9)
CAMERA_NUMBERS_HINT = "give fx,fy,cx,cy in pixels, or fx,fy,cx,cy,k1,k2,p1,p2[,k3] with OpenCV's distortion"


def parse_camera_numbers(text: str, what: str = "--intrinsics") -> tuple[float, ...]:
    """The 4, 8 or 9 comma-separated numbers of a camera given as text (fx,fy,cx,cy[,k1,k2,p1,
    p2[,k3]]), each finite; one line naming ``what`` (not the text) otherwise."""
    parts = [p.strip() for p in str(text).replace(";", ",").split(",") if p.strip()]
    if len(parts) not in CAMERA_NUMBER_COUNTS:
        raise InputError(f"{what}: {len(parts)} numbers, {', '.join(map(str, CAMERA_NUMBER_COUNTS[:-1]))} or "
                         f"{CAMERA_NUMBER_COUNTS[-1]} expected", hint=CAMERA_NUMBERS_HINT)
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
    values = []
    for part, name in zip(parts, names, strict=False):
        try:
            x = float(part)
        except ValueError:
            raise InputError(f"{what}: {name} is not a number", hint=CAMERA_NUMBERS_HINT) from None
        if not math.isfinite(x):
            raise InputError(f"{what}: {name} is not a finite number", hint=CAMERA_NUMBERS_HINT)
        values.append(x)
    camera_numbers(values, what)  # ranges
    return tuple(values)


def camera_numbers(values: Any, what: str = "--intrinsics") -> CameraNumbers:
    """A camera of 4, 8 or 9 numbers: fx, fy, cx, cy [px], then k1, k2, p1, p2[, k3]; each in
    its range, one line naming ``what`` and the number otherwise."""
    values = list(values)
    if len(values) not in CAMERA_NUMBER_COUNTS:
        raise InputError(f"{what}: {len(values)} numbers, {', '.join(map(str, CAMERA_NUMBER_COUNTS[:-1]))} or "
                         f"{CAMERA_NUMBER_COUNTS[-1]} expected", hint=CAMERA_NUMBERS_HINT)
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
    out = [in_range(v, f"{what} {name}", *(FOCAL_RANGE if k < 2 else CENTRE_RANGE if k < 4 else DISTORTION_RANGE),
                    unit="px" if k < 4 else "", hint=CAMERA_NUMBERS_HINT)
           for k, (v, name) in enumerate(zip(values, names, strict=False))]
    return CameraNumbers(out[0], out[1], out[2], out[3], tuple((out[4:] + [0.0] * 5)[:5]))


@dataclass(frozen=True)
class DatasetSpec:
    """What a mapping file says (every field optional; docs/calibration.md).

    images, poses, index: paths inside the data set folder (a folder of images; a folder of
        pose files or a CSV file; an index file)
    image_column: the CSV column that names the image
    intrinsics_key, distortion_key: the keys (dotted paths) of each pose file that hold the
        camera's intrinsics and distortion; None: the usual names (INTRINSICS_KEYS, DISTORTION_KEYS)
    """

    mapping: PoseMapping = field(default_factory=PoseMapping)
    setup: Setup | None = None
    images: str | None = None
    poses: str | None = None
    index: str | None = None
    image_column: str | None = None
    board: Board | None = None
    camera: CameraNumbers | None = None
    source: Path | None = None  # the mapping file
    intrinsics_key: str | None = None  # the key of each pose file holding the intrinsics
    distortion_key: str | None = None  # the key of each pose file holding the distortion


def _keys(value: Any) -> tuple[str, ...]:
    return (str(value),) if isinstance(value, str) else tuple(str(v) for v in value)


def read_mapping(path: Path, dataset: Path | None = None) -> DatasetSpec:
    """Read and check a mapping file (schemas/handeye_dataset.schema.json). A board file it
    names lies inside the data set folder (``dataset``; without it, the mapping's folder),
    links resolved; it is checked before it is read."""
    path = Path(path)
    _not_leaving_its_folder(path, "mapping file", MAPPING_HINT)
    doc = _read_doc(path, "mapping file", LIMITS.max_bytes, MAPPING_HINT)
    if doc is None:
        return DatasetSpec(source=path)
    if not isinstance(doc, dict):
        raise InputError(f"{path}: the mapping file holds {_kind(doc)}, not a mapping (key: value lines)",
                         hint=MAPPING_HINT)
    check(doc, "handeye_dataset", path)
    values: dict[str, Any] = {}
    for f in fields(PoseMapping):
        if f.name not in doc:
            continue
        v = doc[f.name]
        values[f.name] = _CHOICES[f.name](v) if f.name in _CHOICES else _keys(v)
    board = None
    if "board" in doc:
        b = doc["board"]
        where = f"{path}:{line_of(doc, 'board') or 1}"
        if isinstance(b, str) and b.partition(":")[0].strip().lower() in BOARD_KINDS:
            board = parse_board(b, f"{where}: board")  # the --board-spec syntax, e.g. chessboard:9x6,0.025
        elif isinstance(b, str):
            if dataset is None:
                root = path.parent.resolve()
            else:
                root = (Path(dataset) if Path(dataset).is_dir() else Path(dataset).parent).resolve()
            board_path = _inside(root, path.parent, b, f"{where}: board")
            doc_b = _read_doc(board_path, "board file", LIMITS.max_bytes, "give the board's keys in the mapping")
            if not isinstance(doc_b, dict):
                raise InputError(f"{board_path}: the board file holds {_kind(doc_b)}, not a mapping (key: value "
                                 "lines)", hint="a board file holds squares_x, squares_y, square_length, "
                                                "marker_length and dictionary")
            board = _board(doc_b, board_path, f"{board_path}:{line_of(doc_b, 'marker_length') or 1}: ")
        else:
            board = _board(b, path, f"{where}: board.")
    camera = None
    if "camera" in doc:
        c = doc["camera"]
        dist = [float(x) for x in c.get("distortion", [])]
        camera = CameraNumbers(float(c["fx"]), float(c["fy"]), float(c["cx"]), float(c["cy"]),
                               tuple(dist + [0.0] * (5 - len(dist))))
    return DatasetSpec(PoseMapping(**values), Setup(doc["setup"]) if "setup" in doc else None,
                       doc.get("images"), doc.get("poses"), doc.get("index"), doc.get("image_column"), board, camera,
                       path, doc.get("intrinsics_key"), doc.get("distortion_key"))


def _board(b: dict, path: Path, where: str) -> BoardSpec:
    """A board of a board file's keys (schemas/board.schema.json), the marker smaller than
    the square; ``where`` prefixes the key in a refusal."""
    check(b, "board", path)
    if float(b["marker_length"]) >= float(b["square_length"]):
        raise InputError(f"{where}marker_length is not smaller than square_length",
                         hint="a ChArUco marker sits inside its square")
    return BoardSpec(int(b["squares_x"]), int(b["squares_y"]), float(b["square_length"]),
                     float(b["marker_length"]), str(b["dictionary"]), bool(b.get("legacy", False)))


def _kind(value: Any) -> str:
    """What a value is, in words (a message names the kind, never the value a file holds)."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a text"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return "a value"


def _not_leaving_its_folder(path: Path, what: str, hint: str) -> None:
    """Refuse a file given on the command line that is a link leading out of its own folder,
    before it is read."""
    try:
        target = path.resolve(strict=True)
    except (OSError, RuntimeError, ValueError):
        raise FileError(f"{what} {path} does not exist", hint=hint) from None
    if not target.is_relative_to(path.parent.resolve()):
        raise InputError(f"{path}: the {what} is a link leading out of its folder; not read",
                         hint="copy the file into the folder instead of linking it")


def _read_doc(path: Path, what: str, max_bytes: int, hint: str = "check the data set", max_values: int | None = None
              ) -> Any:
    """A YAML or JSON file (by its suffix) through the guarded readers; a number that is not
    finite is refused with its key path (``poses/3.json:1: O_T_EE[5] is not a finite number``)."""
    is_json = path.suffix.lower() == ".json"
    try:
        if is_json:
            return load_json(path, what, max_bytes=max_bytes)
        limits = replace(LIMITS, max_bytes=max_bytes, max_nodes=max_values or LIMITS.max_nodes)
        return read_yaml(path, what, hint=hint, limits=limits)
    except ReconError as exc:
        if "finite number" not in exc.message and "too large for a number" not in exc.message:
            raise
        found = _non_finite_key(path, is_json, max_bytes)
        if found is None:
            raise
        key, line = found
        if line is None:
            m = re.search(r"(\d+)", str(getattr(exc, "where", None) or ""))
            line = int(m.group(1)) if m else None
        raise InputError(f"{path}{f':{line}' if line else ''}: {key} is not a finite number",
                         hint="write a finite number (NaN and infinity are not numbers)") from None


_NON_FINITE = re.compile(r"^[-+]?(\.inf|\.nan|[0-9][0-9_]*(\.[0-9_]*)?[eE][-+]?[0-9]+|\.[0-9_]+[eE][-+]?[0-9]+)$",
                         re.IGNORECASE)


def _non_finite_key(path: Path, is_json: bool, max_bytes: int) -> tuple[str, int | None] | None:
    """The key path (and line) of the first number that is not finite in a file a guarded
    reader refused for it (so its size, nesting, aliases and tags have passed the reader's
    checks), or None."""
    def key_path(at: list) -> str:
        return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" if i else str(k) for i, k in enumerate(at))

    try:
        text = files.read_limited(path, max_bytes, lambda r: OSError(r.reason)).decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    if is_json:
        try:
            doc = json.loads(text, object_pairs_hook=lambda pairs: pairs)
        except (ValueError, RecursionError):
            return None
        stack: list[tuple[Any, list]] = [(doc, [])]  # depth first, in the file's order
        while stack:
            node, at = stack.pop()
            if isinstance(node, float) and not math.isfinite(node):
                return key_path(at), None
            if isinstance(node, list) and node and all(isinstance(p, tuple) and len(p) == 2 for p in node) \
                    and all(isinstance(p[0], str) for p in node):  # an object's (key, value) pairs
                stack.extend((v, [*at, k]) for k, v in reversed(node))
            elif isinstance(node, list):
                stack.extend((node[i], [*at, i]) for i in reversed(range(len(node))))
        return None
    try:
        root = yaml.compose(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except (yaml.YAMLError, RecursionError):
        return None
    nodes: list[tuple[Any, list]] = [(root, [])]
    while nodes:
        node, at = nodes.pop()
        if isinstance(node, yaml.ScalarNode):
            if not node.style and _NON_FINITE.match(node.value.strip()) and \
                    not math.isfinite(float(node.value.replace("_", "").lower().replace(".inf", "inf")
                                            .replace(".nan", "nan"))):
                return key_path(at), node.start_mark.line + 1
        elif isinstance(node, yaml.MappingNode):
            nodes.extend((v, [*at, k.value if isinstance(k, yaml.ScalarNode) else "?"])
                         for k, v in reversed(node.value))
        elif isinstance(node, yaml.SequenceNode):
            nodes.extend((node.value[i], [*at, i]) for i in reversed(range(len(node.value))))
    return None


# --------------------------------------------------------------------- one pose
def _lookup(record: Any, key: str) -> tuple[Any, bool]:
    """The value at ``key`` (a name, or a dotted path into nested mappings and lists)."""
    if isinstance(record, dict) and key in record:
        return record[key], True
    node = record
    for part in key.split("."):
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        else:
            return None, False
    return node, True


def _key_list(record: Any) -> str:
    names = [str(k) if len(str(k)) <= 40 else str(k)[:37] + "..." for k in record] if isinstance(record, dict) else []
    return ", ".join(names[:12]) + (", ..." if len(names) > 12 else "") if names else "none"


def _number(value: Any, what: str, where: str) -> float:
    """A finite float of a pose's value (a CSV cell is a text to convert); the refusal names
    ``where`` and the key path ``what``, not the value."""
    if isinstance(value, str):  # CSV cells
        try:
            value = float(value.strip())
        except ValueError:
            raise InputError(f"{where}: {what} is a text, not a number", hint="write plain numbers") from None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"{where}: {what} is {_kind(value)}, not a number", hint="write plain numbers")
    try:
        x = float(value)
    except OverflowError:
        raise InputError(f"{where}: {what} is too large for a number", hint="write plain numbers") from None
    if not math.isfinite(x):
        raise InputError(f"{where}: {what} is not a finite number",
                         hint="write a finite number (NaN and infinity are not numbers)")
    return x


def _in_range(value: Any, what: str, where: str, lo: float, hi: float, unit: str = "") -> float:
    """A finite float inside [lo, hi], or one line naming ``where``, the key path and the range."""
    x = _number(value, what, where)
    if not lo <= x <= hi:
        u = f" {unit}" if unit else ""
        raise InputError(f"{where}: {what} = {x:.6g}{u} is outside [{lo:g}, {hi:g}]{u}",
                         hint="give a value inside the range")
    return x


def _whole(value: Any, what: str, where: str, lo: int, hi: int) -> int:
    """A whole number inside [lo, hi] (an integral float is taken)."""
    x = _in_range(value, what, where, lo, hi)
    if not float(x).is_integer():
        raise InputError(f"{where}: {what} = {x:g} is not a whole number", hint="write a whole number")
    return int(x)


def _flat(value: Any) -> list[Any]:
    if isinstance(value, list):
        return [x for v in value for x in _flat(v)]
    return [value]


def _numbers(record: Any, keys: tuple[str, ...], n: int | None, where: str, role: str
             ) -> tuple[np.ndarray, list[str]]:
    """The numbers of ``keys`` and the key path of each: one key holding a list (nested lists
    are read row by row), or one key per number. ``n`` None: as many as there are (at most
    MAX_NUMBERS)."""
    if len(keys) == 1:
        value, found = _lookup(record, keys[0])
        if not found:
            raise InputError(f"{where}: no key {keys[0]!r} (the {role}; keys: {_key_list(record)})",
                             hint=f"name the keys in a mapping file or the options ({MAPPING_HINT})")
        items = _flat(value)
        if (n is not None and len(items) != n) or len(items) > MAX_NUMBERS:
            raise InputError(f"{where}: {keys[0]} holds {len(items)} numbers, the {role} takes "
                             f"{n if n is not None else f'at most {MAX_NUMBERS}'}",
                             hint=f"check the pose format and its keys ({MAPPING_HINT})")
        names = [f"{keys[0]}[{i}]" if isinstance(value, list) else keys[0] for i in range(len(items))]
        return np.array([_number(v, name, where) for v, name in zip(items, names, strict=True)]), names
    if n is not None and len(keys) != n:
        raise InputError(f"{where}: the mapping names {len(keys)} keys for the {role}, which takes {n}",
                         hint=MAPPING_HINT)
    out = []
    for k in keys:
        value, found = _lookup(record, k)
        if not found:
            raise InputError(f"{where}: no key {k!r} (the {role}; keys: {_key_list(record)})",
                             hint=f"name the keys in a mapping file or the options ({MAPPING_HINT})")
        out.append(_number(value, k, where))
    return np.array(out), list(keys)


def _translation(values: np.ndarray, names: list[str], mapping: PoseMapping, where: str) -> np.ndarray:
    t = values * mapping.length_unit.metres
    with np.errstate(over="ignore"):
        norm = float(np.linalg.norm(t))
    if norm > MAX_TRANSLATION:
        k = int(np.argmax(np.abs(values)))
        largest = f"{names[k]} = {values[k]:.4g} {mapping.length_unit.value}"
        if mapping.length_unit is LengthUnit.M:
            raise InputError(f"{where}: the translation is {norm:.4g} m from the base ({largest}), more than "
                             f"{MAX_TRANSLATION:g} m: it looks like millimetres while the mapping says metres",
                             hint="set length_unit: mm in the mapping file (or --length-unit mm)")
        raise InputError(f"{where}: the translation is {norm:.4g} m from the base ({largest}), more than "
                         f"{MAX_TRANSLATION:g} m", hint="check the position keys and length_unit")
    return t


def _angles(values: np.ndarray, names: list[str], mapping: PoseMapping, where: str) -> np.ndarray:
    for v, name in zip(values, names, strict=True):
        if mapping.angle_unit is AngleUnit.RAD and abs(v) > MAX_RADIANS:
            raise InputError(f"{where}: {name} = {v:.4g} is more than 2 pi: it looks like degrees while the mapping "
                             "says radians", hint="set angle_unit: deg in the mapping file (or --angle-unit deg)")
        if mapping.angle_unit is AngleUnit.DEG and abs(v) > MAX_DEGREES:
            raise InputError(f"{where}: {name} = {v:.4g} deg is outside [-360, 360] deg",
                             hint="check the angle keys and angle_unit")
    return values * mapping.angle_unit.radians


def _quaternion_matrix(values: np.ndarray, mapping: PoseMapping, where: str) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q = values if mapping.quaternion_order is QuaternionOrder.XYZW else np.r_[values[1:], values[0]]
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise InputError(f"{where}: the quaternion's norm is {norm:.6g}, off 1 by {abs(norm - 1.0):.3g} (more than "
                         f"{QUATERNION_TOLERANCE:g}); this view is not used",
                         hint="log unit quaternions, or check the keys and quaternion_order (xyzw or wxyz)")
    return Rotation.from_quat(q / norm).as_matrix()


def _matrix(values: np.ndarray, names: list[str], mapping: PoseMapping, where: str) -> np.ndarray:
    bound = MAX_TRANSLATION / mapping.length_unit.metres
    for v, name in zip(values, names, strict=True):
        if abs(v) > bound:
            raise InputError(f"{where}: {name} = {v:.4g} is outside [-{bound:g}, {bound:g}] (no number of a pose "
                             f"matrix in {mapping.length_unit.value} is larger)",
                             hint="check the matrix keys and length_unit")
    order = mapping.matrix_order or matrix_order_of(values, names[0].split("[")[0])
    M = values.reshape(4, 4)
    if order is MatrixOrder.COLUMN:
        M = M.T
    bottom = np.array([0.0, 0.0, 0.0, 1.0])
    if not np.allclose(M[3], bottom, atol=1e-6):
        other = "column" if order is MatrixOrder.ROW else "row"
        if mapping.matrix_order is not None and np.allclose(M[:, 3], bottom, atol=1e-6):
            raise InputError(f"{where}: the matrix's last row is {np.round(M[3], 6).tolist()}, not [0, 0, 0, 1]: it "
                             f"looks {other}-major while the mapping says {order.value}-major",
                             hint=f"set matrix_order: {other} in the mapping file (or --matrix-order {other})")
        raise InputError(f"{where}: the matrix's last row is not [0, 0, 0, 1], read row by row or column by column",
                         hint="give a 4x4 homogeneous transform")
    R = M[:3, :3]
    off = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if off > ROTATION_TOLERANCE or np.linalg.det(R) < 0:
        raise InputError(f"{where}: the matrix's rotation part is not a rotation (|R^T R - I| = {off:.3g}, det "
                         f"{np.linalg.det(R):.3g})",
                         hint="check the matrix and matrix_order (row or column); lengths in the last column")
    U, _, Vt = np.linalg.svd(R)
    out = np.eye(4)
    out[:3, :3] = U @ Vt
    column = [names[4 * i + 3] if order is MatrixOrder.ROW else names[12 + i] for i in range(3)]
    out[:3, 3] = _translation(M[:3, 3], column, mapping, where)
    return out


#: keys whose 16 numbers are column-major when the numbers read both ways (a pose at the base's origin)
COLUMN_MAJOR_KEYS = ("O_T_EE", "O_T_EE_d", "O_T_EE_c", "F_T_EE", "EE_T_K")


def matrix_order_of(values: np.ndarray, key: str) -> MatrixOrder:
    """The order of a 4x4 matrix's 16 numbers: the one that puts [0, 0, 0, 1] in the last row
    (row-major: the last four numbers; column-major: every fourth). When both do (no
    translation), libfranka's keys (O_T_EE, ...) are column-major and others row-major; when
    neither does, the one the key suggests (the matrix is then refused when read)."""
    bottom = np.array([0.0, 0.0, 0.0, 1.0])
    row = bool(np.allclose(values[12:16], bottom, atol=1e-6))
    column = bool(np.allclose(values[3::4], bottom, atol=1e-6))
    if row != column:
        return MatrixOrder.ROW if row else MatrixOrder.COLUMN
    return MatrixOrder.COLUMN if key.rsplit(".", 1)[-1] in COLUMN_MAJOR_KEYS else MatrixOrder.ROW


def robot_pose(record: Any, where: str, mapping: PoseMapping, kin=None) -> np.ndarray:
    """``base_T_flange`` (4, 4) [m] of one pose record (a mapping of keys to values) as the
    mapping reads it; ``kin``: the cell's Kinematics, for joint positions. One InputError
    naming ``where`` when it cannot be read."""
    f = mapping.pose_format
    if f is None:
        raise InputError(f"{where}: the pose format is not known", hint=MAPPING_HINT)
    T = np.eye(4)
    if f is PoseFormat.MATRIX:
        return _matrix(*_numbers(record, mapping.matrix, 16, where, "4x4 matrix"), mapping, where)
    if f is PoseFormat.JOINTS:
        if kin is None:
            raise InputError(f"{where}: joint positions need the robot's kinematics", hint="pass --cell NAME|FILE")
        return _joints_pose(record, where, mapping, kin)
    t = _translation(*_numbers(record, mapping.position, 3, where, "position"), mapping, where)
    if f is PoseFormat.XYZ_QUAT:
        q, _ = _numbers(record, mapping.quaternion_keys, 4, where, "quaternion")
        T[:3, :3] = _quaternion_matrix(q, mapping, where)
    else:
        rpy = _angles(*_numbers(record, mapping.rpy, 3, where, "roll, pitch, yaw"), mapping, where)
        T[:3, :3] = rpy_to_matrix(*rpy)
    T[:3, 3] = t
    return T


def _joints_pose(record: Any, where: str, mapping: PoseMapping, kin) -> np.ndarray:
    names = tuple(kin.joint_names)
    q, keys = _numbers(record, mapping.joints, None, where, "joint positions")
    if len(q) != len(names):
        raise InputError(f"{where}: {len(q)} joint positions, the cell {kin.cell.name} has {len(names)} joints "
                         f"({', '.join(names)})", hint="pass the --cell the poses were logged with")
    linear = set(kin.cell.linear_joints)
    out = np.empty(len(q))
    for i, (name, key, v) in enumerate(zip(names, keys, q, strict=True)):
        if name in linear:
            out[i] = v * mapping.length_unit.metres
            if abs(out[i]) > MAX_TRANSLATION:
                raise InputError(f"{where}: {key} (joint {name}) at {out[i]:.4g} m: it looks like millimetres",
                                 hint="set length_unit: mm (or --length-unit mm)")
        else:
            out[i] = _angles(np.array([v]), [f"{key} (joint {name})"], mapping, where)[0]
    return kin.frame_pose(out, kin.cell.flange_link)


def detect_format(record: Any, mapping: PoseMapping, where: str) -> PoseMapping:
    """The mapping with its pose format (and keys) told by the keys of a pose, when it has
    none: O_T_EE (libfranka's; at the top or under one key, e.g. robot_state.O_T_EE; its
    order told by its numbers), x y z qx qy qz qw, position.{x,y,z} +
    orientation.{x,y,z,w} (a ROS Pose), x y z roll pitch yaw, matrix, joints."""
    if mapping.pose_format is not None:
        return mapping

    def has(*keys: str) -> bool:
        return all(_lookup(record, k)[1] for k in keys)

    def order(key: str) -> MatrixOrder | None:
        """The mapping's matrix order, else the one the first pose's numbers show."""
        if mapping.matrix_order is not None:
            return mapping.matrix_order
        value, _ = _lookup(record, key)
        items = _flat(value)
        if len(items) != 16 or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in items):
            return None  # the view says what is wrong when it is read
        with np.errstate(all="ignore"):
            return matrix_order_of(np.array(items, dtype=np.float64), key)

    franka = "O_T_EE" if has("O_T_EE") else next(
        (f"{k}.O_T_EE" for k, v in record.items() if isinstance(k, str) and isinstance(v, dict) and "O_T_EE" in v),
        None) if isinstance(record, dict) else None  # libfranka's state at the top, or under one key
    if franka is not None:
        return replace(mapping, pose_format=PoseFormat.MATRIX, matrix=(franka,), matrix_order=order(franka))
    if has("x", "y", "z", "qx", "qy", "qz", "qw"):
        return replace(mapping, pose_format=PoseFormat.XYZ_QUAT, quaternion=("qx", "qy", "qz", "qw"),
                       quaternion_order=QuaternionOrder.XYZW)
    if has("position.x", "position.y", "position.z", "orientation.x", "orientation.y", "orientation.z",
           "orientation.w"):
        return replace(mapping, pose_format=PoseFormat.XYZ_QUAT, position=("position.x", "position.y", "position.z"),
                       quaternion=("orientation.x", "orientation.y", "orientation.z", "orientation.w"),
                       quaternion_order=QuaternionOrder.XYZW)
    if has("x", "y", "z", "roll", "pitch", "yaw"):
        return replace(mapping, pose_format=PoseFormat.XYZ_RPY)
    for key in mapping.matrix if len(mapping.matrix) == 1 else ():
        if has(key):
            return replace(mapping, pose_format=PoseFormat.MATRIX, matrix_order=order(key))
    if len(mapping.joints) == 1 and has(mapping.joints[0]):
        return replace(mapping, pose_format=PoseFormat.JOINTS)
    raise InputError(f"{where}: the pose's form cannot be told from its keys ({_key_list(record)})",
                     hint="write a mapping file naming the keys and units, or pass --pose-format and name the keys "
                          f"in a mapping file ({MAPPING_HINT})")


# --------------------------------------------------------------------- the data set's files
@dataclass(frozen=True)
class DatasetView:
    """One image and its pose as the data set holds them: ``record`` the pose's values by
    key (None when the pose could not be read: ``problem`` says why), ``where`` the file
    (and line) they came from."""

    name: str
    image: Path
    record: Any
    where: str
    camera: CameraNumbers | str | None = None  # the intrinsics its pose file holds, why they cannot be read, or None


@dataclass(frozen=True)
class IndexHints:
    """What an index file of ros-industrial's industrial_calibration says beside the pairs."""

    camera: CameraNumbers | None = None
    board: Board | None = None
    setup: Setup | None = None
    camera_source: str = "the index file's intrinsics"  # where ``camera`` was read, for the report


@dataclass(frozen=True)
class Dataset:
    folder: Path
    layout: str  # how the pairs were found, for the report
    views: list[DatasetView]
    skipped: list[SkippedImage]
    hints: IndexHints = field(default_factory=IndexHints)


def _natural(name: str) -> list:
    return [int(p) if p.isdigit() else p.lower() for p in re.split(r"(\d+)", name)]


def _refuse_file(what: str, path: Path, limit: int) -> files.Refuse:
    return files.file_errors(path, what, "check the data set", lambda size: (
        f"{size:,} bytes, more than the {limit:,} recon reads", "this is not a pose file recon reads"))


def _shown(name: str) -> str:
    return repr(name) if len(name) <= 80 else repr(name[:77] + "...")


def _file_name(value: Any, what: str, where: str) -> str:
    """A file name an index or CSV file gives: a text of at most MAX_NAME characters."""
    if not isinstance(value, str):
        raise InputError(f"{where}: the {what} is {_kind(value)}, not a file name",
                         hint="write the path inside the data set folder, e.g. images/0.png")
    if not value.strip():
        raise InputError(f"{where}: the {what} names no file", hint="write the path inside the data set folder")
    if len(value) > MAX_NAME or "\x00" in value:
        raise InputError(f"{where}: the {what} is not a file name ({len(value):,} characters"
                         f"{', a NUL character' if chr(0) in value else ''})",
                         hint=f"write a path of at most {MAX_NAME:,} characters inside the data set folder")
    return value


def _inside(root: Path, base: Path, name: str, where: str) -> Path:
    """``base / name``, a path the data set names, refused unless it stays inside ``root``
    (an absolute path, '..' or '~' leave it; a link is followed, and where it leads must be
    inside), all before it is read."""
    p = PurePath(str(name))
    if p.is_absolute() or ".." in p.parts or str(name).startswith("~"):
        raise InputError(f"{where}: {_shown(str(name))} leaves the data set folder",
                         hint="name files inside the data set folder by a relative path without '..'")
    path = base / p
    try:
        target = path.resolve(strict=True)
    except (OSError, RuntimeError, ValueError):  # ValueError: a NUL byte
        raise InputError(f"{where}: {path} does not exist", hint="check the name, or add the file") from None
    if not target.is_relative_to(root):
        raise InputError(f"{where}: {path} leads out of the data set folder (a link); not read",
                         hint="copy the file into the folder")
    return path


class _DatasetRefused(InputError):
    """A refusal of the whole data set (a bound exceeded), not of one view."""


class _PoseBytes:
    """The bytes of the pose files read so far, bounded by MAX_POSES_BYTES (each file's size
    is taken from its stat before it is read)."""

    def __init__(self) -> None:
        self.total = 0

    def take(self, path: Path) -> None:
        try:
            self.total += os.stat(path).st_size
        except OSError:
            return  # the reader names the problem
        if self.total > MAX_POSES_BYTES:
            raise _DatasetRefused(f"{path}: the pose files hold more than {MAX_POSES_BYTES:,} bytes together",
                                  hint=f"a pose file holds one pose (at most {MAX_POSE_BYTES:,} bytes); "
                                       f"at most {MAX_VIEWS:,} views")


def _read_record(path: Path, budget: _PoseBytes | None = None) -> Any:
    if budget is not None:
        budget.take(path)
    return _read_doc(path, "pose file", MAX_POSE_BYTES, max_values=MAX_POSE_VALUES)


def _dictionary_name(value: Any) -> str | None:
    import cv2

    names = {int(getattr(cv2.aruco, n)): n for n in dir(cv2.aruco) if n.startswith("DICT_") and not n.endswith("_SIZE")}
    if isinstance(value, str):
        return value.upper() if value.upper() in names.values() else None
    if isinstance(value, int) and not isinstance(value, bool):
        return names.get(value)
    return None


def _index_hints(doc: Any, where: str) -> IndexHints:
    """intrinsics {fx, fy, cx, cy, distortion}, target_finder (a ChArUco grid: rows, cols,
    chessboard_dim, aruco_marker_dim, dictionary) and static_camera of an
    industrial_calibration cal_data.yaml, each number finite and in its range."""
    if not isinstance(doc, dict):
        return IndexHints()

    def at(container: Any, key: Any) -> str:
        line = line_of(container, key)
        return f"{where}:{line}" if line else where

    camera = board = setup = None
    intr = doc.get("intrinsics")
    if isinstance(intr, dict) and all(k in intr for k in ("fx", "fy", "cx", "cy")):
        v = [_in_range(intr[k], f"intrinsics.{k}", at(intr, k), *(FOCAL_RANGE if k in ("fx", "fy") else CENTRE_RANGE),
                       unit="px") for k in ("fx", "fy", "cx", "cy")]
        dist = intr.get("distortion", [])
        if not isinstance(dist, list) or len(dist) > 5:
            raise InputError(f"{at(intr, 'distortion')}: intrinsics.distortion is "
                             f"{f'a list of {len(dist)}' if isinstance(dist, list) else _kind(dist)}, not a list of "
                             "at most 5 numbers", hint="write [k1, k2, p1, p2, k3] (OpenCV's order)")
        d = [_in_range(x, f"intrinsics.distortion[{i}]", at(dist, i), *DISTORTION_RANGE) for i, x in enumerate(dist)]
        camera = CameraNumbers(v[0], v[1], v[2], v[3], tuple((d + [0.0] * 5)[:5]))
    tf = doc.get("target_finder")
    if isinstance(tf, dict) and "Charuco" in str(tf.get("type", "")):
        missing = [k for k in ("rows", "cols", "chessboard_dim", "aruco_marker_dim", "dictionary") if k not in tf]
        if missing:
            raise InputError(f"{at(doc, 'target_finder')}: target_finder lacks {', '.join(missing)}",
                             hint="a ChArUco grid: rows, cols, chessboard_dim, aruco_marker_dim, dictionary")
        rows = _whole(tf["rows"], "target_finder.rows", at(tf, "rows"), 2, 100)
        cols = _whole(tf["cols"], "target_finder.cols", at(tf, "cols"), 2, 100)
        square = _in_range(tf["chessboard_dim"], "target_finder.chessboard_dim", at(tf, "chessboard_dim"), 0.001, 1.0,
                           unit="m")
        marker = _in_range(tf["aruco_marker_dim"], "target_finder.aruco_marker_dim", at(tf, "aruco_marker_dim"),
                           0.0005, 1.0, unit="m")
        if marker >= square:
            raise InputError(f"{at(tf, 'aruco_marker_dim')}: target_finder.aruco_marker_dim is not smaller than "
                             "chessboard_dim", hint="a ChArUco marker sits inside its square")
        name = _dictionary_name(tf["dictionary"])
        if name is None:
            raise InputError(f"{at(tf, 'dictionary')}: target_finder.dictionary is not an ArUco dictionary",
                             hint="a DICT_... name or OpenCV's number of one (10: DICT_6X6_250)")
        board = BoardSpec(cols, rows, square, marker, name)  # OpenCV's CharucoBoard((cols, rows), ...)
    if "static_camera" in doc:
        if not isinstance(doc["static_camera"], bool):
            raise InputError(f"{at(doc, 'static_camera')}: static_camera is {_kind(doc['static_camera'])}, not true "
                             "or false", hint="true: the camera is fixed (eye-to-hand); false: on the flange")
        setup = Setup.EYE_TO_HAND if doc["static_camera"] else Setup.EYE_IN_HAND
    return IndexHints(camera, board, setup)


def _from_index(index: Path, root: Path) -> Dataset:
    doc = _read_doc(index, "index file", MAX_INDEX_BYTES)
    entries = doc.get("data") if isinstance(doc, dict) else doc
    if not isinstance(entries, list):
        raise InputError(f"{index}: no list of {{image, pose}} pairs (under data:)",
                         hint="write data: [{image: images/0.png, pose: poses/0.yaml}, ...]")
    if len(entries) > MAX_VIEWS:
        raise InputError(f"{index}: {len(entries):,} pairs, more than {MAX_VIEWS:,}",
                         hint=f"use at most {MAX_VIEWS:,} views (every second or third one of a larger set)")
    hints = _index_hints(doc, str(index))
    views: list[DatasetView] = []
    skipped: list[SkippedImage] = []
    names: set[str] = set()
    budget = _PoseBytes()
    base = index.parent
    for k, e in enumerate(entries):
        line = line_of(entries, k)
        where = f"{index}:{line}" if line else f"{index}: entry {k + 1}"
        if not isinstance(e, dict) or "image" not in e or "pose" not in e:
            skipped.append(SkippedImage(f"entry {k + 1}", f"{where}: not an {{image, pose}} pair"))
            continue
        try:
            name = _file_name(e["image"], "image", where)
        except InputError as exc:
            skipped.append(SkippedImage(f"entry {k + 1}", exc.one_line()))
            continue
        if name in names:
            skipped.append(SkippedImage(name, f"{where}: {_shown(name)} is listed twice; the first entry is used"))
            continue
        try:
            image = _inside(root, base, name, where)
            if isinstance(e["pose"], dict):
                record, at = e["pose"], where
            else:
                pose_path = _inside(root, base, _file_name(e["pose"], "pose", where), where)
                record, at = _read_record(pose_path, budget), str(pose_path)
        except _DatasetRefused:
            raise
        except ReconError as exc:
            skipped.append(SkippedImage(name, exc.one_line()))
            continue
        names.add(name)
        views.append(DatasetView(name, image, record, at))
    return Dataset(base, f"index {index}", views, skipped, hints)


def _from_csv(path: Path, root: Path, images_dir: Path, column: str | None) -> Dataset:
    data = files.read_limited(path, MAX_CSV_BYTES, _refuse_file("pose CSV file", path, MAX_CSV_BYTES))
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FileError(f"{path} is not UTF-8 text (byte {exc.start})", hint="save it as UTF-8 CSV") from None
    first = text.split("\n", 1)[0]
    delimiter = next((d for d in (",", ";", "\t") if d in first), ",")
    reader = csv.reader(io.StringIO(text), delimiter=delimiter)
    try:
        header = [h.strip() for h in next(reader)]
    except (StopIteration, csv.Error):
        raise InputError(f"{path}: no header row", hint="the first row names the columns, one of them the image") \
            from None
    if len(header) > MAX_CSV_COLUMNS:
        raise InputError(f"{path}:1: {len(header):,} columns, more than {MAX_CSV_COLUMNS:,}",
                         hint="a row holds an image's name and its pose")
    if len(set(header)) != len(header):
        twice = sorted({h for h in header if header.count(h) > 1})
        raise InputError(f"{path}:1: column {_shown(twice[0])} appears twice", hint="give every column its own name")
    col = column or next((c for c in IMAGE_COLUMNS if c in header), None)
    if col is None or col not in header:
        raise InputError(f"{path}:1: no column naming the image ({'no ' + repr(column) if column else 'none of '}"
                         f"{'' if column else ', '.join(IMAGE_COLUMNS)}; columns: {_key_list(dict.fromkeys(header))})",
                         hint="name it with image_column in the mapping file")
    views: list[DatasetView] = []
    skipped: list[SkippedImage] = []
    names: set[str] = set()
    try:
        for row in reader:
            if not any(cell.strip() for cell in row):
                continue
            where = f"{path}:{reader.line_num}"
            if len(views) + len(skipped) >= MAX_VIEWS:
                raise InputError(f"{path}: more than {MAX_VIEWS:,} rows", hint="split the data set")
            if len(row) != len(header):
                skipped.append(SkippedImage(f"row {reader.line_num}", f"{where}: {len(row)} cells, the header has "
                                                                      f"{len(header)}"))
                continue
            record = dict(zip(header, (c.strip() for c in row), strict=True))
            try:
                name = _file_name(record[col], "image", where)
            except InputError as exc:
                skipped.append(SkippedImage(f"row {reader.line_num}", exc.one_line()))
                continue
            try:
                try:
                    image = _inside(root, path.parent, name, where)
                except InputError:
                    image = _inside(root, images_dir, name, where)
            except ReconError as exc:
                skipped.append(SkippedImage(name, exc.one_line()))
                continue
            if name in names:
                skipped.append(SkippedImage(name, f"{where}: {_shown(name)} is listed twice; the first row is used"))
                continue
            names.add(name)
            views.append(DatasetView(name, image, record, where))
    except csv.Error as exc:
        raise InputError(f"{path}:{reader.line_num}: not valid CSV ({exc})", hint="check the quotes") from None
    return Dataset(path.parent, f"CSV {path}", views, skipped)


def _entries(folder: Path, limit: int | None = None) -> list[Path]:
    """The entries of a folder of the data set, refused beyond ``limit`` (MAX_FOLDER_ENTRIES;
    counted before any entry is looked at)."""
    limit = MAX_FOLDER_ENTRIES if limit is None else limit
    out: list[Path] = []
    try:
        with os.scandir(folder) as it:
            for entry in it:
                if len(out) >= limit:
                    raise InputError(f"{folder} holds more than {limit:,} entries",
                                     hint=f"a data set folder holds its images and poses (at most {MAX_VIEWS:,} "
                                          "views)")
                out.append(folder / entry.name)
    except OSError as exc:
        raise FileError(f"{folder} cannot be listed ({exc.strerror or exc})", hint="check the data set") from None
    return out


def _files(entries: list[Path], suffixes: tuple[str, ...]) -> list[Path]:
    """The regular files (links followed) among ``entries`` with one of ``suffixes``."""
    return [p for p in entries if p.suffix.lower() in suffixes and p.is_file()]


def _images_in(folder: Path, root: Path, skipped: list[SkippedImage]) -> list[Path]:
    """The images of a folder in natural order (2.png before 10.png); links leading out of
    the data set go into ``skipped``."""
    if not folder.is_dir():
        raise FileError(f"{folder} is not a folder", hint="name the images' folder with images: in the mapping file")
    found = _files(_entries(folder), IMAGE_SUFFIXES)
    if len(found) > MAX_VIEWS:
        raise InputError(f"{folder}: {len(found):,} images, more than {MAX_VIEWS:,}",
                         hint=f"use at most {MAX_VIEWS:,} views (every second or third one of a larger set)")
    found.sort(key=lambda p: _natural(p.name))
    kept = []
    for p in found:
        if p.resolve().is_relative_to(root):
            kept.append(p)
        else:
            skipped.append(SkippedImage(p.name, f"{p} is a link leading out of the data set folder; not read"))
    return kept


def _from_pose_files(folder: Path, root: Path, images_dir: Path, poses_dir: Path) -> Dataset:
    views: list[DatasetView] = []
    skipped: list[SkippedImage] = []
    images = _images_in(images_dir, root, skipped)
    if not images:
        raise FileError(f"{images_dir} holds no images ({', '.join(IMAGE_SUFFIXES)})",
                        hint="pass the data set folder (images/ and poses/, or images and pose files side by side)")
    if not poses_dir.is_dir():
        raise FileError(f"{poses_dir} is not a folder", hint="name the pose files' folder with poses: in the mapping")
    pose_files = _files(_entries(poses_dir), POSE_SUFFIXES)
    if len(pose_files) > MAX_VIEWS + MAX_TOP_FILES:
        raise InputError(f"{poses_dir}: {len(pose_files):,} pose files, more than the {MAX_VIEWS:,} views (and "
                         f"{MAX_TOP_FILES} other files) recon reads",
                         hint=f"use at most {MAX_VIEWS:,} views (every second or third one of a larger set)")
    by_stem: dict[str, list[Path]] = {}
    for p in pose_files:
        by_stem.setdefault(p.stem, []).append(p)
    budget = _PoseBytes()
    stems = set()
    for image in images:
        stems.add(image.stem)
        name = str(image.relative_to(folder))
        candidates = sorted(by_stem.get(image.stem, []))
        if not candidates:
            skipped.append(SkippedImage(name, f"no pose file {poses_dir / image.stem}.yaml (or .yml, .json) for "
                                              f"{image}; add it or remove the image"))
            continue
        if len(candidates) > 1:
            skipped.append(SkippedImage(name, f"{len(candidates)} pose files for {image}: "
                                              f"{', '.join(p.name for p in candidates)}; keep one"))
            continue
        pose = candidates[0]
        try:
            if not pose.resolve().is_relative_to(root):
                raise InputError(f"{pose} leads out of the data set folder (a link); not read",
                                 hint="copy the file into the folder")
            record = _read_record(pose, budget)
        except _DatasetRefused:
            raise
        except ReconError as exc:
            skipped.append(SkippedImage(name, exc.one_line()))
            continue
        views.append(DatasetView(name, image, record, str(pose)))
    if poses_dir != images_dir:  # a folder of pose files: name those without an image
        for stem in sorted(set(by_stem) - stems, key=_natural):
            skipped.append(SkippedImage(by_stem[stem][0].name, f"{by_stem[stem][0]}: no image {stem}.* in "
                                                               f"{images_dir}"))
    return Dataset(folder, f"pose files in {poses_dir}", views, skipped)


def _is_index(path: Path) -> bool:
    """A YAML/JSON file at the top of a data set that lists {image, pose} pairs."""
    try:
        doc = load_json(path, "index file", max_bytes=MAX_INDEX_BYTES) if path.suffix.lower() == ".json" \
            else read_yaml(path, "index file", limits=replace(LIMITS, max_bytes=MAX_INDEX_BYTES))
    except ReconError:
        return False
    entries = doc.get("data") if isinstance(doc, dict) else doc
    return isinstance(entries, list) and bool(entries) and all(isinstance(e, dict) and "image" in e for e in entries)


#: names of the board image and of the pose file a view's folder is taken to hold when it holds several
VIEW_IMAGE_STEMS = ("image", "color", "colour", "rgb", "img", "board")
VIEW_POSE_STEMS = ("data", "pose", "robot_state", "robot", "state", "meta")
#: entries of one view's folder (its image, its pose file, a depth image, ...)
MAX_VIEW_ENTRIES = 100


def _one_of(found: list[Path], stems: tuple[str, ...]) -> Path | list[Path]:
    """The one file of a view's folder among ``found`` (the only one, or the only one named
    like ``stems``, a depth image left aside), or all of them when that cannot be told."""
    if len(found) <= 1:
        return found[0] if found else []
    kept = [p for p in found if "depth" not in p.stem.lower() and "mask" not in p.stem.lower()]
    if len(kept) == 1:
        return kept[0]
    named = [p for p in kept if p.stem.lower() in stems]
    return named[0] if len(named) == 1 else sorted(kept or found, key=lambda p: _natural(p.name))


def _from_view_folders(folder: Path, root: Path, subs: list[Path]) -> Dataset:
    """One folder per view (pose_00/{image.png, data.json}, ...), in natural order of the
    folders' names: each holds one image and one pose file (a depth image beside them is
    left aside). A folder holding neither an image nor a pose file (output/, .git/) is no
    view."""
    if len(subs) > MAX_VIEWS:
        raise InputError(f"{folder}: {len(subs):,} folders, more than the {MAX_VIEWS:,} views recon reads",
                         hint=f"use at most {MAX_VIEWS:,} views (every second or third one of a larger set)")
    views: list[DatasetView] = []
    skipped: list[SkippedImage] = []
    budget = _PoseBytes()
    any_image = False
    for sub in sorted(subs, key=lambda p: _natural(p.name)):
        name = sub.name
        if not sub.resolve().is_relative_to(root):
            skipped.append(SkippedImage(name, f"{sub} is a link leading out of the data set folder; not read"))
            continue
        if name.startswith("."):
            continue
        try:
            entries = _entries(sub, MAX_VIEW_ENTRIES)
        except FileError as exc:
            skipped.append(SkippedImage(name, exc.one_line()))
            continue
        except ReconError:
            skipped.append(SkippedImage(name, f"{sub} holds more than {MAX_VIEW_ENTRIES} entries; a view's folder "
                                              "holds its image and its pose file"))
            continue
        image = _one_of(_files(entries, IMAGE_SUFFIXES), VIEW_IMAGE_STEMS)
        pose = _one_of(_files(entries, POSE_SUFFIXES), VIEW_POSE_STEMS)
        if image == [] and pose == []:
            continue  # not a view
        any_image = any_image or bool(image)
        problem = None
        if isinstance(image, list):
            problem = (f"{len(image)} images in {sub} ({', '.join(p.name for p in image[:4])}); keep one, or name "
                       "the board's image.png" if image else f"no image ({', '.join(IMAGE_SUFFIXES)}) in {sub}")
        elif isinstance(pose, list):
            problem = (f"{len(pose)} pose files in {sub} ({', '.join(p.name for p in pose[:4])}); keep one, or "
                       "name the pose's data.json" if pose else f"no pose file (.yaml, .yml, .json) in {sub}; add "
                                                                 "it or remove the folder")
        if problem is not None:
            skipped.append(SkippedImage(name, problem))
            continue
        assert isinstance(image, Path) and isinstance(pose, Path)
        label = f"{name}/{image.name}"
        try:
            for p in (image, pose):
                if not p.resolve().is_relative_to(root):
                    raise InputError(f"{p} leads out of the data set folder (a link); not read",
                                     hint="copy the file into the folder")
            record = _read_record(pose, budget)
        except _DatasetRefused:
            raise
        except ReconError as exc:
            skipped.append(SkippedImage(label, exc.one_line()))
            continue
        views.append(DatasetView(label, image, record, str(pose)))
    if not any_image:
        raise FileError(f"{folder} holds no images ({', '.join(IMAGE_SUFFIXES)}), nor folders of one image and one "
                        "pose file each", hint="pass the data set folder (images and pose files side by side, "
                                               "images/ and poses/, or a folder per view)")
    return Dataset(folder, f"a folder per view in {folder}", views, skipped)


# --------------------------------------------------------------------- the camera of each view
#: keys of a pose file that hold the camera's intrinsics: {fx, fy, cx, cy} (RealSense's ppx,
#: ppy too), a 3x3 matrix (9 numbers, row by row) or [fx, fy, cx, cy]; and its distortion
INTRINSICS_KEYS = ("K", "camera_matrix", "cameraMatrix", "intrinsics", "camera_intrinsics", "intrinsic_matrix",
                   "camera_info.K", "camera_info.k")
DISTORTION_KEYS = ("D", "dist", "distortion", "dist_coeffs", "distCoeffs", "distortion_coefficients", "coeffs",
                   "camera_info.D", "camera_info.d")  # a list, or a YAML matrix {rows, cols, data}
#: coefficients OpenCV takes (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]); recon's model uses the first 5
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)


def _distortion(value: Any, key: str, where: str) -> tuple[float, ...]:
    """k1, k2, p1, p2, k3 of a distortion key's list (OpenCV's order); more coefficients only
    when they are zero (recon's camera model is OpenCV's five). A ROS or OpenCV YAML matrix
    ({rows, cols, data}) is read by its data."""
    if isinstance(value, dict) and isinstance(value.get("data"), list):
        value, key = value["data"], f"{key}.data"
    if not isinstance(value, list):
        raise InputError(f"{where}: {key} is {_kind(value)}, not a list of distortion coefficients",
                         hint="write [k1, k2, p1, p2, k3] (OpenCV's order)")
    items = _flat(value)
    if len(items) not in DISTORTION_LENGTHS:
        raise InputError(f"{where}: {key} holds {len(items)} numbers; distortion coefficients are 4, 5, 8, 12 or 14 "
                         "(OpenCV's order)", hint="write [k1, k2, p1, p2, k3]")
    d = [_in_range(x, f"{key}[{i}]", where, *DISTORTION_RANGE) for i, x in enumerate(items)]
    if any(d[5:]):
        raise InputError(f"{where}: {key} holds {len(d)} coefficients, the 6th or later not zero; recon's camera "
                         "model takes k1, k2, p1, p2, k3", hint="calibrate the camera with that model (recon "
                                                                "calibrate intrinsics) and pass --camera-file")
    return tuple((d + [0.0] * 5)[:5])


def _pinhole(value: Any, key: str, where: str) -> tuple[tuple[float, float, float, float], tuple[float, ...] | None]:
    """(fx, fy, cx, cy) [px] of an intrinsics key, and the distortion it holds itself ({fx, fy,
    cx, cy, distortion} or RealSense's {fx, fy, ppx, ppy, coeffs}), or None."""
    def ranged(v: Any, name: str, i: int) -> float:
        return _in_range(v, name, where, *(FOCAL_RANGE if i < 2 else CENTRE_RANGE), unit="px")

    if isinstance(value, dict) and "fx" not in value and isinstance(value.get("data"), list):
        value, key = value["data"], f"{key}.data"  # a ROS or OpenCV YAML matrix: {rows, cols, data}
    if isinstance(value, dict):
        names = [next((n for n in options if n in value), options[0])
                 for options in (("fx",), ("fy",), ("cx", "ppx"), ("cy", "ppy"))]
        missing = [n for n in names if n not in value]
        if missing:
            raise InputError(f"{where}: {key} lacks {', '.join(missing)}",
                             hint=f"write {key}: {{fx, fy, cx, cy}} in pixels, or a 3x3 camera matrix")
        pinhole = tuple(ranged(value[n], f"{key}.{n}", i) for i, n in enumerate(names))
        inner = next((n for n in ("distortion", "dist", "coeffs", "D", "dist_coeffs") if n in value), None)
        dist = _distortion(value[inner], f"{key}.{inner}", where) if inner is not None else None
        return (pinhole[0], pinhole[1], pinhole[2], pinhole[3]), dist
    if not isinstance(value, list):
        raise InputError(f"{where}: {key} is {_kind(value)}, not intrinsics",
                         hint=f"write {key}: {{fx, fy, cx, cy}} in pixels, or a 3x3 camera matrix")
    items = _flat(value)
    if len(items) == 4:
        return (ranged(items[0], f"{key}[0]", 0), ranged(items[1], f"{key}[1]", 1), ranged(items[2], f"{key}[2]", 2),
                ranged(items[3], f"{key}[3]", 3)), None
    if len(items) != 9:
        raise InputError(f"{where}: {key} holds {len(items)} numbers; intrinsics are a 3x3 camera matrix (9) or "
                         "fx, fy, cx, cy (4)",
                         hint=f"name the key that holds them with intrinsics_key ({MAPPING_HINT})")
    M = np.array([_number(v, f"{key}[{i // 3}][{i % 3}]", where) for i, v in enumerate(items)]).reshape(3, 3)
    if not (abs(M[1, 0]) < 1e-9 and abs(M[2, 0]) < 1e-9 and abs(M[2, 1]) < 1e-9 and abs(M[2, 2] - 1.0) < 1e-9
            and abs(M[0, 1]) <= 1e-6 * max(abs(M[0, 0]), 1.0)):
        transposed = abs(M[0, 2]) < 1e-9 and abs(M[1, 2]) < 1e-9 and abs(M[2, 2] - 1.0) < 1e-9
        raise InputError(f"{where}: {key} is not a camera matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]"
                         + (" (it looks written column by column)" if transposed else ""),
                         hint="write the 3x3 matrix row by row, without skew")
    return (ranged(M[0, 0], f"{key}[0][0]", 0), ranged(M[1, 1], f"{key}[1][1]", 1), ranged(M[0, 2], f"{key}[0][2]", 2),
            ranged(M[1, 2], f"{key}[1][2]", 3)), None


def view_camera(record: Any, where: str, intrinsics_key: str | None = None, distortion_key: str | None = None
                ) -> CameraNumbers | str | None:
    """The intrinsics and distortion a view's pose file holds (the keys named, else the usual
    names: INTRINSICS_KEYS, DISTORTION_KEYS), one line saying why they cannot be read, or None
    when it holds none (no distortion key: none)."""
    if not isinstance(record, dict):
        return None
    k_keys = (intrinsics_key,) if intrinsics_key else INTRINSICS_KEYS
    d_keys = (distortion_key,) if distortion_key else DISTORTION_KEYS
    key = next((k for k in k_keys if _lookup(record, k)[1]), None)
    if key is None:
        return (f"{where}: no key {intrinsics_key!r} (the intrinsics the mapping names; keys: {_key_list(record)})"
                if intrinsics_key else None)
    try:
        pinhole, inner = _pinhole(_lookup(record, key)[0], key, where)
        d_key = next((k for k in d_keys if _lookup(record, k)[1]), None)
        if d_key is not None:
            dist = _distortion(_lookup(record, d_key)[0], d_key, where)
        elif distortion_key:
            raise InputError(f"{where}: no key {distortion_key!r} (the distortion the mapping names)",
                             hint=MAPPING_HINT)
        else:
            dist = inner if inner is not None else (0.0,) * 5
    except InputError as exc:
        return exc.one_line()
    return CameraNumbers(*pinhole, distortion=dist)


#: stems of a camera file at the top of a data set (recon's intrinsics.yaml, a ROS camera_info, ...)
CAMERA_FILE_STEMS = ("intrinsics", "camera", "camera_info", "camera_intrinsics", "camera_calibration",
                     "calibration", "cam")


def _camera_file(folder: Path) -> CameraNumbers | None:
    """The camera of a file at the top of a data set folder named like CAMERA_FILE_STEMS (its
    intrinsics by key, or {fx, fy, cx, cy[, distortion]} at its top), inside the folder and
    bounded like a pose file; a file that cannot be read is refused in one line."""
    if not folder.is_dir():
        return None
    root = folder.resolve()
    found = sorted(p for p in _files(_entries(folder), POSE_SUFFIXES) if p.stem.lower() in CAMERA_FILE_STEMS)
    for path in found:
        if not path.resolve().is_relative_to(root):
            continue
        doc = _read_doc(path, "camera file", MAX_POSE_BYTES, max_values=MAX_POSE_VALUES)
        if not isinstance(doc, dict):
            continue
        camera = view_camera(doc, str(path))
        if camera is None and all(k in doc for k in ("fx", "fy")):
            camera = view_camera({"intrinsics": doc}, str(path))
        if isinstance(camera, str):
            raise InputError(camera, hint="fix the camera file, or move it out of the data set folder")
        if camera is not None:
            return camera
    return None


def _with_cameras(dataset: Dataset, spec: DatasetSpec) -> Dataset:
    """The data set with the camera each view's pose file holds; the first one read becomes
    the data set's camera (unless an index file names one), else a camera file at the top
    of the data set folder."""
    views = [replace(v, camera=view_camera(v.record, v.where, spec.intrinsics_key, spec.distortion_key))
             for v in dataset.views]
    first = next((v.camera for v in views if isinstance(v.camera, CameraNumbers)), None)
    if first is None and dataset.hints.camera is None and not spec.intrinsics_key:
        top = _camera_file(dataset.folder)
        return dataset if top is None else replace(dataset, hints=replace(dataset.hints, camera=top,
                                                                           camera_source="the camera file at the top "
                                                                                         "of the data set"))
    if first is None and not spec.intrinsics_key:
        return dataset
    hints = (dataset.hints if dataset.hints.camera is not None else
             replace(dataset.hints, camera=first, camera_source="the pose files' intrinsics"))
    return replace(dataset, views=views, hints=hints)


def read_dataset(source: Path, spec: DatasetSpec = DatasetSpec()) -> Dataset:  # noqa: B008 (frozen)
    """The (image, pose) pairs of a data set folder (or of an index or CSV file): the index
    the mapping names, else one found at the top of the folder, else the CSV file (the
    mapping's ``poses`` or the only one at the top), else one pose file per image by stem
    (``images``/``poses`` of the mapping, else images/ and poses/ when they exist, else the
    folder itself: images and pose files side by side), else a folder per view (no image at
    the top, folders of one image and one pose file each). The intrinsics and distortion
    each pose file holds (:func:`view_camera`) come with its view; the first view's are the
    data set's camera when no index file gives one."""
    return _with_cameras(_pairs(Path(source), spec), spec)


def _pairs(source: Path, spec: DatasetSpec) -> Dataset:
    source = Path(source)
    if source.is_file():
        folder = source.parent
        root = folder.resolve()
        if not source.resolve().is_relative_to(root):
            raise InputError(f"{source} leads out of its folder (a link); not read",
                             hint="pass the data set folder, or copy the file into it")
        if source.suffix.lower() == ".csv":
            return _from_csv(source, root, folder / (spec.images or "images"), spec.image_column)
        return _from_index(source, root)
    if not source.is_dir():
        raise FileError(f"data set {source} does not exist", hint="pass the folder of the images and their poses")
    folder, root = source, source.resolve()

    def inside(name: str, what: str) -> Path:
        try:
            return _inside(root, folder, name, f"mapping {spec.source or ''} {what}".replace("  ", " "))
        except InputError as exc:
            raise InputError(exc.message, hint=f"{what}: a path inside {folder}") from None

    images_dir = inside(spec.images, "images") if spec.images else (
        folder / "images" if (folder / "images").is_dir() else folder)
    if spec.index:
        return _from_index(inside(spec.index, "index"), root)
    if spec.poses and spec.poses.lower().endswith(".csv"):
        return _from_csv(inside(spec.poses, "poses"), root, images_dir, spec.image_column)
    top = _entries(folder)
    if not spec.poses:
        image_stems = {p.stem for p in top if p.suffix.lower() in IMAGE_SUFFIXES}
        mapping = spec.source.resolve() if spec.source is not None else None
        tops = sorted((p for p in _files(top, POSE_SUFFIXES) if p.stem not in image_stems and p.resolve() != mapping
                       and p.resolve().is_relative_to(root)), key=lambda p: p.name)
        if len(tops) > MAX_TOP_FILES:
            raise InputError(f"{folder} holds {len(tops)} YAML/JSON files beside its images' stems, more than the "
                             f"{MAX_TOP_FILES} looked into for an index",
                             hint="name the index with index: in a mapping file, or put the pose files into poses/")
        indexes = [p for p in tops if _is_index(p)]
        if len(indexes) > 1:
            raise InputError(f"{folder} holds {len(indexes)} index files ({', '.join(p.name for p in indexes)})",
                             hint="name one with index: in a mapping file")
        if indexes:
            return _from_index(indexes[0], root)
        csvs = sorted(p for p in _files(top, (".csv",)) if p.resolve().is_relative_to(root))
        if len(csvs) > 1:
            raise InputError(f"{folder} holds {len(csvs)} CSV files ({', '.join(p.name for p in csvs)})",
                             hint="name the poses' one with poses: in a mapping file")
        if csvs:
            return _from_csv(csvs[0], root, images_dir, spec.image_column)
    poses_dir = inside(spec.poses, "poses") if spec.poses else (
        folder / "poses" if (folder / "poses").is_dir() else images_dir)
    if not spec.images and not spec.poses and images_dir == folder == poses_dir \
            and not _files(top, IMAGE_SUFFIXES):
        subs = [p for p in top if p.is_dir()]
        if subs:
            return _from_view_folders(folder, root, subs)
    return _from_pose_files(folder, root, images_dir, poses_dir)


# --------------------------------------------------------------------- views of the board
def corner_view(name: str, rgb: np.ndarray, base_T_flange: np.ndarray, board: Board, camera: CameraSource,
                min_corners: int = MIN_CORNERS, where: str = "") -> CornerView | SkippedImage:
    """The board's points and pose in one image (RGB), or why the image cannot be used."""
    h, w = rgb.shape[:2]
    cam = camera.at_size(w, h)
    found = find_pose(rgb, board, cam.intrinsics, cam.distortion_array, min_corners)
    if isinstance(found, BoardMissing):
        return SkippedImage(name, found.reason)
    marker_T_cv = invert(board.opencv_board_T_marker())
    pts = found.points.object_points @ marker_T_cv[:3, :3].T + marker_T_cv[:3, 3]
    return CornerView(name, np.asarray(base_T_flange, dtype=np.float64), found.pose.camera_T_marker, pts,
                      found.points.image_points, cam, found.pose.reprojection_rms, where)


@dataclass(frozen=True)
class DatasetViews:
    """The usable views, the skipped ones with their reasons, and the mapping that read the
    poses (with the pose format told by the keys, when the mapping had none)."""

    views: list[CornerView]
    skipped: list[SkippedImage]
    mapping: PoseMapping


def dataset_views(dataset: Dataset, mapping: PoseMapping, board: Board, camera: CameraSource, kin=None,
                  min_corners: int = MIN_CORNERS, progress: Callable[[str, int, int], None] | None = None,
                  poses_read: Callable[[list[np.ndarray], list[SkippedImage]], None] | None = None
                  ) -> DatasetViews:
    """Every pair of the data set read: its pose through the mapping, its image, the board's
    corners in it; a pair that cannot be used is skipped with its reason. Every pose is read
    before any image: ``poses_read`` is then called with the robot poses read (base_T_flange)
    and the views skipped so far, and may refuse the data set before an image is decoded.
    ``camera`` the data set's own (``dataset.hints.camera``): each view is seen with the
    intrinsics its pose file holds, when it holds them."""
    import cv2

    order = {v.name: k for k, v in enumerate(dataset.views)}
    later: list[SkippedImage] = []
    posed: list[tuple[DatasetView, np.ndarray]] = []
    own = camera is dataset.hints.camera
    for v in dataset.views:
        if own and isinstance(v.camera, str):
            later.append(SkippedImage(v.name, v.camera))
            continue
        try:
            if mapping.pose_format is None:
                mapping = detect_format(v.record, mapping, v.where)
            posed.append((v, robot_pose(v.record, v.where, mapping, kin)))
        except ReconError as exc:
            later.append(SkippedImage(v.name, exc.one_line()))
    if poses_read is not None:
        poses_read([T for _, T in posed], list(dataset.skipped) + later)
    views: list[CornerView] = []
    n = len(posed)
    for k, (v, base_T_flange) in enumerate(posed, start=1):
        try:
            bgr = read_color(v.image, "board image", hint="replace or remove the image")
        except ReconError as exc:
            later.append(SkippedImage(v.name, exc.one_line()))
        else:
            with native_output_captured((1, 2)):  # OpenCV's own diagnostics stay off the terminal
                try:
                    seen_by = v.camera if own and isinstance(v.camera, CameraNumbers) else camera
                    found = corner_view(v.name, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), base_T_flange, board,
                                        seen_by, min_corners, v.where)
                except cv2.error as exc:
                    reason = (str(exc).strip().splitlines() or ["no reason given"])[-1][:160]
                    found = SkippedImage(v.name, f"{v.image}: the board cannot be found in it (OpenCV: {reason})")
            if isinstance(found, SkippedImage):
                later.append(found)
            else:
                views.append(found)
        if progress:
            progress("board images", k, n)
    later.sort(key=lambda s: order.get(s.name, len(order)))
    return DatasetViews(views, list(dataset.skipped) + later, mapping)
