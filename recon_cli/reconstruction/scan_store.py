"""The scan store: one folder per session, one subfolder per scan (the contract between
acquisition and registration; design notes, "The scan store").

    <session>/session.json            cell, sensor, backend, object (what produced the scans)
    <session>/scan_0003/color.png     RGB, 8 bit
    <session>/scan_0003/depth.png     uint16, depth [m] * depth_scale (0 = no return)
    <session>/scan_0003/scan.json     intrinsics, depth_scale, measured joints, world_T_camera
                                      from forward kinematics, marker pose (when found),
                                      planned view, execution report, timestamps
    <session>/scan_0003/ground_truth.json   simulation only: true camera pose (never read
                                      by any algorithm; evaluation only)

A scan is written completely into a hidden temporary folder and then renamed into place,
so a crash or Ctrl-C loses at most the scan in progress; readers ignore temporary folders.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from recon_cli.errors import FileError, MetadataError
from recon_cli.geometry.transforms import transform_points
from recon_cli.inputs.images import COLOR, DEPTH, read_image
from recon_cli.lazy import lazy_module
from recon_cli.outputs import atomic_write, remove_inside
from recon_cli.perception.camera_model import Intrinsics, backproject, undistort_color, undistort_depth
from recon_cli.reconstruction.metadata import (
    MAX_METADATA_BYTES,
    SCAN_FORMAT,
    SessionInfo,
    check_pose,
    load_json,
    read_scan_meta,
    read_session,
)
from recon_cli.serialization import to_jsonable

if TYPE_CHECKING:
    import cv2
else:
    cv2 = lazy_module("cv2")

SCAN_DIR = re.compile(r"^scan_(\d{4,})$")
FORMAT_VERSION = SCAN_FORMAT


@dataclass
class Scan:
    """One scan read back from (or about to be written to) the store."""

    index: int
    color: np.ndarray | None  # (H, W, 3) uint8 RGB, None when the scan has no colour
    depth: np.ndarray  # (H, W) float64 [m], 0 = no return
    intrinsics: Intrinsics
    joints: dict[str, float]  # measured joint positions [m or rad]
    world_T_camera_fk: np.ndarray  # camera pose from forward kinematics of the measured joints
    meta: dict[str, Any] = field(default_factory=dict)  # planned view, execution, timestamps...
    marker_T_camera: np.ndarray | None = None  # from the ChArUco board, when found
    ground_truth: dict[str, Any] | None = None  # simulation only; evaluation only
    path: Path | None = None
    distortion: tuple[float, ...] | None = None  # lens distortion of the intrinsics (OpenCV), None: pinhole

    def pinhole_images(self) -> tuple[np.ndarray | None, np.ndarray]:
        """Colour and depth in the pinhole camera of the intrinsics (undistorted when the
        scan has a lens distortion; depth resampled nearest, never blended across edges)."""
        if self.distortion is None:
            return self.color, self.depth

        color = None if self.color is None else undistort_color(self.color, self.intrinsics, self.distortion)
        return color, undistort_depth(self.depth, self.intrinsics, self.distortion)

    def points_camera(self) -> np.ndarray:
        """Points (N, 3) in the camera frame [m]."""
        return backproject(self.pinhole_images()[1], self.intrinsics)

    def points_world_fk(self) -> np.ndarray:
        """Points (N, 3) in the world, placed with the forward-kinematics camera pose."""
        return transform_points(self.world_T_camera_fk, self.points_camera())

    def to_open3d_rgbd(self, depth_trunc: float = 3.0):
        """An Open3D RGBDImage (colour kept as colour, depth in metres)."""
        import open3d as o3d

        color, depth = self.pinhole_images()
        color = color if color is not None else np.zeros((*depth.shape, 3), np.uint8)
        # arrays are buffers: numpy's stubs say so for Python 3.12 and newer only, Open3D's take a Buffer
        return o3d.geometry.RGBDImage.create_from_color_and_depth(
            o3d.geometry.Image(np.ascontiguousarray(color)),  # type: ignore[call-overload]
            o3d.geometry.Image(depth.astype(np.float32)),  # type: ignore[call-overload]
            depth_scale=1.0, depth_trunc=depth_trunc, convert_rgb_to_intensity=False)

    def to_open3d_cloud(self, world_T_camera: np.ndarray | None = None):
        """Open3D point cloud with colours, in the camera frame or placed by a pose."""
        import open3d as o3d

        cloud = o3d.geometry.PointCloud.create_from_rgbd_image(
            self.to_open3d_rgbd(), self.intrinsics.to_open3d())
        if world_T_camera is not None:
            cloud.transform(world_T_camera)
        return cloud


def _write_json(path: Path, data) -> None:
    with open(path, "w") as f:
        json.dump(data, f, indent=2, default=to_jsonable)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())


def encoded_depth(depth: np.ndarray, depth_scale: float) -> np.ndarray:
    """Depth [m] as the stored uint16 image in ``depth_scale`` units per metre (FileError
    beyond its range)."""
    units = np.round(depth * depth_scale)
    if np.any(units > np.iinfo(np.uint16).max):
        raise FileError(f"depth beyond {np.iinfo(np.uint16).max / depth_scale:.2f} m "
                        f"cannot be stored at scale {depth_scale}")
    return units.astype(np.uint16)


def decoded_depth(units: np.ndarray, depth_scale: float) -> np.ndarray:
    """The stored depth image as depth [m] (what every reader of a scan gets)."""
    return units.astype(np.float64) / float(depth_scale)


def stored_depth(depth: np.ndarray, depth_scale: float) -> np.ndarray:
    """Depth [m] exactly as it reads back once stored."""
    return decoded_depth(encoded_depth(depth, depth_scale), depth_scale)


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise FileError(f"cannot encode {path.name}")
    with open(path, "wb") as f:
        f.write(buf.tobytes())
        f.flush()
        os.fsync(f.fileno())


class ScanStore:
    """A session folder of scans."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    # ------------------------------------------------------------------ writing
    @classmethod
    def create(cls, root: Path, session: dict[str, Any]) -> ScanStore:
        root = Path(root)
        try:
            root.mkdir(parents=True, exist_ok=True)
            store = cls(root)
            info = {"format": FORMAT_VERSION, "created": time.time(), **session}
            atomic_write(root / "session.json", lambda tmp: _write_json(tmp, info))
        except OSError as exc:
            raise FileError(f"cannot write the scan store {root} ({exc.strerror})",
                            hint="choose a writable output folder") from None
        return store

    def folder(self, index: int) -> Path:
        """The folder of scan ``index`` (whether it is written or not)."""
        return self.root / f"scan_{index:04d}"

    def write(self, scan: Scan, depth_scale: float) -> Path:
        """Write a scan atomically (temporary folder, then rename). Returns its folder."""
        final = self.folder(scan.index)
        tmp = self.root / f".scan_{scan.index:04d}.tmp-{os.getpid()}"
        if final.exists() or final.is_symlink():
            raise FileError(f"scan {final} already exists", hint="use a new session folder")
        try:
            remove_inside(self.root, tmp.name)  # left by a crash (a link: only the link)
            tmp.mkdir()
            if scan.color is not None:
                _write_png(tmp / "color.png", cv2.cvtColor(scan.color, cv2.COLOR_RGB2BGR))
            _write_png(tmp / "depth.png", encoded_depth(scan.depth, depth_scale))
            record = {
                "format": FORMAT_VERSION,
                "index": scan.index,
                "intrinsics": scan.intrinsics.to_dict(),
                "depth_scale": depth_scale,
                "depth_unit": f"{1e3 / depth_scale:g} mm",
                "joints": scan.joints,
                "world_T_camera_fk": scan.world_T_camera_fk,
                "marker_T_camera": scan.marker_T_camera,
                **({} if scan.distortion is None else {"distortion": list(scan.distortion)}),
                **scan.meta,
            }
            _write_json(tmp / "scan.json", record)
            if scan.ground_truth is not None:
                _write_json(tmp / "ground_truth.json", scan.ground_truth)
            fd = os.open(tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.rename(tmp, final)
        except OSError as exc:
            shutil.rmtree(tmp, ignore_errors=True)
            raise FileError(f"cannot write scan {final} ({exc.strerror})",
                            hint="check free space and permissions of the output folder") from None
        scan.path = final
        return final

    # ------------------------------------------------------------------ reading
    def session(self) -> SessionInfo:
        """``session.json``, checked and typed (empty when the store has none); refused when
        it is a link leading out of the store."""
        self.check_inside(self.root / "session.json")
        return read_session(self.root)

    def scan_folders(self) -> list[tuple[int, Path]]:
        """Every ``scan_NNNN`` folder (complete or not), by index."""
        if not self.root.is_dir():
            return []
        out = []
        for child in self.root.iterdir():
            m = SCAN_DIR.match(child.name)
            if m and child.is_dir():
                out.append((int(m.group(1)), child))
        return sorted(out)

    def indices(self) -> list[int]:
        """Indices of the scan folders that hold a scan.json."""
        return [i for i, folder in self.scan_folders() if (folder / "scan.json").exists()]

    def check_inside(self, path: Path) -> None:
        """Refuse (MetadataError) a file or scan folder of the store that is a link leading out
        of the store, or a scan folder holding one: what is read from a store lies inside it."""
        real_root = self.root.resolve()
        path = Path(path)
        if not (path.exists() or path.is_symlink()):
            return
        for p in (path, *(sorted(path.iterdir()) if path.is_dir() else ())):
            if not p.is_symlink():
                continue
            try:
                target = p.resolve(strict=True)
            except (OSError, RuntimeError):
                raise MetadataError(f"{p} is a link to {os.readlink(p)}, which does not resolve", path=str(p),
                                    hint="remove the link") from None
            if not target.is_relative_to(real_root):
                raise MetadataError(f"{p} is a link to {target}, outside the scan store {self.root}", path=str(p),
                                    hint="copy the scan into the store, or remove the link")

    def next_index(self) -> int:
        return max((i for i, _ in self.scan_folders()), default=-1) + 1

    def read(self, index: int, images: bool = True) -> Scan:
        """One scan; a scan folder (or a file in it) that is a link leading out of the store
        is refused like a broken scan (MetadataError). ``images=False``: its records alone
        (see :func:`read_scan`)."""
        return read_scan(self.folder(index), images=images)

    def __iter__(self):
        for i in self.indices():
            yield self.read(i)

    def __len__(self) -> int:
        return len(self.indices())


def _read_image(path: Path, flags: int, what: str) -> np.ndarray:
    """A scan's PNG through the guarded reader (colour: 8-bit BGR, else 16-bit grey); a bad
    image is a MetadataError, so that registration skips the scan with the reason."""
    if not path.exists():
        raise MetadataError(f"{path}: {what} is missing", path=str(path))
    try:
        return read_image(path, COLOR if flags == cv2.IMREAD_COLOR else DEPTH, what, formats=("png",),
                          hint="re-record the scan or remove its folder")
    except FileError as exc:
        raise MetadataError(exc.message, path=str(path), hint=exc.hint) from None


def _ground_truth(path: Path) -> dict[str, Any] | None:
    """A simulated scan's ``ground_truth.json`` (None when there is none): a JSON object whose
    ``world_T_camera`` is a rigid 4 x 4 pose of numbers within +-1000."""
    if not (path.exists() or path.is_symlink()):
        return None
    gt = load_json(path, "ground_truth.json", MAX_METADATA_BYTES, root=path.parent.parent)
    hint = "remove ground_truth.json (it is used for evaluation only)"
    if not isinstance(gt, dict):
        raise MetadataError(f"{path}: ground_truth.json holds no JSON object", path=str(path), hint=hint)
    pose = gt.get("world_T_camera")

    def number(v) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool) and -1000 <= v <= 1000

    if not (isinstance(pose, list) and len(pose) == 4
            and all(isinstance(r, list) and len(r) == 4 and all(map(number, r)) for r in pose)):
        raise MetadataError(f"{path}: ground_truth.json key 'world_T_camera' is not a 4 x 4 pose of numbers "
                            "within [-1000, 1000]", path=str(path), where="world_T_camera", hint=hint)
    check_pose(pose, path, "ground_truth.json", "world_T_camera")
    return gt


