"""Two-sided scanning: side 2 (the object turned over) registered onto side 1 by shape.

Synthetic sides: the object's surface sampled, the points visible from 8 cameras on a
hemisphere above the table (Open3D's hidden point removal) kept, those within 5 mm of the
table dropped, normals turned toward the camera that saw them, noise of 0.3 mm. Side 2 is
the object turned by 180 deg about a horizontal axis, turned about the vertical and moved on
the table: the true side1_T_side2 is known. Run with -s for a table of the numbers.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import cache

import numpy as np
import open3d as o3d
import pytest

from recon_cli.errors import InputError
from recon_cli.geometry.transforms import invert, pose, rot_z, rotation_angle, transform_points
from recon_cli.objects import SceneObject, load_object, ycb_path
from recon_cli.reconstruction.sides import SideRegistration, SidesOptions, register_sides
from tests.conftest import SHARED_DATA

VOXEL = 0.003  # [m] registration voxel
NOISE = 0.0003  # [m] standard deviation of the points (each axis)
BAND = 0.005  # [m] dropped above the table: what each side misses besides what faces the table
YCB = ("drill", "mustard")


@dataclass(frozen=True)
class Case:
    obj: SceneObject
    side1: o3d.geometry.PointCloud
    side2: o3d.geometry.PointCloud
    side2_clean: np.ndarray  # (N, 3) side 2's points without the noise
    side1_T_side2: np.ndarray  # (4, 4) the truth


def _visible(obj: SceneObject, world_T_object: np.ndarray, rng: np.random.Generator, n: int = 20_000,
             views: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Points and normals (N, 3) of the surface seen from cameras on a hemisphere above the
    table (elevations 25 and 60 deg alternating), without those within BAND of the table."""
    p = replace(obj, world_T_object=world_T_object).surface_points(n, rng, exclude_base=-1.0)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.004, max_nn=30))
    normals = np.asarray(cloud.normals).copy()
    centre, diameter = (p.min(axis=0) + p.max(axis=0)) / 2.0, float(np.linalg.norm(np.ptp(p, axis=0)))
    camera = np.full((len(p), 3), np.nan)  # the first camera that saw each point
    for k in range(views):
        azimuth, elevation = 2.0 * math.pi * k / views, math.radians(25.0 if k % 2 == 0 else 60.0)
        eye = centre + 0.5 * np.array([math.cos(elevation) * math.cos(azimuth),
                                       math.cos(elevation) * math.sin(azimuth), math.sin(elevation)])
        seen = np.asarray(cloud.hidden_point_removal(eye, 100.0 * diameter)[1], dtype=int)
        seen = seen[np.isnan(camera[seen, 0])]
        camera[seen] = eye
    keep = ~np.isnan(camera[:, 0]) & (p[:, 2] > p[:, 2].min() + BAND)
    p, normals, camera = p[keep], normals[keep], camera[keep]
    normals[np.sum(normals * (camera - p), axis=1) < 0.0] *= -1.0
    return p, normals


def _cloud(points: np.ndarray, normals: np.ndarray) -> o3d.geometry.PointCloud:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.normals = o3d.utility.Vector3dVector(normals)
    return cloud


def _turned_over(obj: SceneObject, axis_azimuth: float = 0.4, yaw: float = 0.7,
                 shift: tuple[float, float] = (0.03, -0.02)) -> np.ndarray:
    """world_T_object of the object turned by 180 deg about a horizontal axis (``axis_azimuth``
    from x), turned by ``yaw`` about the vertical, moved by ``shift`` and set on the table."""
    from scipy.spatial.transform import Rotation

    axis = np.array([math.cos(axis_azimuth), math.sin(axis_azimuth), 0.0])
    R = rot_z(yaw) @ Rotation.from_rotvec(math.pi * axis).as_matrix() @ obj.world_T_object[:3, :3]
    lowest = float((obj.vertices @ R.T)[:, 2].min())
    t = obj.world_T_object[:3, 3] + np.array([shift[0], shift[1], 0.0])
    return pose(R, (t[0], t[1], obj.world_T_object[2, 3] - lowest))


def _object(name: str) -> SceneObject:
    if name in YCB and not ycb_path(name).exists():
        pytest.skip(f"the YCB {name} needs {ycb_path(name)} (the shared data {SHARED_DATA}), which is not here")
    return load_object(name)


@cache
def _case(name: str) -> Case:
    rng = np.random.default_rng(0)
    obj = _object(name)
    p1, n1 = _visible(obj, obj.world_T_object, rng)
    world_T_turned = _turned_over(obj)
    p2, n2 = _visible(obj, world_T_turned, rng)
    noisy1, noisy2 = p1 + rng.normal(0.0, NOISE, p1.shape), p2 + rng.normal(0.0, NOISE, p2.shape)
    return Case(obj, _cloud(noisy1, n1), _cloud(noisy2, n2), p2, obj.world_T_object @ invert(world_T_turned))


@cache
def _registered(name: str, other: str | None = None) -> tuple[SideRegistration, float]:
    """Side 2 of ``other`` (default: the same object) registered onto side 1 of ``name``, and
    the seconds it took."""
    start = time.perf_counter()
    result = register_sides(_case(name).side1, _case(other or name).side2, VOXEL, seed=0)
    return result, time.perf_counter() - start


