"""A RealSense stand-in: pyrealsense2's own ``software_device`` with a depth and a colour
sensor, fed from a thread the way a camera streams.

Depth is a plane at ``depth`` [m] in z16 units of ``units`` [m]; colour is white on the left
half and black on the right; the colour camera sits ``baseline`` [m] along x from the depth
camera (its extrinsics registered), so colour aligned to depth moves by
fx * baseline / depth pixels. Frame n has timestamp n ms, so a test can tell which frames
were pushed before a capture began (``pushed``).
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pyrealsense2 as rs


def _intrinsics(width: int, height: int, f: float):
    k = rs.intrinsics()
    k.width, k.height, k.fx, k.fy, k.ppx, k.ppy = width, height, f, f, width / 2, height / 2
    k.model = rs.distortion.brown_conrady
    k.coeffs = [0.0] * 5
    return k


def _stream(kind, uid: int, fmt, bpp: int, width: int, height: int, fps: int, f: float):
    s = rs.video_stream()
    s.type, s.index, s.uid = kind, 0, uid
    s.width, s.height, s.fps, s.bpp, s.fmt = width, height, fps, bpp, fmt
    s.intrinsics = _intrinsics(width, height, f)
    return s


class SoftwareRealSense:
    def __init__(self, serial: str = "SW-0001", width: int = 64, height: int = 48, fps: int = 30, f: float = 50.0,
                 depth: float = 0.5, units: float = 1e-4, baseline: float = 0.05, period: float = 0.004) -> None:
        self.width, self.height, self.f = width, height, f
        self.depth, self.units, self.baseline, self.period = depth, units, baseline, period
        self.device = rs.software_device()
        self.device.register_info(rs.camera_info.serial_number, serial)
        self.device.register_info(rs.camera_info.name, "software RealSense stand-in")
        self.depth_sensor = self.device.add_sensor("Stereo Module")
        self.color_sensor = self.device.add_sensor("RGB Camera")
        self.depth_profile = self.depth_sensor.add_video_stream(
            _stream(rs.stream.depth, 0, rs.format.z16, 2, width, height, fps, f))
        self.depth_sensor.add_read_only_option(rs.option.depth_units, units)
        self.color_profile = self.color_sensor.add_video_stream(
            _stream(rs.stream.color, 1, rs.format.rgb8, 3, width, height, fps, f))
        extrinsics = rs.extrinsics()
        extrinsics.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        extrinsics.translation = [baseline, 0.0, 0.0]  # colour -> depth
        self.color_profile.register_extrinsics_to(self.depth_profile, extrinsics)
        self.device.create_matcher(rs.matchers.dlr_c)
        self.depth_pixels = np.full((height, width), round(depth / units), np.uint16).tobytes()
        color = np.zeros((height, width, 3), np.uint8)
        color[:, : width // 2] = 255
        self.color_pixels = color.tobytes()
        self.pushed = 0  # frames pushed so far (frame n has timestamp n ms)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def start(self) -> SoftwareRealSense:
        self._thread.start()
        return self

    def _push(self, n: int) -> None:
        for sensor, profile, pixels, bpp in ((self.depth_sensor, self.depth_profile, self.depth_pixels, 2),
                                             (self.color_sensor, self.color_profile, self.color_pixels, 3)):
            frame = rs.software_video_frame()
            frame.pixels = pixels
            frame.stride, frame.bpp = self.width * bpp, bpp
            frame.timestamp = float(n)  # [ms]
            frame.domain = rs.timestamp_domain.hardware_clock
            frame.frame_number = n
            frame.profile = profile.as_video_stream_profile()
            sensor.on_video_frame(frame)

    def _run(self) -> None:
        n = 0
        while not self._stop.is_set():
            n += 1
            self._push(n)
            self.pushed = n
            time.sleep(self.period)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