def read_scan(folder: Path, images: bool = True) -> Scan:
    """Read one scan folder (from simulation or hardware); a broken or inconsistent scan, or
    one that is (or holds) a link leading out of its store (the folder's parent), raises a
    MetadataError that names the file and what is wrong with it. ``images=False``: its
    records alone (the depth an empty (0, 0) array, no colour), for a reader that has the
    images' results already."""
    folder = Path(folder)
    ScanStore(folder.parent).check_inside(folder)
    meta = read_scan_meta(folder)
    intr = meta["intrinsics"]
    size = (int(intr["height"]), int(intr["width"]))
    if not images:
        return _scan(folder, meta, None, np.zeros((0, 0)))
    depth_raw = _read_image(folder / "depth.png", cv2.IMREAD_UNCHANGED, "depth image")
    if depth_raw.ndim != 2 or depth_raw.dtype != np.uint16:
        raise MetadataError(f"{folder / 'depth.png'}: depth image is {depth_raw.dtype} with "
                            f"{1 if depth_raw.ndim == 2 else depth_raw.shape[2]} channels, not 16-bit grey",
                            path=str(folder / "depth.png"), hint="store depth as uint16 PNG in depth_scale units")
    if depth_raw.shape != size:
        raise MetadataError(f"{folder / 'depth.png'}: depth image is {depth_raw.shape[1]} x {depth_raw.shape[0]}, "
                            f"the intrinsics in scan.json say {size[1]} x {size[0]}", path=str(folder / "depth.png"))
    depth = decoded_depth(depth_raw, meta["depth_scale"])
    color = None
    if (folder / "color.png").exists():
        bgr = _read_image(folder / "color.png", cv2.IMREAD_COLOR, "colour image")
        if bgr.shape[:2] != size:
            raise MetadataError(f"{folder / 'color.png'}: colour image is {bgr.shape[1]} x {bgr.shape[0]}, the "
                                f"depth image {size[1]} x {size[0]}", path=str(folder / "color.png"),
                                hint="register colour to depth before storing the scan")
        color = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    return _scan(folder, meta, color, depth)


def _scan(folder: Path, meta: dict[str, Any], color: np.ndarray | None, depth: np.ndarray) -> Scan:
    intr = meta["intrinsics"]
    gt = _ground_truth(folder / "ground_truth.json")
    marker = meta.get("marker_T_camera")
    known = {"format", "index", "intrinsics", "depth_scale", "depth_unit", "joints",
             "world_T_camera_fk", "marker_T_camera", "distortion"}
    dist = meta.get("distortion")
    return Scan(
        index=int(meta["index"]), color=color, depth=depth,
        intrinsics=Intrinsics.from_dict(intr),
        joints={k: float(v) for k, v in meta["joints"].items()},
        world_T_camera_fk=np.asarray(meta["world_T_camera_fk"], dtype=float),
        meta={k: v for k, v in meta.items() if k not in known},
        marker_T_camera=None if marker is None else np.asarray(marker, dtype=float),
        ground_truth=gt, path=folder,
        distortion=None if dist is None else tuple(float(v) for v in dist),
    )
