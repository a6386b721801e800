"""GenICam/GenTL 3D cameras through harvesters (Photoneo PhoXi and MotionCam-3D, and any
other camera that streams a ``Range`` component in a Coord3D pixel format).

The GenTL producer (a ``.cti`` file from the camera vendor) is found through
``GENICAM_GENTL64_PATH`` unless the station file names it; the device by its serial
number. The adapter enables the range component and the texture component (colour or
intensity on the same sensor grid) and disables the others it can. Each capture is one
frame taken after ``capture()`` was called: a software trigger where the device has one
(``TriggerMode``/``TriggerSource``/``TriggerSoftware``), else a short free run (start,
take the first complete frame, stop).

Range data -> depth [m]: ``value * scale + offset`` per coordinate (Scan3dCoordinateScale/
Offset of the device, chunk data when present, or the station file), times the distance
unit (Scan3dDistanceUnit, or ``depth_unit``); the depth image is the C (Z) coordinate.
Coord3D_ABC32f (an XYZ point map, interleaved or planar A/B/C parts) and C-only formats
(Coord3D_C16, Coord3D_C32f: a range image) are read. Invalid points (NaN, the device's
Scan3dInvalidDataValue, Z <= 0) become 0 = no return.

Intrinsics: the station file's, else the device's Scan3dFocalLength, Scan3dAspectRatio,
Scan3dPrincipalPointU/V, else fitted to the XYZ point map (u = fx X/Z + cx, v = fy Y/Z + cy,
least squares; refused when the pixels do not follow a pinhole camera). Optional nodes that
a device lacks are skipped one by one (each read is its own try), never guessed.

One module on purpose (about 600 lines): the adapter, its configuration and the
conversions of GenICam components (point maps, ranges, textures, optional nodes) are one
device protocol; split, each part would be meaningless alone.
"""

from __future__ import annotations

import glob
import logging
import os
import re
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.backends.base import RGBDFrame
from recon_cli.backends.hardware.camera_config import (
    check_keys,
    choice,
    distortion_values,
    intrinsics_values,
    number,
    require_driver,
    text,
)
from recon_cli.errors import CameraFault, InputError
from recon_cli.inputs.yamlfile import shown_key
from recon_cli.perception.camera_model import Intrinsics

log = logging.getLogger(__name__)

ADAPTER = "genicam"
INSTALL = "genicam"  # pip install 'recon-scan[genicam]'
#: metres per unit of Scan3dDistanceUnit
DISTANCE_UNITS = {"Millimeter": 1e-3, "Centimeter": 1e-2, "Meter": 1.0, "Micrometer": 1e-6, "Inch": 0.0254}
#: how many bits a texture format carries (shifted to 8 bit)
MONO_BITS = {"Mono8": 8, "Mono10": 10, "Mono12": 12, "Mono14": 14, "Mono16": 16}
#: [px] RMS of a point-map intrinsics fit above which the grid is not a pinhole camera
FIT_TOLERANCE_PX = 0.5