def _errors(case: Case, side1_T_side2: np.ndarray) -> tuple[float, float]:
    """Rotation [rad] from the truth, and how far [m] side 2's centroid lands from where it should."""
    c = case.side2_clean.mean(axis=0)
    return (rotation_angle(side1_T_side2[:3, :3].T @ case.side1_T_side2[:3, :3]),
            float(np.linalg.norm(transform_points(side1_T_side2, c[None]) - transform_points(case.side1_T_side2,
                                                                                               c[None]))))


def _off_surface(case: Case, side1_T_side2: np.ndarray) -> np.ndarray:
    """Distances [m] of side 2's noise-free points, placed by the pose, from the true surface."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(case.obj.mesh_world()))
    q = transform_points(side1_T_side2, case.side2_clean).astype(np.float32)
    return scene.compute_distance(o3d.core.Tensor(q)).numpy()


def _line(name: str, result: SideRegistration, seconds: float) -> str:
    angle, shift = _errors(_case(name), result.side1_T_side2)
    return (f"{name:10s} rotation {math.degrees(angle):7.3f} deg, translation {shift * 1e3:7.3f} mm, fitness "
            f"{result.fitness:.3f} / {result.fitness_reverse:.3f}, rmse {result.rmse * 1e3:.3f} mm, overlap "
            f"{result.overlap:.2f}, {len(result.alternatives)} alternatives, {seconds:.2f} s")


@pytest.mark.parametrize("name", ["toy_blocks", "drill", "mustard"])
def test_an_object_without_symmetry_is_registered_to_a_fraction_of_a_millimetre(name):
    result, seconds = _registered(name)
    print(_line(name, result, seconds))
    angle, shift = _errors(_case(name), result.side1_T_side2)
    assert math.degrees(angle) < 0.2 and shift < 0.5e-3
    assert result.trusted and not result.ambiguous and not result.alternatives
    assert result.fitness > 0.8 and result.rmse < 1.5e-3 and result.candidates > 10


@pytest.mark.parametrize("name", ["bottle", "mug"])
def test_a_symmetric_object_is_ambiguous_in_pose_but_its_merged_shape_is_right(name):
    """The bottle is a body of revolution (any turn about its axis fits); the built-in mug is a
    closed cylinder with its handle at mid-height: turned by 180 deg about the axis through
    the handle it is itself. The pose is not unique, the merged shape is."""
    result, seconds = _registered(name)
    print(_line(name, result, seconds))
    assert result.ambiguous and not result.shape_ambiguous and result.trusted
    for side1_T_side2 in (result.side1_T_side2, *(a.side1_T_side2 for a in result.alternatives)):
        off = _off_surface(_case(name), side1_T_side2)
        assert np.quantile(off, 0.95) < 0.5e-3 and np.median(off) < 0.2e-3
    assert all(a.angle > math.radians(1.0) or a.translation > 1e-3 for a in result.alternatives)
    if name == "mug":  # a discrete symmetry: the truth is one of the poses
        errors = [_errors(_case(name), T) for T in (result.side1_T_side2, *(a.side1_T_side2
                                                                           for a in result.alternatives))]
        assert any(math.degrees(angle) < 0.2 and shift < 0.5e-3 for angle, shift in errors)


def test_a_prism_turned_over_does_not_fix_its_height():
    """The wooden block is a box: its flanks are vertical, and neither side saw the strip near
    its table (BAND), so side 2 slides along side 1's flanks: the height of the merged box is
    open. Reported as ambiguous in shape, with the reason (besides the box's 180 deg turns,
    which keep the shape)."""
    result, seconds = _registered("wood_block")
    print(_line("wood_block", result, seconds))
    assert result.ambiguous and result.shape_ambiguous and not result.trusted
    assert "shapes up to" in result.reason
    # side 2 slides along the flanks until it would stick out above side 1's top or lie under its table
    assert max(a.shape_difference for a in result.alternatives) < BAND + SidesOptions().support_band


def test_unrelated_objects_give_a_reason():
    result, _ = _registered("mug", "toy_blocks")
    assert not result.trusted and "no pose fits" in result.reason
    assert min(result.fitness, result.fitness_reverse) < SidesOptions().min_fitness and not result.alternatives


def test_the_same_seed_gives_the_same_result_to_the_last_digit():
    case = _case("mug")
    first, _ = _registered("mug")
    again = register_sides(case.side1, case.side2, VOXEL, seed=0)
    assert np.array_equal(first.side1_T_side2, again.side1_T_side2)
    assert [a.side1_T_side2.tolist() for a in first.alternatives] == [a.side1_T_side2.tolist()
                                                                       for a in again.alternatives]
    assert (first.fitness, first.rmse, first.candidates) == (again.fitness, again.rmse, again.candidates)


def test_too_few_points_or_no_voxel_is_the_users_error():
    case = _case("mug")
    few = case.side2.select_by_index(list(range(50)))
    with pytest.raises(InputError, match="side 2 has 50 points"):
        register_sides(case.side1, few, VOXEL)
    with pytest.raises(InputError, match="voxel"):
        register_sides(case.side1, case.side2, 0.0)
