"""Geometry of the view planner: Eberly's nearest point against brute force, the camera
pose from a surface point, the potential field."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from recon_cli.viewplan.ellipsoid import Ellipsoid, nearest_point_on_ellipsoid
from recon_cli.viewplan.views import camera_pose, next_sample, potential

AXES = [np.array([0.3, 0.2, 0.1]), np.array([0.1, 0.25, 0.15]), np.array([0.2, 0.2, 0.05])]


def _brute(e: np.ndarray, y: np.ndarray) -> float:
    """Distance to the surface by a dense grid over (theta, phi), refined by Nelder-Mead."""
    th, ph = np.meshgrid(np.linspace(0, np.pi, 300), np.linspace(-np.pi, np.pi, 600))

    def point(t, p):
        return np.stack([e[0] * np.sin(t) * np.cos(p), e[1] * np.sin(t) * np.sin(p), e[2] * np.cos(t)], -1)

    d = np.linalg.norm(point(th, ph) - y, axis=-1)
    k = np.unravel_index(np.argmin(d), d.shape)
    best = np.inf
    for start in ([th[k], ph[k]], [th[k] + 1e-3, ph[k] - 1e-3]):
        r = minimize(lambda v: np.linalg.norm(point(v[0], v[1]) - y), start, method="Nelder-Mead",
                     options={"xatol": 1e-14, "fatol": 1e-16, "maxiter": 40000})
        best = min(best, r.fun)
    return best


@pytest.mark.parametrize("axes", AXES, ids=["e1>e2>e3", "e2>e3>e1", "e1=e2>e3"])
def test_nearest_point_matches_brute_force(axes):
    rng = np.random.default_rng(0)
    queries = [rng.normal(0, 0.3, 3) for _ in range(6)]  # mostly outside
    queries += [rng.uniform(-0.5, 0.5, 3) * axes for _ in range(4)]  # inside
    queries += [np.array([0.4, 0, 0]), np.array([0, 0, 0.02]), np.array([0, 0.05, 0]),  # on axes
                np.array([0.03, 0.0, 0.01]), np.array([0.0, -0.01, 0.3])]  # on coordinate planes
    for y in queries:
        x = nearest_point_on_ellipsoid(axes, y)
        assert abs(np.sum((x / axes) ** 2) - 1.0) < 1e-12  # on the surface
        d, b = np.linalg.norm(x - y), _brute(axes, y)
        assert d <= b * (1 + 1e-9) + 1e-15, (y, d, b)
        assert abs(d - b) <= 1e-9 * max(b, 1e-12) + 1e-12, (y, d, b)


def test_nearest_point_of_a_surface_point_is_itself():
    e = AXES[0]
    rng = np.random.default_rng(1)
    for _ in range(20):
        u = rng.normal(size=3)
        p = u / np.linalg.norm(u) * e
        assert np.allclose(nearest_point_on_ellipsoid(e, p), p, atol=1e-12)


def _rotation(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_camera_pose_from_a_surface_point():
    rng = np.random.default_rng(2)
    for _ in range(50):
        ell = Ellipsoid.from_box(rng.uniform(-1, 1, 3), _rotation(rng), rng.uniform(0.05, 0.3, 3))
        u = rng.normal(size=3)
        p = ell.surface_from_directions(u)
        T = camera_pose(ell, p, 0.55)
        n_world = ell.world_T_E[:3, :3] @ ell.normal(p)
        assert np.allclose(T[:3, 2], -n_world, atol=1e-12)  # z along the inward normal
        assert abs(T[2, 0]) < 1e-12  # x perpendicular to world z
        assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12) and np.linalg.det(T[:3, :3]) > 0
        assert np.allclose(T[:3, 3], ell.to_world(p) + 0.55 * n_world, atol=1e-12)  # eq. 2.5
    top = Ellipsoid.from_box(np.zeros(3), np.eye(3), [0.2, 0.1, 0.1])
    T = camera_pose(top, np.array([0, 0, top.axes[2]]), 0.5)  # straight down: still a rotation
    assert np.allclose(T[:3, 2], [0, 0, -1]) and abs(T[2, 0]) < 1e-12


def test_potential_prefers_samples_far_from_earlier_ones():
    ell = Ellipsoid.from_box(np.zeros(3), np.eye(3), [0.4, 0.2, 0.1])
    earlier = np.array([ell.surface_from_directions(np.array([1.0, 0, 0]))])
    near = ell.surface_from_directions(np.array([1.0, 0.1, 0]))
    far = ell.surface_from_directions(np.array([-1.0, 0, 0]))
    c = potential(ell, np.array([near, far]), earlier, 1e-5)
    assert c[1] < c[0]
    rng = np.random.default_rng(3)
    p = next_sample(ell, earlier, 200, 1e-5, rng)
    assert ell.to_world(p)[0] < 0  # the chosen sample is on the far side
    # the norm of eq. 2.8 makes the choice independent of the axes' ratio
    sphere = Ellipsoid.from_box(np.zeros(3), np.eye(3), [0.2, 0.2, 0.2])
    u = np.random.default_rng(4).normal(size=(50, 3))
    a, b = ell.surface_from_directions(u), sphere.surface_from_directions(u)
    prev_a, prev_b = a[:5], b[:5]
    assert np.allclose(potential(ell, a, prev_a, 1e-5), potential(sphere, b, prev_b, 1e-5))


def test_ellipsoid_encloses_the_box_of_the_cloud():
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1, 1, (2000, 3)) * [0.1, 0.05, 0.02] + [0.3, 0.1, 0.8]
    ell = Ellipsoid.from_cloud(pts)
    assert np.all(ell.norm(ell.to_local(pts)) <= 1.0 + 1e-9)
    assert np.allclose(sorted(ell.axes), sorted(np.array([0.2, 0.1, 0.04]) * np.sqrt(3) / 2), rtol=0.05)