@dataclass(frozen=True)
class GenICamConfig:
    """``camera.genicam`` of a station file.

    cti: GenTL producer files (default: every .cti in GENICAM_GENTL64_PATH, else the genicam
    package's software producer); serial: the device's serial number (also matched against
    its id and user-defined name; default: the only device); trigger: "software" (falls back
    to "free" when the device has no software trigger) or "free"; timeout [s] for one frame;
    range_component / texture_component: ComponentSelector entries (texture None: no colour,
    a grey image); depth_unit [m per coordinate unit] overrides Scan3dDistanceUnit;
    coordinate_scale / coordinate_offset override Scan3dCoordinateScale/Offset;
    intrinsics: {fx, fy, cx, cy} [px] (default: the device's nodes, else fitted to the point
    map); distortion: OpenCV k1, k2, p1, p2[, k3] of those intrinsics; features: node
    settings applied in order when the device is opened (e.g. ExposureTime); skip_frames:
    frames dropped before the one returned (a camera whose first frame is stale).
    """

    cti: tuple[str, ...] = ()
    serial: str | None = None
    trigger: str = "software"
    timeout: float = 10.0
    range_component: str = "Range"
    texture_component: str | None = "Intensity"
    depth_unit: float | None = None
    coordinate_scale: float | None = None
    coordinate_offset: float | None = None
    intrinsics: tuple[float, float, float, float] | None = None
    distortion: tuple[float, ...] | None = None
    features: tuple[tuple[str, Any], ...] = ()
    skip_frames: int = 0
    where: str = field(default="camera.genicam", compare=False, repr=False)

    @classmethod
    def from_mapping(cls, d: dict, where: str = "camera.genicam") -> GenICamConfig:
        d = check_keys(d, where, cls)
        cti = d.get("cti", ())
        if isinstance(cti, str):
            cti = (cti,)
        if not isinstance(cti, (list, tuple)) or not all(isinstance(c, str) for c in cti):
            raise InputError(f"{where}.cti is not a path or a list of paths",
                             hint="the camera vendor's GenTL producer, e.g. .../API/lib/photoneo.cti")
        features = d.get("features") or {}
        if not isinstance(features, dict):
            raise InputError(f"{where}.features is not a mapping", hint="write NodeName: value lines under it")
        texture = d.get("texture_component", "Intensity")
        return cls(
            cti=tuple(cti),
            serial=text(d, "serial", where, None),
            trigger=choice(d, "trigger", where, "software", ("software", "free")),
            timeout=number(d, "timeout", where, 10.0, positive=True),
            range_component=text(d, "range_component", where, "Range") or "Range",
            texture_component=None if texture is None else text(d, "texture_component", where, "Intensity"),
            depth_unit=number(d, "depth_unit", where, None, positive=True, optional=True),
            coordinate_scale=number(d, "coordinate_scale", where, None, optional=True),
            coordinate_offset=number(d, "coordinate_offset", where, None, optional=True),
            intrinsics=None if d.get("intrinsics") is None else intrinsics_values(d["intrinsics"],
                                                                                  f"{where}.intrinsics"),
            distortion=distortion_values(d.get("distortion"), f"{where}.distortion"),
            features=tuple((str(k), v) for k, v in features.items()),
            skip_frames=number(d, "skip_frames", where, 0, integer=True, minimum=0),
            where=where,
        )


# --------------------------------------------------------------------- producers and devices
def producer_files(cfg: GenICamConfig) -> list[str]:
    """The GenTL producers to load: the configured ones, else GENICAM_GENTL64_PATH's, else the
    genicam package's software producer."""
    if cfg.cti:
        missing = [c for c in cfg.cti if not Path(c).is_file()]
        if missing:
            raise InputError(f"{cfg.where}.cti: {missing[0]} does not exist",
                             hint="give the path of the camera vendor's GenTL producer (.cti)")
        return list(cfg.cti)
    found: list[str] = []
    for folder in os.environ.get("GENICAM_GENTL64_PATH", "").split(os.pathsep):
        if folder:
            found += sorted(glob.glob(os.path.join(folder, "*.cti")))
    if found:
        return found
    bundled = software_producer()
    if bundled is not None:
        log.warning("no GenTL producer in GENICAM_GENTL64_PATH: using the genicam package's software producer %s",
                    bundled)
        return [bundled]
    raise CameraFault("no GenTL producer (.cti) found", adapter=ADAPTER,
                      hint=f"set GENICAM_GENTL64_PATH or {cfg.where}.cti to the camera vendor's producer")


def software_producer() -> str | None:
    """The software GenTL producer shipped inside the genicam package (streams a test
    pattern with a Coord3D range component), or None."""
    try:
        import genicam
    except ImportError:
        return None
    found = sorted(glob.glob(os.path.join(os.path.dirname(genicam.__file__), "*.cti")))
    return found[0] if found else None


def _device_names(info) -> list[str]:
    names = []
    for attr in ("serial_number", "id_", "user_defined_name"):
        try:
            value = getattr(info, attr, None)
        except Exception:  # noqa: BLE001 - a producer may refuse any property
            value = None
        if value:
            names.append(str(value))
    return names


