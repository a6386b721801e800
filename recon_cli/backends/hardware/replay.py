"""The replay camera: recorded RGB-D frames played back in order, one per ``capture()``.

Two kinds of recording:

* a recon scan store (``session.json`` + ``scan_NNNN/``): colour, depth, intrinsics,
  distortion and the recorded camera pose ``world_T_camera_fk`` of every scan;
* a folder of images: colour and depth files paired in natural order (``1.png``, ``2.png``,
  ``10.png``), by default everything in its ``color/`` (or ``rgb/``) and ``depth/``
  subfolders, else the globs ``color`` and ``depth`` name. Integer depth images are
  ``depth_scale`` units per metre (1000: millimetres; TUM: 5000); float images are metres.
  Intrinsics come from the station file or an ``intrinsics.json`` ({fx, fy, cx, cy}) in the
  folder. Camera poses (optional): a text file, one line per frame, ``tx ty tz qx qy qz qw``
  (world_T_camera, quaternion Hamilton x y z w, as slambook's pose.txt), or with a leading
  timestamp (TUM groundtruth), or 12 / 16 numbers (the 3 x 4 / 4 x 4 matrix row by row);
  ``#`` starts a comment. Both files must be regular files within their size limits
  (checked before they are opened and read); every pose must be finite, its translation
  within +-1000 m, its quaternion of norm 1 or its matrix rigid; fx, fy, cx, cy must be
  inside the ranges of ``camera.replay.intrinsics`` (docs/inputs.md).

After the last frame, ``capture()`` raises a one-line CameraFault (or, with ``loop``, starts
again). ``import_recording`` turns a recording into a scan store whose kinematic poses are
the recorded ones, so ``recon register STORE --no-board`` re-processes it.

One module on purpose (about 500 lines): the replay camera and the import of a
recording into a scan store share the readers of both source kinds (scan stores, image
folders with poses).
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from recon_cli.backends.base import RGBDFrame
from recon_cli.backends.hardware.camera_config import (
    check_keys,
    choice,
    distortion_values,
    intrinsics_values,
    number,
    text,
)
from recon_cli.errors import CameraFault, FileError, InputError
from recon_cli.geometry.transforms import transform_points
from recon_cli.inputs.images import read_color, read_depth
from recon_cli.inputs.jsonfile import MAX_METADATA_BYTES, load_json, read_bytes
from recon_cli.inputs.numbers import in_range
from recon_cli.perception.camera_model import Intrinsics, backproject
from recon_cli.reconstruction.metadata import read_scan_meta
from recon_cli.reconstruction.scan_store import Scan, ScanStore, read_scan

log = logging.getLogger(__name__)

ADAPTER = "replay"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".pgm", ".ppm", ".tif", ".tiff", ".exr", ".bmp")
COLOR_DIRS = ("color", "rgb", "colour", "image")
DEPTH_DIRS = ("depth",)


@dataclass(frozen=True)
class ReplayConfig:
    """``camera.replay`` of a station file.

    source: a scan store or a folder of images (relative paths: from the working folder);
    kind: auto | store | images; color, depth: globs inside ``source`` (images; default: its
    color/ and depth/ subfolders); depth_scale: depth image units per metre (integer images);
    intrinsics: {fx, fy, cx, cy} [px] (images; default: ``source``/intrinsics.json);
    distortion: OpenCV k1, k2, p1, p2[, k3]; poses: the poses file (images; relative to
    ``source``; default pose.txt or poses.txt there when present); loop: start again after
    the last frame instead of failing.
    """

    source: str
    kind: str = "auto"
    color: str | None = None
    depth: str | None = None
    depth_scale: float = 1000.0
    intrinsics: tuple[float, float, float, float] | None = None
    distortion: tuple[float, ...] | None = None
    poses: str | None = None
    loop: bool = False
    where: str = field(default="camera.replay", compare=False, repr=False)

    @classmethod
    def from_mapping(cls, d: dict, where: str = "camera.replay") -> ReplayConfig:
        d = check_keys(d, where, cls)
        source = text(d, "source", where, None)
        if not source:
            raise InputError(f"{where}.source is missing", hint="the recording's folder (a scan store or images)")
        loop = d.get("loop", False)
        if not isinstance(loop, bool):
            raise InputError(f"{where}.loop is not true or false", hint="loop: true or loop: false")
        return cls(
            source=source,
            kind=choice(d, "kind", where, "auto", ("auto", "store", "images")),
            color=text(d, "color", where, None),
            depth=text(d, "depth", where, None),
            depth_scale=number(d, "depth_scale", where, 1000.0, positive=True),
            intrinsics=None if d.get("intrinsics") is None else intrinsics_values(d["intrinsics"],
                                                                                  f"{where}.intrinsics"),
            distortion=distortion_values(d.get("distortion"), f"{where}.distortion"),
            poses=text(d, "poses", where, None),
            loop=loop,
            where=where,
        )


@dataclass(frozen=True)
class RecordedFrame:
    """One frame of a recording, read when played.

    name: the frame's name (file stem or scan folder); world_T_camera: the recorded pose
    (4, 4) or None; depth_scale: units per metre of its depth file (integer images)."""

    index: int
    name: str
    color_path: Path | None
    depth_path: Path
    intrinsics: Intrinsics | None  # None: from the image size and the configured values
    distortion: tuple[float, ...] | None
    world_T_camera: np.ndarray | None
    depth_scale: float
    timestamp: float | None = None
    scan_folder: Path | None = None  # a scan store's scan
    focal: tuple[float, float, float, float] | None = None  # images: fx, fy, cx, cy [px]


def natural_key(path: Path) -> list:
    """Sort key: digits as numbers (2.png before 10.png)."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def _images(folder: Path, pattern: str | None, dirs: tuple[str, ...], what: str, cfg: ReplayConfig) -> list[Path]:
    if pattern is not None:
        found = [p for p in folder.glob(pattern) if p.is_file()]
        if not found:
            raise FileError(f"{cfg.where}.{what}: no file matches {folder / pattern}",
                            hint="a glob inside the source folder, e.g. depth/*.png")
    else:
        sub = next((folder / d for d in dirs if (folder / d).is_dir()), None)
        if sub is None:
            raise FileError(f"{folder} has no {'/ or '.join(dirs)}/ folder of {what} images",
                            hint=f"give {cfg.where}.{what}: a glob of its {what} images")
        found = [p for p in sub.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES]
    return sorted(found, key=natural_key)


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q).as_matrix()  # (x, y, z, w)


