"""The depth sensor's figures and noise model (a sensor file: the cell file's ``camera.sensor``,
robot/camera.yaml in the thesis' cells; schemas/sensor.schema.json).

Noise model: each valid pixel's depth z is perturbed along its ray by zero-mean Gaussian
noise with sigma(z) = sigma_ref * (z / z_ref)^2 (triangulation noise grows with the square
of the distance); depths outside [z_min, z_max] and surfaces seen at more than
``max_incidence`` from the ray return no depth (0), as a structured-light sensor returns
nothing there. The colour image gets Gaussian pixel noise (``color_noise_std`` levels).
Everything is drawn from the ``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import functools
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon_cli.errors import InputError
from recon_cli.inputs.files import version_stamp
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import line_of, read_yaml
from recon_cli.paths import ROBOT_DIR
from recon_cli.perception.camera_model import Intrinsics, fovy_from_hfov, intrinsics_from_fovy
from recon_cli.robot.cell_file import CellFile

#: most pixels (width x height) of a sensor's image: the simulation renders, and every scan
#: holds, several images and buffers of this size (docs/inputs.md); the 2448 x 2048 px of
#: the largest industrial depth cameras are 5.0 million
MAX_SENSOR_PIXELS = 6_000_000


@dataclass(frozen=True)
class SensorModel:
    name: str
    width: int  # [px]
    height: int  # [px]
    hfov: float  # [rad]
    z_min: float  # [m]
    z_max: float  # [m]
    noise_sigma_ref: float  # [m] at z_ref
    noise_z_ref: float  # [m]
    max_incidence: float  # [rad]
    depth_scale: float  # depth PNG units per metre
    color_noise_std: float = 0.0  # [8-bit levels]
    scan_distance: float | None = None  # [m] default camera-to-object distance; None: see default_distance

    @property
    def default_distance(self) -> float:
        """[m] the camera-to-object distance a scan uses unless told otherwise: the sensor
        file's ``scan_distance``, else a quarter into the working range (depth noise grows
        with z^2, so the near part of the range, with room for the object's depth)."""
        if self.scan_distance is not None:
            return self.scan_distance
        return self.z_min + 0.25 * (self.z_max - self.z_min)

    @property
    def fovy(self) -> float:
        return fovy_from_hfov(self.width, self.height, self.hfov)

    def intrinsics(self, scale: float = 1.0) -> Intrinsics:
        """Intrinsics at full resolution (scale 1) or a reduced one (e.g. 0.25 in tests)."""
        w, h = round(self.width * scale), round(self.height * scale)
        return intrinsics_from_fovy(w, h, fovy_from_hfov(w, h, self.hfov))

    def sigma(self, z: np.ndarray) -> np.ndarray:
        """Depth noise standard deviation [m] at depth z [m]."""
        return self.noise_sigma_ref * (np.asarray(z) / self.noise_z_ref) ** 2

    def apply_color(self, color: np.ndarray, rng: np.random.Generator | None, noise: bool = True) -> np.ndarray:
        """Colour image with Gaussian pixel noise (uint8, same shape)."""
        if not noise or rng is None or self.color_noise_std <= 0:
            return color
        noisy = rng.standard_normal(color.shape, dtype=np.float32)
        noisy *= np.float32(self.color_noise_std)
        noisy += color  # in place, without temporaries: the same numbers as colour + noise x std
        np.rint(noisy, out=noisy)
        np.clip(noisy, 0, 255, out=noisy)
        return noisy.astype(np.uint8)

    def apply(self, depth: np.ndarray, K: Intrinsics, rng: np.random.Generator | None,
              noise: bool = True) -> np.ndarray:
        """Sensor effects on an ideal depth image [m] (0 = no return): range limits,
        grazing-angle dropout and (when ``noise``) Gaussian depth noise along the rays."""
        out = depth.astype(np.float64, copy=True)
        valid = (out >= self.z_min) & (out <= self.z_max)
        valid &= _incidence_ok(out, K, self.max_incidence)
        out[~valid] = 0.0
        if noise and rng is not None:
            z = out[valid]
            out[valid] = z + rng.standard_normal(z.shape) * self.sigma(z)
        return out