def choose_device(infos: list, serial: str | None, producers: list[str]):
    """The DeviceInfo of ``serial`` (or the only one); CameraFault listing what was found."""
    listing = ", ".join(f"{n[0]} ({' / '.join(n[1:])})" if len(n) > 1 else n[0]
                        for n in (_device_names(i) or ["?"] for i in infos))
    if not infos:
        raise CameraFault(f"no GenICam device found through {', '.join(Path(p).name for p in producers)}",
                          adapter=ADAPTER, hint="check the camera's power and network, and the producer")
    if serial is None:
        if len(infos) > 1:
            raise CameraFault(f"{len(infos)} GenICam devices found ({listing})", adapter=ADAPTER,
                              hint="choose one with camera.genicam.serial")
        return infos[0]
    for info in infos:
        if serial in _device_names(info):
            return info
    raise CameraFault(f"no GenICam device with serial '{serial}' (found: {listing})", adapter=ADAPTER,
                      hint="set camera.genicam.serial to one of these")


# --------------------------------------------------------------------- node access
def _node_errors() -> tuple[type[BaseException], ...]:
    from genicam import genapi, gentl

    return (AttributeError, genapi.GenericException, gentl.GenericException)


def read_node(node_map, name: str, default=None):
    """A node's value, or ``default`` when the device lacks it or it is not readable now."""
    try:
        return getattr(node_map, name).value
    except _node_errors():
        return default


def write_node(node_map, name: str, value) -> bool:
    """Set a node; False when the device lacks it or refuses the value."""
    try:
        getattr(node_map, name).value = value
        return True
    except _node_errors():
        return False


def symbolics(node_map, name: str) -> tuple[str, ...]:
    try:
        return tuple(getattr(node_map, name).symbolics)
    except _node_errors():
        return ()


# --------------------------------------------------------------------- conversions (pure)
def color_from_texture(data: np.ndarray, fmt: str, width: int, height: int) -> np.ndarray:
    """A texture part as (H, W, 3) uint8 RGB: Mono8..16 (shifted to 8 bit), RGB8, BGR8,
    RGBa8, BGRa8, Bayer 8 bit."""
    import cv2

    flat = np.asarray(data)
    if fmt in MONO_BITS:
        grey = flat.reshape(height, width)
        if MONO_BITS[fmt] > 8:
            grey = (grey.astype(np.uint32) >> (MONO_BITS[fmt] - 8)).clip(0, 255)
        grey = grey.astype(np.uint8)
        return np.repeat(grey[:, :, None], 3, axis=2)
    if fmt in ("RGB8", "BGR8", "RGBa8", "BGRa8"):
        channels = 4 if fmt.endswith("a8") else 3
        img = flat.astype(np.uint8, copy=False).reshape(height, width, channels)[:, :, :3]
        return np.ascontiguousarray(img[:, :, ::-1] if fmt.startswith("BGR") else img)
    bayer = {"BayerRG8": cv2.COLOR_BayerRG2RGB, "BayerBG8": cv2.COLOR_BayerBG2RGB,
             "BayerGR8": cv2.COLOR_BayerGR2RGB, "BayerGB8": cv2.COLOR_BayerGB2RGB}
    if fmt in bayer:
        return cv2.cvtColor(flat.astype(np.uint8).reshape(height, width), bayer[fmt])
    raise CameraFault(f"texture pixel format {fmt} is not supported", adapter=ADAPTER,
                      hint="set PixelFormat of the texture component to Mono8, RGB8 or BGR8 "
                           "(camera.genicam.features)")


@dataclass(frozen=True)
class Coordinates:
    """Scale, offset and invalid value of each coordinate (A, B, C) of the range data, and
    the distance unit [m]."""

    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    invalid: float | None = None  # raw value that marks "no data" (Scan3dInvalidDataValue)
    unit: float = 1e-3  # [m] per scaled unit

    def metres(self, raw: np.ndarray, axis: int) -> np.ndarray:
        values = np.asarray(raw, dtype=np.float64)
        out = (values * self.scale[axis] + self.offset[axis]) * self.unit
        bad = ~np.isfinite(values)
        if self.invalid is not None:
            bad |= values == self.invalid
        out[bad] = np.nan
        return out