#: bytes of a poses file (one line of at most about 200 bytes per frame)
MAX_POSES_BYTES = 16 * 2**20
#: largest coordinate of a recorded camera position [m]
MAX_TRANSLATION = 1000.0
#: focal lengths and principal point of a recording's intrinsics [px] (as camera.replay.intrinsics)
FOCAL_RANGE, CENTRE_RANGE = (1.0, 1e5), (-1e5, 1e5)


def _read_text(path: Path, what: str, max_bytes: int) -> str:
    """The UTF-8 text of a recording's file: a regular file (checked before it is opened) of
    at most ``max_bytes`` bytes (checked before it is read), or a one-line FileError."""

    try:
        data = read_bytes(path, what, max_bytes)
    except FileError as exc:
        raise FileError(exc.message, hint=exc.hint) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise FileError(f"{path}: {what} is not UTF-8 text (byte {exc.start})", hint="save it as UTF-8 text") from None


def _pose_matrix(v: np.ndarray, path: Path, k: int) -> np.ndarray:
    """world_T_camera of one line's numbers (7, 8, 12 or 16), checked: finite, translation
    within +-MAX_TRANSLATION, a unit quaternion or a rigid matrix."""
    if not np.all(np.isfinite(v)):
        raise FileError(f"{path}:{k}: {' '.join(f'{x:g}' for x in v)} holds NaN or infinity",
                        hint="tx ty tz qx qy qz qw per line, finite numbers")
    T = np.eye(4)
    if len(v) in (7, 8):
        t, q = (v[0:3], v[3:7]) if len(v) == 7 else (v[1:4], v[4:8])
        if not np.isclose(np.linalg.norm(q), 1.0, atol=1e-3):
            raise FileError(f"{path}:{k}: quaternion of norm {np.linalg.norm(q):.4f}",
                            hint="tx ty tz qx qy qz qw with a unit quaternion")
        T[:3, :3] = _quat_matrix(q / np.linalg.norm(q))
        T[:3, 3] = t
    elif len(v) in (12, 16):
        M = v.reshape(-1, 4)
        R = M[:3, :3]
        rigid = (float(np.max(np.abs(R.T @ R - np.eye(3)))) <= 1e-3 and float(np.linalg.det(R)) > 0
                 and (len(v) == 12 or np.allclose(M[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-9)))
        if not rigid:
            raise FileError(f"{path}:{k}: the matrix is not a rigid transform",
                            hint="a rotation and a translation, last row 0 0 0 1")
        T[:3] = M[:3]
    else:
        raise FileError(f"{path}:{k}: {len(v)} numbers", hint="7 (tx ty tz qx qy qz qw), 8 (with a leading "
                                                              "timestamp), 12 or 16 (matrix rows)")
    if np.any(np.abs(T[:3, 3]) > MAX_TRANSLATION):
        raise FileError(f"{path}:{k}: translation ({', '.join(f'{x:g}' for x in T[:3, 3])}) m is outside "
                        f"[-{MAX_TRANSLATION:g}, {MAX_TRANSLATION:g}] m",
                        hint="poses in metres, tx ty tz qx qy qz qw per line")
    return T


def read_poses(path: Path) -> list[np.ndarray]:
    """world_T_camera of every line of a poses file (see the module docstring); the file is
    read as :func:`_read_text` reads it, every pose checked by :func:`_pose_matrix`."""
    path = Path(path)
    poses = []
    lines = _read_text(path, "poses file", MAX_POSES_BYTES).splitlines()
    for k, line in enumerate(lines, 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            v = np.array([float(t) for t in line.replace(",", " ").split()])
        except ValueError:
            raise FileError(f"{path}:{k}: not a list of numbers", hint="tx ty tz qx qy qz qw per line") from None
        poses.append(_pose_matrix(v, path, k))
    return poses


def _check_focal(values: tuple[float, float, float, float], where: str) -> tuple[float, float, float, float]:
    """fx, fy, cx, cy inside FOCAL_RANGE and CENTRE_RANGE (one-line InputError)."""

    names, ranges = ("fx", "fy", "cx", "cy"), (FOCAL_RANGE, FOCAL_RANGE, CENTRE_RANGE, CENTRE_RANGE)
    fx, fy, cx, cy = (in_range(v, f"{where}.{name}" if where != "--intrinsics" else f"--intrinsics {name}", lo, hi,
                               unit="px", hint="fx, fy, cx, cy in pixels")
                      for v, name, (lo, hi) in zip(values, names, ranges, strict=True))
    return fx, fy, cx, cy


def _intrinsics_file(folder: Path) -> tuple[float, float, float, float] | None:
    """fx, fy, cx, cy of the recording's ``intrinsics.json``, None when there is none; read by
    the scan store's JSON reader (regular file, size, nesting, finite numbers)."""

    path = folder / "intrinsics.json"
    if not (path.exists() or path.is_symlink()):
        return None
    try:
        data = load_json(path, "intrinsics.json", MAX_METADATA_BYTES)
    except FileError as exc:
        raise FileError(exc.message, hint=exc.hint or "a JSON object {fx, fy, cx, cy} [px]") from None
    data = {k: v for k, v in data.items() if k not in ("width", "height")} if isinstance(data, dict) else data
    return _check_focal(intrinsics_values(data, str(path)), str(path))


def image_frames(cfg: ReplayConfig, folder: Path) -> list[RecordedFrame]:
    """The frames of a folder of colour and depth images."""
    depth_files = _images(folder, cfg.depth, DEPTH_DIRS, "depth", cfg)
    color_files = _images(folder, cfg.color, COLOR_DIRS, "color", cfg)
    color_files = [p for p in color_files if p not in set(depth_files)]
    if len(color_files) != len(depth_files):
        raise FileError(f"{folder}: {len(color_files)} colour images but {len(depth_files)} depth images",
                        hint=f"pair them one to one ({cfg.where}.color and .depth globs)")
    given = "--intrinsics" if cfg.where == "recon replay" else f"{cfg.where}.intrinsics"
    values = _check_focal(cfg.intrinsics, given) if cfg.intrinsics else _intrinsics_file(folder)
    if values is None:
        raise InputError(f"{cfg.where}: the recording {folder} has no intrinsics",
                         hint=(f"give {cfg.where}.intrinsics: {{fx, fy, cx, cy}}" if cfg.where != "recon replay"
                               else "give --intrinsics fx,fy,cx,cy") + " or put an intrinsics.json there")
    poses_path = None
    if cfg.poses is not None:
        poses_path = folder / cfg.poses
        if not poses_path.exists():
            raise FileError(f"{cfg.where}.poses: {poses_path} does not exist", hint="a path inside the source folder")
    else:
        poses_path = next((folder / n for n in ("pose.txt", "poses.txt") if (folder / n).exists()), None)
    poses = read_poses(poses_path) if poses_path is not None else None
    if poses is not None and len(poses) != len(depth_files):
        raise FileError(f"{poses_path}: {len(poses)} poses for {len(depth_files)} frames",
                        hint="one pose line per frame, in the frames' order")
    frames: list[RecordedFrame] = []
    for k, (c, d) in enumerate(zip(color_files, depth_files, strict=True)):
        frames.append(RecordedFrame(k, d.stem, c, d, None, cfg.distortion, None if poses is None else poses[k],
                                    cfg.depth_scale, focal=values))
    return frames


def store_frames(folder: Path) -> list[RecordedFrame]:
    """The scans of a recon scan store (each read and checked when played)."""

    frames: list[RecordedFrame] = []
    for _, scan_folder in ScanStore(folder).scan_folders():
        if not (scan_folder / "scan.json").exists():
            continue
        meta = read_scan_meta(scan_folder)
        dist = meta.get("distortion")
        stamp = meta.get("timestamp")
        frames.append(RecordedFrame(
            len(frames), scan_folder.name, scan_folder / "color.png" if (scan_folder / "color.png").exists() else None,
            scan_folder / "depth.png", Intrinsics.from_dict(meta["intrinsics"]),
            None if dist is None else tuple(float(v) for v in dist),
            np.asarray(meta["world_T_camera_fk"], dtype=float), float(meta["depth_scale"]),
            float(stamp) if isinstance(stamp, (int, float)) else None, scan_folder))
    return frames


def is_scan_store(folder: Path) -> bool:

    return (folder / "session.json").exists() or bool(ScanStore(folder).scan_folders())


def recording_frames(cfg: ReplayConfig) -> list[RecordedFrame]:
    """Every frame of the recording ``cfg.source``, in playing order."""
    folder = Path(cfg.source).expanduser()
    if not folder.is_dir():
        raise FileError(f"{cfg.where}.source: {folder} is not a folder", hint="a scan store or a folder of images")
    kind = cfg.kind if cfg.kind != "auto" else "store" if is_scan_store(folder) else "images"
    frames = store_frames(folder) if kind == "store" else image_frames(cfg, folder)
    if not frames:
        raise FileError(f"{folder} holds no frames", hint="record some, or point to another folder")
    return frames


def load_frame(frame: RecordedFrame) -> RGBDFrame:
    """Read one recorded frame: colour (H, W, 3) RGB, depth [m], its intrinsics."""
    import cv2

    if frame.scan_folder is not None:

        scan = read_scan(frame.scan_folder)
        color = scan.color if scan.color is not None else np.zeros((*scan.depth.shape, 3), np.uint8)
        return RGBDFrame(color, scan.depth, scan.intrinsics, _stamp(frame), scan.distortion)
    raw = _read_image(read_depth, frame.depth_path, "depth image", metres=True,
                      hint="16-bit PNG/PGM in depth_scale units, or a 32-bit float TIFF in metres")
    if np.issubdtype(raw.dtype, np.integer):
        depth = raw.astype(np.float64) / frame.depth_scale
    else:
        depth = np.where(np.isfinite(raw), raw, 0.0).astype(np.float64)
    depth[depth < 0] = 0.0
    h, w = depth.shape
    if frame.color_path is not None:
        bgr = _read_image(read_color, frame.color_path, "colour image")
        if bgr.shape[:2] != (h, w):
            raise CameraFault(f"{frame.color_path} is {bgr.shape[1]} x {bgr.shape[0]}, its depth image "
                              f"{frame.depth_path.name} {w} x {h}", adapter=ADAPTER,
                              hint="replay colour registered to depth (same size)")
        color = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    else:
        color = np.zeros((h, w, 3), np.uint8)
    K = frame.intrinsics
    if K is None:
        assert frame.focal is not None  # a frame of an image folder has the configured values
        K = Intrinsics(w, h, *frame.focal)
    return RGBDFrame(color, depth, K, _stamp(frame), frame.distortion)


def _read_image(reader, path: Path, what: str, **kw) -> np.ndarray:
    """An image through the guarded reader; a bad one is the replay camera's fault."""
    try:
        return reader(path, what, **kw)
    except FileError as exc:
        raise CameraFault(exc.message, adapter=ADAPTER, hint=exc.hint) from None


def _stamp(frame: RecordedFrame) -> float:
    return frame.timestamp if frame.timestamp is not None else float(frame.index)


class ReplayCamera:
    """CameraBackend that plays a recording (see the module docstring).

    frames: what will be played; position: the next frame's index; last: the frame the last
    capture returned (its recorded pose is ``last.world_T_camera``)."""

    def __init__(self, cfg: ReplayConfig, frames: list[RecordedFrame]) -> None:
        self.cfg = cfg
        self.frames = frames
        self.position = 0
        self.last: RecordedFrame | None = None
        self._open = True

    def capture(self) -> RGBDFrame:
        if not self._open:
            raise CameraFault("the replay camera is closed", adapter=ADAPTER)
        if self.position >= len(self.frames):
            if not self.cfg.loop:
                raise CameraFault(f"the replay of {self.cfg.source} has no frame left (all {len(self.frames)} "
                                  "played)", adapter=ADAPTER,
                                  hint=f"plan at most {len(self.frames)} scans, or set {self.cfg.where}.loop: true")
            self.position = 0
        frame = self.frames[self.position]
        self.position += 1
        out = load_frame(frame)
        self.last = frame
        return out

    def describe(self) -> dict:
        return {"adapter": ADAPTER, "source": str(self.cfg.source), "frames": len(self.frames),
                "poses": all(f.world_T_camera is not None for f in self.frames), "loop": self.cfg.loop}

    def close(self) -> None:
        self._open = False

    def __enter__(self) -> ReplayCamera:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_camera(cfg: ReplayConfig) -> ReplayCamera:
    """The replay camera of a recording (its frames listed and checked, not yet read)."""
    return ReplayCamera(cfg, recording_frames(cfg))


# --------------------------------------------------------------------- recording -> scan store
@dataclass(frozen=True)
class ImportedRecording:
    """What ``import_recording`` wrote: the store, its scan folders and the crop box
    (world frame = the recording's frame; None: none derived)."""

    store: Path
    scans: tuple[Path, ...]
    crop_box: tuple[tuple[float, float, float], tuple[float, float, float]] | None  # (centre, size) [m]


def data_crop_box(frames: list[tuple[RGBDFrame, np.ndarray]], quantile: float = 0.01, margin: float = 0.02,
                  stride: int = 4) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """An axis-aligned box (centre, size) [m] around what the frames saw, in the world frame:
    per axis the ``quantile`` .. 1 - ``quantile`` range of every ``stride``-th pixel's point,
    widened by ``margin`` of its size on each side."""

    pts = np.vstack([transform_points(T, backproject(f.depth[::stride, ::stride], _strided(f.intrinsics, stride)))
                     for f, T in frames])
    if len(pts) == 0:
        raise InputError("the recording has no depth to derive a crop box from",
                         hint="pass --crop-box to recon register")
    lo, hi = np.quantile(pts, quantile, axis=0), np.quantile(pts, 1.0 - quantile, axis=0)
    pad = (hi - lo) * margin
    lo, hi = lo - pad, hi + pad
    return _xyz((lo + hi) / 2), _xyz(np.maximum(hi - lo, 1e-3))


def _xyz(values: Iterable[float]) -> tuple[float, float, float]:
    x, y, z = map(float, values)
    return x, y, z


def _strided(K: Intrinsics, s: int) -> Intrinsics:
    """The intrinsics of every s-th pixel (pixel k of the strided image is pixel s k)."""
    return Intrinsics(-(-K.width // s), -(-K.height // s), K.fx / s, K.fy / s, K.cx / s, K.cy / s)


def import_recording(source: ReplayConfig | str | Path, store: Path, *, crop_box: str | tuple | None = "auto",
                     name: str | None = None) -> ImportedRecording:
    """Write a recording as a recon scan store: one scan per frame whose kinematic pose
    (``world_T_camera_fk``) is the recorded pose, no joints, no marker pose, and a
    ``session.json`` with ``world_T_marker`` = identity (the marker frame is the
    recording's world frame), backend "hardware", sensor "replay". Then
    ``recon register STORE --no-board`` registers the frames from the recorded poses.

    crop_box: "auto" (around what the frames saw, ``data_crop_box``), (centre, size) [m] in
    the recording's frame, or None (register needs --crop-box then). Frames without a recorded
    pose are refused (InputError). ``store`` must not hold scans yet.
    """

    cfg = source if isinstance(source, ReplayConfig) else ReplayConfig(str(source))
    frames = recording_frames(cfg)
    missing = [f.name for f in frames if f.world_T_camera is None]
    if missing:
        raise InputError(f"the recording {cfg.source} has no pose for {len(missing)} of {len(frames)} frames "
                         f"(first: {missing[0]})", hint="give a poses file (tx ty tz qx qy qz qw per frame)")
    store = Path(store)
    if store.exists() and ScanStore(store).scan_folders():
        raise FileError(f"{store} already holds scans", hint="import into a new folder")
    loaded = [(load_frame(f), T) for f in frames if (T := f.world_T_camera) is not None]  # all (checked above)
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    if isinstance(crop_box, str):
        if crop_box != "auto":
            raise InputError(f"crop_box = {crop_box!r}", hint="'auto', (centre, size) or None")
        box = data_crop_box(loaded)
    elif crop_box is not None:
        center, size = crop_box
        box = (_xyz(center), _xyz(size))
    session = {"backend": "hardware", "sensor": "replay", "world_T_marker": np.eye(4).tolist(),
               "recording": {"source": str(cfg.source), "frames": len(frames), "name": name or Path(cfg.source).name}}
    if box is not None:
        session["crop_box"] = {"frame": "world", "center": list(box[0]), "size": list(box[1])}
    out = ScanStore.create(store, session)
    written = []
    for k, (frame, (rgbd, T)) in enumerate(zip(frames, loaded, strict=True)):
        scan = Scan(index=k, color=rgbd.color, depth=rgbd.depth, intrinsics=rgbd.intrinsics, joints={},
                    world_T_camera_fk=np.asarray(T, dtype=float),
                    meta={"name": frame.name, "timestamp": rgbd.timestamp,
                          "recorded": {"depth": str(frame.depth_path),
                                       "color": None if frame.color_path is None else str(frame.color_path)}},
                    marker_T_camera=None, distortion=rgbd.distortion)
        written.append(out.write(scan, depth_scale=frame.depth_scale))
    log.info("imported %d frames of %s into %s", len(written), cfg.source, store)
    return ImportedRecording(store, tuple(written), box)