def _incidence_ok(depth: np.ndarray, K: Intrinsics, max_incidence: float) -> np.ndarray:
    """Pixels whose surface normal (from the depth image) is within max_incidence of the ray."""
    cos, edge = _incidence_cos(depth, K)
    ok = cos >= math.cos(max_incidence)
    # neighbours across a depth edge (or without depth) make no normal: keep those pixels
    return ok | edge


def _incidence_cos(depth: np.ndarray, K: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """|cos| of the angle between each pixel's ray and its surface normal (from the depth
    image), and the pixels where no normal can be made (neighbours missing or degenerate).
    The normal is the cross product of the central differences of the back-projected points
    (X, Y, Z) = depth (u, v, 1) along the image's columns and rows (zero on the border),
    computed per component with few temporaries, in two bands of rows at once (numpy lets go
    of the interpreter lock in its array operations; each pixel's arithmetic is the same)."""
    h, w = depth.shape
    d = np.asarray(depth, dtype=np.float64)
    u = (np.arange(w) - K.cx) / K.fx
    v = (np.arange(h) - K.cy) / K.fy
    if h < BAND_ROWS:
        return _incidence_band(d, u, v)
    m = h // 2
    # each band one row beyond its half: that row is the band's border (no normal), and
    # the inner neighbour of the other half
    lower = _band_pool().submit(_incidence_band, d[m - 1:], u, v[m - 1:])
    cos_top, edge_top = _incidence_band(d[:m + 1], u, v[:m + 1])
    cos_low, edge_low = lower.result()
    return np.vstack([cos_top[:m], cos_low[1:]]), np.vstack([edge_top[:m], edge_low[1:]])


#: images with fewer rows are done in one piece
BAND_ROWS = 64


@functools.cache
def _band_pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(1, thread_name_prefix="sensor-band")


def _incidence_band(d: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_incidence_cos` of the rows of ``d`` whose ray coordinates are ``v``."""
    h, w = d.shape
    right, left = d[1:-1, 2:], d[1:-1, :-2]  # neighbours along u (interior rows)
    down, up = d[2:, 1:-1], d[:-2, 1:-1]  # neighbours along v (interior columns)
    uc, vc = u[None, 1:-1], v[1:-1, None]
    zu = right - left
    zv = down - up
    xu = right * u[None, 2:]
    xu -= left * u[None, :-2]
    xv = down * uc
    xv -= up * uc
    yu = right * vc
    yu -= left * vc
    yv = down * v[2:, None]
    yv -= up * v[:-2, None]
    nx = np.zeros((h, w))
    ny = np.zeros((h, w))
    nz = np.zeros((h, w))
    inner = (slice(1, -1), slice(1, -1))
    np.multiply(yu, zv, out=nx[inner])
    nx[inner] -= zu * yv
    np.multiply(zu, xv, out=ny[inner])
    ny[inner] -= xu * zv
    np.multiply(xu, yv, out=nz[inner])
    nz[inner] -= yu * xv
    del zu, zv, xu, xv, yu, yv
    norm = nx * nx
    norm += ny * ny
    norm += nz * nz
    np.sqrt(norm, out=norm)
    ray = u[None, :] * u[None, :] + v[:, None] * v[:, None]
    ray += 1.0
    np.sqrt(ray, out=ray)
    cos = nx
    cos *= u[None, :]
    ny *= v[:, None]
    cos += ny
    cos += nz
    np.abs(cos, out=cos)
    ray *= norm
    ray += 1e-300
    with np.errstate(invalid="ignore", over="ignore"):
        cos /= ray
    edge = norm == 0
    edge |= ~np.isfinite(cos)
    return cos, edge


def motioncam_3d_m() -> SensorModel:
    """The thesis' sensor (robot/camera.yaml), the camera of the gantry and ceiling cells."""
    return sensor_file(ROBOT_DIR / "camera.yaml")


def cell_sensor(cell: CellFile) -> SensorModel:
    """The sensor of a cell (its cell file's ``camera.sensor``)."""
    return sensor_file(cell.sensor_file)


def sensor_file(path: Path) -> SensorModel:
    """A sensor file, read and checked (one line naming ``file:line`` when it is wrong)."""
    return _sensor_file(path.resolve(), version_stamp(path))


@functools.lru_cache(maxsize=8)
def _sensor_file(path: Path, stamp: tuple[int, int]) -> SensorModel:
    d = read_yaml(path, "sensor file")
    check(d, "sensor", path)

    def refuse(key: str, what: str, hint: str) -> InputError:
        line = line_of(d, key)
        return InputError(f"{path}:{line or 1}: {key}: {what}", hint=hint)

    width, height = int(d["width"]), int(d["height"])
    if width * height > MAX_SENSOR_PIXELS:  # before any image, buffer or framebuffer of that size exists
        raise refuse("width", f"{width} x {height} px are {width * height:,} pixels, more than the "
                     f"{MAX_SENSOR_PIXELS:,} of a sensor's image", f"give the depth image's size, at most "
                     f"{MAX_SENSOR_PIXELS:,} pixels (e.g. 2448 x 2048)")
    z_min, z_max = float(d["z_min"]), float(d["z_max"])
    if z_min >= z_max:
        raise refuse("z_max", f"the working range {z_min:g} ... {z_max:g} m is empty", "z_max must exceed z_min")
    scan = d.get("scan_distance")
    if scan is not None and not z_min <= float(scan) <= z_max:
        raise refuse("scan_distance", f"{float(scan):g} m lies outside the working range {z_min:g} ... {z_max:g} m",
                     "choose a distance inside the range")
    if float(d["depth_scale"]) * z_max > 65535:
        raise refuse("depth_scale", f"{float(d['depth_scale']):g} units per m cannot hold z_max = {z_max:g} m in "
                     "a 16-bit depth image", f"at most {65535 / z_max:.0f} units per m")
    return SensorModel(
        name=d["name"], width=width, height=height,
        hfov=math.radians(float(d["hfov_deg"])), z_min=z_min, z_max=z_max,
        noise_sigma_ref=float(d["noise_sigma_ref"]), noise_z_ref=float(d["noise_z_ref"]),
        max_incidence=math.radians(float(d["max_incidence_deg"])),
        depth_scale=float(d["depth_scale"]), color_noise_std=float(d.get("color_noise_std", 0.0)),
        scan_distance=None if scan is None else float(scan),
    )


# --------------------------------------------------------------------- realism profiles
# Structured-light artefacts and image effects of a realism profile (recon_cli/realism.py).
# Simple models, each documented in docs/simulation.md ("Realism profiles"); every random
# draw comes from the generator passed in.

def _grey(color: np.ndarray) -> np.ndarray:
    """Luminance (ITU-R BT.601) of an RGB image, float [0, 255]."""
    c = color.astype(np.float64)
    return 0.299 * c[..., 0] + 0.587 * c[..., 1] + 0.114 * c[..., 2]


def flying_pixels(depth: np.ndarray, share: float, edge_jump: float, rng: np.random.Generator) -> np.ndarray:
    """Mixed pixels at depth edges: a pixel whose 3 x 3 neighbourhood spans more than
    ``edge_jump`` [m] (between valid depths) gets, with probability ``share``, a depth drawn
    uniformly between the nearest and the farthest of its neighbours (the sensor saw both
    surfaces in one pixel)."""
    import cv2

    if share <= 0:
        return depth
    valid = depth > 0
    kernel = np.ones((3, 3), np.uint8)
    zmax = cv2.dilate(depth, kernel)
    zmin = cv2.erode(np.where(valid, depth, np.inf), kernel)
    edge = valid & np.isfinite(zmin) & (zmax - zmin > edge_jump)
    pick = edge & (rng.random(depth.shape) < share)
    out = depth.copy()
    t = rng.random(int(pick.sum()))
    out[pick] = zmin[pick] + t * (zmax[pick] - zmin[pick])
    return out


def dropouts(depth: np.ndarray, color: np.ndarray, K: Intrinsics, grazing: tuple[float, float] | None,
             dark_level: float, saturated_level: float, rng: np.random.Generator,
             dark_dropout: float = 1.0) -> np.ndarray:
    """Pixels that return no depth (0): at grazing incidence with a probability rising
    linearly from 0 at ``grazing[0]`` to 1 at ``grazing[1]`` [rad]; on dark surfaces (grey
    level of the colour image below ``dark_level``, probability rising linearly to
    ``dark_dropout`` at black); on saturated (specular) pixels at or above
    ``saturated_level``."""
    p = np.zeros(depth.shape)
    if grazing is not None:
        cos, edge = _incidence_cos(depth, K)
        angle = np.arccos(np.clip(np.nan_to_num(cos, nan=1.0), 0.0, 1.0))
        ramp = np.clip((angle - grazing[0]) / (grazing[1] - grazing[0]), 0.0, 1.0)
        p = np.maximum(p, np.where(edge, 0.0, ramp))
    if dark_level > 0 or saturated_level <= 255:
        grey = _grey(color)
        if dark_level > 0:
            p = np.maximum(p, dark_dropout * np.clip((dark_level - grey) / dark_level, 0.0, 1.0))
        p[grey >= saturated_level] = 1.0
    drop = (depth > 0) & (rng.random(depth.shape) < p)
    out = depth.copy()
    out[drop] = 0.0
    return out


def multipath(depth: np.ndarray, K: Intrinsics, gain: float, window: float) -> np.ndarray:
    """Multipath-like bias in concave corners: light reflected off a neighbouring surface
    lengthens the measured path where a surface lies behind its surroundings. A pixel whose
    depth exceeds the mean depth of its neighbourhood (``window`` [m] wide at the scene's
    median depth) by d reads gain * min(d, window) farther; flat and convex surfaces read
    true."""
    import cv2

    valid = depth > 0
    if gain <= 0 or not valid.any():
        return depth
    z_typ = float(np.median(depth[valid]))
    size = max(3, int(round(window * K.fx / z_typ)) | 1)
    s = cv2.boxFilter(np.where(valid, depth, 0.0), -1, (size, size), normalize=False)
    n = cv2.boxFilter(valid.astype(np.float64), -1, (size, size), normalize=False)
    mean = np.divide(s, n, out=np.zeros_like(s), where=n > 0)
    behind = np.clip(depth - mean, 0.0, window)
    return np.where(valid & (n >= 0.5 * size * size), depth + gain * behind, depth)


def quantize_depth(depth: np.ndarray, step_ref: float, z_ref: float) -> np.ndarray:
    """Depth rounded to the sensor's resolution, as a triangulating sensor resolves it: in
    steps of inverse depth (disparity, phase), ``step_ref`` [m] apart at ``z_ref`` [m] and
    so growing with z^2 (1 / z is a multiple of step_ref / z_ref^2)."""
    if step_ref <= 0:
        return depth
    valid = depth > 0
    unit = step_ref / z_ref ** 2  # [1/m]
    out = depth.copy()
    out[valid] = 1.0 / (np.round(1.0 / depth[valid] / unit) * unit)
    return out


def image_effects(color: np.ndarray, exposure: float, blur_sigma: float) -> np.ndarray:
    """Exposure gain and Gaussian blur (sigma [px] of this image) of an RGB image (uint8)."""
    import cv2

    out = color.astype(np.float32) * np.float32(exposure)
    if blur_sigma > 0:
        out = np.asarray(cv2.GaussianBlur(out, (0, 0), blur_sigma))
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)