def range_parts(parts: list[tuple[str, np.ndarray, int, int]]) -> tuple[np.ndarray | None, np.ndarray, int, int]:
    """The point map's A, B, C planes from the range parts (format, data, width, height):
    one interleaved Coord3D_ABC part, planar Coord3D_A/B/C parts, or a C-only range image.
    Returns (AB (2, H, W) or None, C (H, W), width, height) as raw values."""
    by_letters: dict[str, tuple[str, np.ndarray, int, int]] = {}
    for part in parts:
        m = re.match(r"Coord3D_([ABC]+)", part[0])
        if m and m.group(1) in ("ABC", "A", "B", "C"):
            by_letters.setdefault(m.group(1), part)
    if "ABC" in by_letters:
        _, data, w, h = by_letters["ABC"]
        xyz = np.asarray(data).reshape(h, w, 3)
        return np.moveaxis(xyz[:, :, :2], 2, 0), xyz[:, :, 2], w, h
    if "C" in by_letters:
        _, data, w, h = by_letters["C"]
        c = np.asarray(data).reshape(h, w)
        if "A" in by_letters and "B" in by_letters:
            a = np.asarray(by_letters["A"][1]).reshape(h, w)
            b = np.asarray(by_letters["B"][1]).reshape(h, w)
            return np.stack([a, b]), c, w, h
        return None, c, w, h
    formats = ", ".join(p[0] for p in parts) or "none"
    raise CameraFault(f"no Coord3D range data in the frame (parts: {formats})", adapter=ADAPTER,
                      hint="enable the Range component in CalibratedABC_Grid or ProjectedC mode")


def depth_and_points(ab: np.ndarray | None, c: np.ndarray, coords: Coordinates
                     ) -> tuple[np.ndarray, np.ndarray | None]:
    """Depth (H, W) [m] (0 = no return) and the XYZ point map (H, W, 3) [m] (NaN where
    invalid) when A and B are present."""
    z = coords.metres(c, 2)
    points = None
    if ab is not None:
        points = np.stack([coords.metres(ab[0], 0), coords.metres(ab[1], 1), z], axis=2)
    depth = np.where(np.isfinite(z) & (z > 0), z, 0.0)
    if points is not None:
        points[depth == 0] = np.nan
    return depth, points


def fit_intrinsics(points: np.ndarray, max_points: int = 20000) -> tuple[tuple[float, float, float, float], float]:
    """(fx, fy, cx, cy) of the pinhole camera whose pixel grid the point map (H, W, 3) [m]
    follows, by least squares u = fx X/Z + cx, v = fy Y/Z + cy; and the RMS reprojection
    residual [px]. Raises CameraFault with fewer than 100 valid points."""
    h, w = points.shape[:2]
    v, u = np.mgrid[0:h, 0:w]
    ok = np.isfinite(points).all(axis=2) & (points[:, :, 2] > 0)
    n = int(ok.sum())
    if n < 100:
        raise CameraFault(f"cannot fit intrinsics to the point map: only {n} valid points", adapter=ADAPTER,
                          hint="point the camera at a surface, or give camera.genicam.intrinsics")
    step = max(1, n // max_points)
    p, uu, vv = points[ok][::step], u[ok][::step].astype(float), v[ok][::step].astype(float)
    x, y = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
    res = []
    out = []
    for q, t in ((x, uu), (y, vv)):
        A = np.column_stack([q, np.ones_like(q)])
        (f, c0), *_ = np.linalg.lstsq(A, t, rcond=None)
        out.append((float(f), float(c0)))
        res.append(t - A @ np.array([f, c0]))
    rms = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))
    (fx, cx), (fy, cy) = out
    return (fx, fy, cx, cy), rms


