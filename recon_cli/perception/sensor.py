"""The depth sensor's figures and noise model (robot/camera.yaml).

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
from dataclasses import dataclass

import numpy as np
import yaml

from recon_cli.paths import ROBOT_DIR
from recon_cli.perception.camera_model import Intrinsics, fovy_from_hfov, intrinsics_from_fovy


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
        noisy = color.astype(np.float32) + rng.standard_normal(color.shape, dtype=np.float32) * self.color_noise_std
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

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
    h, w = depth.shape
    u = (np.arange(w) - K.cx) / K.fx
    v = (np.arange(h) - K.cy) / K.fy
    X = depth * u[None, :]
    Y = depth * v[:, None]
    P = np.stack([X, Y, depth], axis=-1)
    du = np.zeros_like(P)
    dv = np.zeros_like(P)
    du[:, 1:-1] = P[:, 2:] - P[:, :-2]
    dv[1:-1, :] = P[2:, :] - P[:-2, :]
    n = np.cross(du, dv)
    norm = np.linalg.norm(n, axis=-1)
    ray = np.stack([np.broadcast_to(u[None, :], (h, w)), np.broadcast_to(v[:, None], (h, w)),
                    np.ones((h, w))], axis=-1)
    cos = np.abs(np.sum(n * ray, axis=-1)) / (norm * np.linalg.norm(ray, axis=-1) + 1e-300)
    ok = cos >= math.cos(max_incidence)
    # neighbours across a depth edge (or without depth) make no normal: keep those pixels
    edge = (norm == 0) | ~np.isfinite(cos)
    return ok | edge


@functools.lru_cache(maxsize=1)
def motioncam_3d_m() -> SensorModel:
    with open(ROBOT_DIR / "camera.yaml") as f:
        d = yaml.safe_load(f)
    return SensorModel(
        name=d["name"], width=int(d["width"]), height=int(d["height"]),
        hfov=math.radians(float(d["hfov_deg"])), z_min=float(d["z_min"]), z_max=float(d["z_max"]),
        noise_sigma_ref=float(d["noise_sigma_ref"]), noise_z_ref=float(d["noise_z_ref"]),
        max_incidence=math.radians(float(d["max_incidence_deg"])),
        depth_scale=float(d["depth_scale"]), color_noise_std=float(d.get("color_noise_std", 0.0)),
    )
