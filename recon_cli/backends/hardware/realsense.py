"""Intel RealSense depth cameras through pyrealsense2 (``pip install 'recon-scan[realsense]'``).

The adapter opens the depth and colour sensors of one device (by serial number) with the
configured stream modes and feeds both into one ``rs.syncer``; each capture drops what is
queued, waits for ``skip_frames`` + 1 new framesets (so the frame returned was exposed
after ``capture()`` was called) and aligns the colour to the depth grid with ``rs.align``.
Depth is z16 times the depth sensor's depth units [m] (set from the station file when
given); the intrinsics (and Brown-Conrady distortion, when not zero) are those of the depth
stream profile.

Any ``rs.device`` is accepted, including an ``rs.software_device`` whose frames a test
pushes in (tests/backends/test_cameras.py): the adapter uses nothing a software device
lacks (sensors, stream profiles, the depth-units option, a syncer), so it is tested through
pyrealsense2 itself, not a mock of it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from recon_cli.backends.base import RGBDFrame
from recon_cli.backends.hardware.camera_config import check_keys, number, require_driver, text
from recon_cli.errors import CameraFault, InputError
from recon_cli.perception.camera_model import Intrinsics

log = logging.getLogger(__name__)

ADAPTER = "realsense"
INSTALL = "realsense"


@dataclass(frozen=True)
class RealSenseConfig:
    """``camera.realsense`` of a station file.

    serial: the device's serial number (default: the only device); width, height [px] and fps
    of the depth stream; color_width, color_height (default: the depth stream's) of the
    colour stream (rgb8, same fps); depth_units [m per z16 unit] written to the device
    (default: the device's, 0.001 on D400); warmup_frames dropped after start (auto
    exposure settles); skip_frames dropped in every capture after the queue is emptied;
    timeout [s] for one frameset.
    """

    serial: str | None = None
    width: int = 640
    height: int = 480
    fps: int = 30
    color_width: int | None = None
    color_height: int | None = None
    depth_units: float | None = None
    warmup_frames: int = 30
    skip_frames: int = 1
    timeout: float = 5.0
    where: str = field(default="camera.realsense", compare=False, repr=False)

    @classmethod
    def from_mapping(cls, d: dict, where: str = "camera.realsense") -> RealSenseConfig:
        d = check_keys(d, where, cls)
        cfg = cls(
            serial=text(d, "serial", where, None),
            width=number(d, "width", where, 640, integer=True, positive=True),
            height=number(d, "height", where, 480, integer=True, positive=True),
            fps=number(d, "fps", where, 30, integer=True, positive=True),
            color_width=number(d, "color_width", where, None, integer=True, positive=True, optional=True),
            color_height=number(d, "color_height", where, None, integer=True, positive=True, optional=True),
            depth_units=number(d, "depth_units", where, None, positive=True, optional=True),
            warmup_frames=number(d, "warmup_frames", where, 30, integer=True, minimum=0),
            skip_frames=number(d, "skip_frames", where, 1, integer=True, minimum=0),
            timeout=number(d, "timeout", where, 5.0, positive=True),
            where=where,
        )
        if (cfg.color_width is None) != (cfg.color_height is None):
            raise InputError(f"{where}: give both color_width and color_height or neither",
                             hint="the colour stream's size [px]")
        return cfg

    @property
    def color_size(self) -> tuple[int, int]:
        return (self.color_width or self.width, self.color_height or self.height)


def _info(rs, device, key) -> str | None:
    try:
        return device.get_info(key) if device.supports(key) else None
    except RuntimeError:
        return None


def choose_device(rs, devices: list, serial: str | None):
    """The device of ``serial`` (or the only one); CameraFault listing what was found."""
    serials = [_info(rs, d, rs.camera_info.serial_number) or "?" for d in devices]
    if not devices:
        raise CameraFault("no RealSense device found", adapter=ADAPTER,
                          hint="check the USB 3 cable (rs-enumerate-devices lists what librealsense sees)")
    if serial is None:
        if len(devices) > 1:
            raise CameraFault(f"{len(devices)} RealSense devices found ({', '.join(serials)})", adapter=ADAPTER,
                              hint="choose one with camera.realsense.serial")
        return devices[0]
    if serial not in serials:
        raise CameraFault(f"no RealSense device with serial '{serial}' (found: {', '.join(serials)})",
                          adapter=ADAPTER, hint="set camera.realsense.serial to one of these")
    return devices[serials.index(serial)]


def _find_profile(rs, sensors, stream, fmt, width: int, height: int, fps: int):
    """(sensor, profile) of the first sensor that offers the mode, or CameraFault with what
    the device offers for that stream."""
    offered = []
    for sensor in sensors:
        for p in sensor.get_stream_profiles():
            if p.stream_type() != stream or not p.is_video_stream_profile():
                continue
            v = p.as_video_stream_profile()
            if p.format() == fmt and v.width() == width and v.height() == height and p.fps() == fps:
                return sensor, p
            offered.append(f"{v.width()}x{v.height()}@{p.fps()} {str(p.format()).split('.')[-1]}")
    name = str(stream).split(".")[-1]
    shown = ", ".join(sorted(set(offered))[:8]) or "none"
    raise CameraFault(f"the RealSense device offers no {name} stream {width}x{height}@{fps} "
                      f"{str(fmt).split('.')[-1]} (offered: {shown})", adapter=ADAPTER,
                      hint="choose one of the offered modes in camera.realsense")


class RealSenseCamera:
    """CameraBackend of a RealSense device (see the module docstring)."""

    def __init__(self, cfg: RealSenseConfig, device) -> None:
        import pyrealsense2 as rs

        self.cfg = cfg
        self._rs = rs
        self.device = device
        self.serial = _info(rs, device, rs.camera_info.serial_number)
        self.name = _info(rs, device, rs.camera_info.name)
        sensors = list(device.query_sensors())
        depth_sensor, depth_profile = _find_profile(rs, sensors, rs.stream.depth, rs.format.z16, cfg.width,
                                                    cfg.height, cfg.fps)
        color_sensor, color_profile = _find_profile(rs, sensors, rs.stream.color, rs.format.rgb8, *cfg.color_size,
                                                    cfg.fps)
        if cfg.depth_units is not None:
            try:
                depth_sensor.set_option(rs.option.depth_units, cfg.depth_units)
            except RuntimeError as exc:
                raise CameraFault(f"the RealSense device refuses depth_units = {cfg.depth_units} ({exc})",
                                  adapter=ADAPTER, hint="leave camera.realsense.depth_units out") from None
        self.depth_units = float(depth_sensor.get_option(rs.option.depth_units)) \
            if depth_sensor.supports(rs.option.depth_units) else 0.001
        profiles: dict[int, tuple[Any, list[Any]]] = {}  # id -> the sensor and its stream profiles
        for sensor, profile in ((depth_sensor, depth_profile), (color_sensor, color_profile)):
            profiles.setdefault(id(sensor), (sensor, []))[1].append(profile)
        self._sensors = []
        self._syncer = rs.syncer(2)
        self._align = rs.align(rs.stream.depth)
        try:
            for sensor, profs in profiles.values():
                sensor.open(profs if len(profs) > 1 else profs[0])
                self._sensors.append(sensor)
                sensor.start(self._syncer)
        except RuntimeError as exc:
            self.close()
            raise CameraFault(f"cannot start the RealSense streams ({exc})", adapter=ADAPTER,
                              hint="is another program using the camera?") from None
        intr = depth_profile.as_video_stream_profile().get_intrinsics()
        self.intrinsics = Intrinsics(intr.width, intr.height, intr.fx, intr.fy, intr.ppx, intr.ppy)
        coeffs = tuple(float(c) for c in intr.coeffs)
        self.distortion = None if not any(coeffs) else coeffs
        if self.distortion is not None and intr.model != rs.distortion.brown_conrady:
            log.warning("RealSense depth distortion model %s is taken as Brown-Conrady", intr.model)
        for _ in range(cfg.warmup_frames):
            self._next()

    def _next(self):
        """The next complete frameset (depth and colour)."""
        rs = self._rs
        for _ in range(50):
            try:
                frames = self._syncer.wait_for_frames(int(self.cfg.timeout * 1000))
            except RuntimeError:
                raise CameraFault(f"no frame from the RealSense device within {self.cfg.timeout:g} s",
                                  adapter=ADAPTER, hint="check the USB connection; raise camera.realsense.timeout") \
                    from None
            if frames.first_or_default(rs.stream.depth) and frames.first_or_default(rs.stream.color):
                return frames
        raise CameraFault("the RealSense device delivers depth and colour frames that never match",
                          adapter=ADAPTER, hint="use the same fps for both streams")

    def capture(self) -> RGBDFrame:
        if not self._sensors:
            raise CameraFault("the RealSense camera is closed", adapter=ADAPTER)
        while True:  # what is queued was exposed before this call
            ok, _ = self._syncer.try_wait_for_frames(0)
            if not ok:
                break
        for _ in range(self.cfg.skip_frames):
            self._next()
        frames = self._align.process(self._next())
        depth_frame, color_frame = frames.get_depth_frame(), frames.get_color_frame()
        depth = np.asanyarray(depth_frame.get_data()).astype(np.float64) * self.depth_units
        color = np.array(np.asanyarray(color_frame.get_data()), dtype=np.uint8, copy=True)
        return RGBDFrame(color, depth, self.intrinsics, float(frames.get_timestamp()) * 1e-3, self.distortion)

    def describe(self) -> dict:
        return {"adapter": ADAPTER, "serial": self.serial, "name": self.name, "depth_units_m": self.depth_units,
                "intrinsics": self.intrinsics.to_dict(), "distortion": self.distortion}

    def close(self) -> None:
        """Stop and close the sensors (idempotent)."""
        sensors, self._sensors = self._sensors, []
        for sensor in sensors:
            for step in (sensor.stop, sensor.close):
                try:
                    step()
                except RuntimeError as exc:
                    log.debug("RealSense sensor %s: %s", step.__name__, exc)

    def __enter__(self) -> RealSenseCamera:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_camera(cfg: RealSenseConfig, device=None) -> RealSenseCamera:
    """Open the RealSense device of ``cfg.serial`` (from a new ``rs.context``), or the given
    ``device`` (an ``rs.device`` from a context of the caller's, or an ``rs.software_device``)."""
    rs = require_driver("pyrealsense2", INSTALL, "RealSense")
    if device is None:
        device = choose_device(rs, list(rs.context().query_devices()), cfg.serial)
    elif cfg.serial is not None:
        found = _info(rs, device, rs.camera_info.serial_number)
        if found != cfg.serial:
            raise CameraFault(f"the RealSense device given has serial '{found}', not '{cfg.serial}'",
                              adapter=ADAPTER, hint="set camera.realsense.serial to it or leave it out")
    return RealSenseCamera(cfg, device)