# --------------------------------------------------------------------- the adapter
class GenICamCamera:
    """CameraBackend of a GenICam/GenTL 3D camera (see the module docstring)."""

    def __init__(self, cfg: GenICamConfig, harvester, acquirer, info, producers: list[str]) -> None:
        self.cfg = cfg
        self._h = harvester
        self._ia = acquirer
        self.producers = producers
        self.device = {"serial": _safe(info, "serial_number"),
                       **{k: _safe(info, k) for k in ("vendor", "model", "id_", "display_name")}}
        nm = acquirer.remote_device.node_map
        self._nm = nm
        self._apply_features()
        self._select_components()
        self.coordinates = self._coordinates()
        self.trigger = self._setup_trigger()
        self.intrinsics_source = "station file" if cfg.intrinsics is not None else "device"
        self._device_intrinsics = None if cfg.intrinsics is not None else self._intrinsics_nodes()
        if cfg.intrinsics is None and self._device_intrinsics is None:
            self.intrinsics_source = "point map"
        self.fit_rms: float | None = None
        self._fitted: tuple[float, float, float, float] | None = None
        self._acquiring = False
        if self.trigger == "software":
            self._ia.start()
            self._acquiring = True

    # ------------------------------------------------------------------ set-up
    def _apply_features(self) -> None:
        for name, value in self.cfg.features:
            if not write_node(self._nm, name, value):
                shown = shown_key(name) or "<key>"
                raise InputError(f"{self.cfg.where}.features.{shown}: the device has no writable node {shown} "
                                 f"that takes the value given", hint="check the name and value in the device's "
                                                               "feature list")

    def _select_components(self) -> None:
        nm, cfg = self._nm, self.cfg
        available = symbolics(nm, "ComponentSelector")
        if not available:
            return  # a single-component device: its one stream must be the range data
        wanted = [cfg.range_component] + ([cfg.texture_component] if cfg.texture_component else [])
        for name in wanted:
            if name not in available:
                raise InputError(f"{cfg.where}: the device has no component '{name}'",
                                 hint=f"its components: {', '.join(available)}")
        for name in available:
            write_node(nm, "ComponentSelector", name)
            on = name in wanted
            if read_node(nm, "ComponentEnable") != on and not write_node(nm, "ComponentEnable", on) and on:
                raise CameraFault(f"cannot enable the {name} component of the device", adapter=ADAPTER)
        write_node(nm, "ComponentSelector", cfg.range_component)

    def _coordinates(self) -> Coordinates:
        """Scale, offset and unit of the range data: the station file's, else the device's."""
        nm, cfg = self._nm, self.cfg
        write_node(nm, "ComponentSelector", cfg.range_component)
        scale, offset = [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]
        for axis, name in enumerate(("CoordinateA", "CoordinateB", "CoordinateC")):
            if write_node(nm, "Scan3dCoordinateSelector", name) or axis == 2:
                scale[axis] = float(read_node(nm, "Scan3dCoordinateScale", 1.0))
                offset[axis] = float(read_node(nm, "Scan3dCoordinateOffset", 0.0))
        if cfg.coordinate_scale is not None:
            scale = [cfg.coordinate_scale] * 3
        if cfg.coordinate_offset is not None:
            offset = [cfg.coordinate_offset] * 3
        invalid = None
        if read_node(nm, "Scan3dInvalidDataFlag", False):
            value = read_node(nm, "Scan3dInvalidDataValue")
            invalid = None if value is None else float(value)
        unit = cfg.depth_unit
        if unit is None:
            name = read_node(nm, "Scan3dDistanceUnit")
            unit = DISTANCE_UNITS.get(str(name), 1e-3)
            if str(name) not in DISTANCE_UNITS:
                log.warning("Scan3dDistanceUnit of the device is %s: range data taken as millimetres "
                            "(set camera.genicam.depth_unit)", "missing" if name is None else repr(name))
        return Coordinates((scale[0], scale[1], scale[2]), (offset[0], offset[1], offset[2]), invalid, float(unit))

    def _setup_trigger(self) -> str:
        nm = self._nm
        if self.cfg.trigger == "software":
            write_node(nm, "TriggerSelector", "FrameStart")
            if (write_node(nm, "TriggerMode", "On") and write_node(nm, "TriggerSource", "Software")
                    and hasattr(nm, "TriggerSoftware")):
                return "software"
            log.warning("the GenICam device has no software trigger: free run, one frame per capture")
        write_node(nm, "TriggerMode", "Off")
        return "free"

    def _intrinsics_nodes(self) -> tuple[float, float, float, float] | None:
        nm = self._nm
        f = read_node(nm, "Scan3dFocalLength")
        u = read_node(nm, "Scan3dPrincipalPointU")
        v = read_node(nm, "Scan3dPrincipalPointV")
        if f is None or u is None or v is None or not f > 0:
            return None
        aspect = float(read_node(nm, "Scan3dAspectRatio", 1.0) or 1.0)
        return float(f), float(f) * aspect, float(u), float(v)

    # ------------------------------------------------------------------ capture
    def capture(self) -> RGBDFrame:
        if self._ia is None:
            raise CameraFault("the GenICam camera is closed", adapter=ADAPTER)
        from genicam import genapi, gentl

        started = False
        try:
            if self.trigger == "free":
                self._ia.start()
                started = self._acquiring = True
            else:
                self._drain()
            return self._grab()
        except gentl.TimeoutException:
            raise CameraFault(f"no frame from the GenICam device within {self.cfg.timeout:g} s", adapter=ADAPTER,
                              hint="check the trigger set-up and the connection; raise camera.genicam.timeout") \
                from None
        except (gentl.GenericException, genapi.GenericException) as exc:
            raise CameraFault(f"the GenICam device failed to deliver a frame ({exc})", adapter=ADAPTER) from None
        finally:
            if started:
                self._ia.stop()
                self._acquiring = False

    def _grab(self) -> RGBDFrame:
        """Drop ``skip_frames`` frames, convert the next one (each triggered in software mode)."""
        frame: RGBDFrame | None = None
        for k in range(self.cfg.skip_frames + 1):
            if self.trigger == "software":
                self._nm.TriggerSoftware.execute()
            with self._ia.fetch(timeout=self.cfg.timeout) as buffer:
                if k == self.cfg.skip_frames:
                    frame = self._frame(buffer)
        assert frame is not None  # the last pass converted one
        return frame

    def _drain(self, limit: int = 64) -> None:
        """Give back frames still queued from an earlier trigger (a capture that timed out)."""
        for _ in range(limit):
            stale = self._ia.try_fetch(timeout=0.001)
            if stale is None:
                return
            stale.queue()

    def _frame(self, buffer) -> RGBDFrame:
        ranges: list[tuple[str, np.ndarray, int, int]] = []
        textures: list[tuple[str, np.ndarray, int, int]] = []
        for comp in buffer.payload.components:
            fmt = str(comp.data_format)
            item = (fmt, np.array(comp.data, copy=True), int(comp.width), int(comp.height))
            (ranges if fmt.startswith("Coord3D_") else textures).append(item)
        textures = [t for t in textures if not t[0].startswith("Confidence")]
        coords = self._chunk_coordinates()
        ab, c, w, h = range_parts(ranges)
        depth, points = depth_and_points(ab, c, coords)
        color = self._color(textures, w, h, depth)
        K = self._intrinsics(points, w, h)
        try:
            stamp = buffer.timestamp_ns * 1e-9
        except Exception:  # noqa: BLE001 - producers without timestamps raise NotAvailable
            stamp = time.time()
        return RGBDFrame(color, depth, K, float(stamp), self.cfg.distortion)

    def _chunk_coordinates(self) -> Coordinates:
        """The frame's own scale and offset of C (chunk data) when the device sends them."""
        cfg, base = self.cfg, self.coordinates
        if cfg.coordinate_scale is not None:
            return base
        write_node(self._nm, "ChunkScan3dCoordinateSelector", "CoordinateC")
        scale = read_node(self._nm, "ChunkScan3dCoordinateScale")
        offset = read_node(self._nm, "ChunkScan3dCoordinateOffset")
        if scale is None:
            return base
        off = base.offset if offset is None or cfg.coordinate_offset is not None else (*base.offset[:2], float(offset))
        return Coordinates((*base.scale[:2], float(scale)), off, base.invalid, base.unit)

    def _color(self, textures: list, w: int, h: int, depth: np.ndarray) -> np.ndarray:
        import cv2

        if not textures:
            grey = np.where(depth > 0, 200, 0).astype(np.uint8)  # no texture: the valid pixels
            return np.repeat(grey[:, :, None], 3, axis=2)
        if len(textures) > 1:
            raise CameraFault(f"{len(textures)} texture parts in the frame ({', '.join(t[0] for t in textures)})",
                              adapter=ADAPTER, hint="enable one texture component (camera.genicam.texture_component)")
        fmt, data, tw, th = textures[0]
        color = color_from_texture(data, fmt, tw, th)
        if (tw, th) == (w, h):
            return color
        if abs(tw / th - w / h) > 0.01:
            raise CameraFault(f"the texture ({tw} x {th}) is not on the depth grid ({w} x {h})", adapter=ADAPTER,
                              hint="use a texture of the depth sensor (Intensity), not a separate colour camera")
        return cv2.resize(color, (w, h), interpolation=cv2.INTER_AREA if tw > w else cv2.INTER_LINEAR)

    def _intrinsics(self, points: np.ndarray | None, w: int, h: int) -> Intrinsics:
        values = self.cfg.intrinsics or self._device_intrinsics or self._fitted
        if values is None:
            if points is None:
                raise CameraFault("no intrinsics: the device has no Scan3dFocalLength/PrincipalPoint nodes and "
                                  "sends no XYZ point map to fit them to", adapter=ADAPTER,
                                  hint=f"give {self.cfg.where}.intrinsics: {{fx, fy, cx, cy}}")
            values, rms = fit_intrinsics(points)
            if rms > FIT_TOLERANCE_PX:
                raise CameraFault(f"the point map does not follow a pinhole camera (fit residual {rms:.2g} px)",
                                  adapter=ADAPTER, hint=f"give {self.cfg.where}.intrinsics: {{fx, fy, cx, cy}}")
            self._fitted, self.fit_rms = values, rms
        fx, fy, cx, cy = values
        return Intrinsics(w, h, fx, fy, cx, cy)

    # ------------------------------------------------------------------ the rest
    def describe(self) -> dict:
        """What the adapter found (for ``recon station check`` and logs)."""
        c = self.coordinates
        return {"adapter": ADAPTER, "producers": self.producers, **self.device, "trigger": self.trigger,
                "depth_unit_m": c.unit, "coordinate_scale": c.scale, "coordinate_offset": c.offset,
                "intrinsics_source": self.intrinsics_source}

    def close(self) -> None:
        """Stop acquisition and release the device and the producers (idempotent)."""
        ia, h = self._ia, self._h
        self._ia = self._h = None
        try:
            if ia is not None:
                if self._acquiring:
                    ia.stop()
                if self.trigger == "software":
                    write_node(self._nm, "TriggerMode", "Off")  # leave the device free-running, as found
                ia.destroy()
        finally:
            if h is not None:
                h.reset()

    def __enter__(self) -> GenICamCamera:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _safe(info, attr: str):
    try:
        return getattr(info, attr, None)
    except Exception:  # noqa: BLE001 - a producer may refuse any property
        return None


def _keeping_ctrl_c(make):
    """``make()`` with recon's Ctrl-C handler kept: harvesters' image acquirer replaces the
    SIGINT handler of the main thread with its own, which only stops its acquisition, so that
    Ctrl-C would no longer reach the run (and stop the robot)."""
    if threading.current_thread() is not threading.main_thread():
        return make()
    handler = signal.getsignal(signal.SIGINT)
    try:
        return make()
    finally:
        if handler is not None:
            signal.signal(signal.SIGINT, handler)


def open_camera(cfg: GenICamConfig) -> GenICamCamera:
    """Load the producers, open the device of ``cfg.serial`` and set it up for capture."""
    require_driver("harvesters.core", INSTALL, "GenICam")
    require_driver("genicam.genapi", INSTALL, "GenICam")
    from harvesters.core import Harvester

    producers = producer_files(cfg)
    h = Harvester()
    try:
        for path in producers:
            h.add_file(path)
        h.update()
        info = choose_device(list(h.device_info_list), cfg.serial, producers)
        try:
            ia = _keeping_ctrl_c(lambda: h.create(info))
        except Exception as exc:  # noqa: BLE001 - GenTL access errors come in many types
            raise CameraFault(f"cannot open the GenICam device {_device_names(info)[:1]} ({exc})", adapter=ADAPTER,
                              hint="is another program using the camera?") from None
        try:
            return GenICamCamera(cfg, h, ia, info, producers)
        except BaseException:
            ia.destroy()
            raise
    except BaseException:
        h.reset()
        raise
