"""Turning an object over by physics (recon_cli/backends/sim/turnover.py): every object ends
at rest on another face, back on its spot, the same for the same seed, and stays put."""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np
import pytest

from recon_cli.backends.sim import turnover
from recon_cli.backends.sim.turnover import mass_properties, simulate_resting, turn_over, turned
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import pose_error
from recon_cli.objects import BUILTIN, SceneObject, load_object, ycb_names

from ..conftest import SHARED_DATA

NO_YCB = pytest.mark.skipif(not (SHARED_DATA / "ycb").is_dir(), reason=f"the YCB meshes are not in {SHARED_DATA}")
OBJECTS = [*BUILTIN, *(pytest.param(name, marks=NO_YCB) for name in ycb_names())]


@functools.cache
def _object(name: str) -> SceneObject:
    return load_object(name)


@functools.cache
def _turn(name: str, seed: int) -> turnover.TurnOver:
    return turn_over(_object(name), np.random.default_rng(seed))


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("name", OBJECTS)
def test_turned_over_onto_another_face_and_back_on_its_spot(name: str, seed: int) -> None:
    obj = _object(name)
    t = _turn(name, seed)
    after = turned(obj, t)
    lo, hi = obj.world_aabb()
    new_lo, new_hi = after.world_aabb()
    assert abs(new_lo[2] - lo[2]) < 1e-3  # lying on the surface it stood on
    np.testing.assert_allclose((new_lo + new_hi)[:2] / 2.0, (lo + hi)[:2] / 2.0, atol=1e-9)
    up_before = obj.world_T_object[:3, :3].T @ [0.0, 0.0, 1.0]
    tilt = math.degrees(math.acos(np.clip((t.world_T_object[:3, :3] @ up_before)[2], -1.0, 1.0)))
    assert tilt == pytest.approx(t.tilt_deg, abs=1e-6)
    assert t.tilt_deg > 60.0  # another face down
    np.testing.assert_allclose(t.world_T_object[:3, :3] @ t.down_object, [0.0, 0.0, -1.0], atol=1e-9)
    assert 0.0 < t.settle_s < turnover.TIMEOUT_S
    assert turnover.DROP_M[0] <= t.dropped_from <= turnover.DROP_M[1]


@pytest.mark.parametrize("name", OBJECTS)
def test_the_resting_pose_is_stable(name: str) -> None:
    after = turned(_object(name), _turn(name, 0))
    moved, turned_by = pose_error(after.world_T_object, simulate_resting(after, 1.0))
    assert moved < 1e-3 and math.degrees(turned_by) < 1.0


@pytest.mark.parametrize("name", OBJECTS)
def test_the_same_seed_gives_the_same_pose(name: str) -> None:
    again = turn_over(_object(name), np.random.default_rng(0))
    np.testing.assert_array_equal(again.world_T_object, _turn(name, 0).world_T_object)
    assert again.settle_s == _turn(name, 0).settle_s


def test_turned_is_a_copy_at_the_new_pose() -> None:
    obj = _object("wood_block")
    t = _turn("wood_block", 0)
    after = turned(obj, t)
    np.testing.assert_array_equal(after.world_T_object, t.world_T_object)
    assert after.vertices is obj.vertices and after.name == obj.name
    assert not np.array_equal(obj.world_T_object, t.world_T_object)  # the original stays where it was


def test_a_face_physics_does_not_confirm_is_followed_by_the_next(monkeypatch) -> None:
    real = turnover._Sim.settle
    calls = []

    def first_lands_as_before(self, world_T_object, name):
        calls.append(world_T_object)
        if len(calls) == 1:
            return _object("wood_block").world_T_object.copy(), 0.5
        return real(self, world_T_object, name)

    monkeypatch.setattr(turnover._Sim, "settle", first_lands_as_before)
    t = turn_over(_object("wood_block"), np.random.default_rng(0))
    assert len(calls) == 2 and t.tilt_deg > 60.0 and t.tried == 2


def test_an_object_that_settles_on_no_face_it_is_put_on_is_an_error(monkeypatch) -> None:
    monkeypatch.setattr(turnover, "MAX_ATTEMPTS", 2)
    monkeypatch.setattr(turnover._Sim, "settle", lambda self, T, name: (_object("wood_block").world_T_object.copy(),
                                                                          0.5))
    with pytest.raises(ReconError, match="settled on none of the 2 stable faces it was put on"):
        turn_over(_object("wood_block"), np.random.default_rng(0))


def test_an_object_with_no_other_stable_face_is_one_line(monkeypatch) -> None:
    # every face of the block counted as the one it stands on
    monkeypatch.setattr(turnover, "MIN_TILT_DEG", 181.0)
    with pytest.raises(ReconError) as e:
        turn_over(_object("wood_block"), np.random.default_rng(0))
    line = e.value.one_line()
    assert "the object 'wood_block' cannot be turned over: its convex hull has no stable face but the one it stands " \
           "on" in line and "--sides 1" in line and "\n" not in line


def test_an_object_still_moving_at_the_time_out_is_an_error(monkeypatch) -> None:
    monkeypatch.setattr(turnover, "TIMEOUT_S", 0.1)
    with pytest.raises(ReconError, match="did not come to rest within 0.1 s"):
        turn_over(_object("bottle"), np.random.default_rng(0))


def test_mass_properties_of_a_box_from_primitives_mesh_and_hull() -> None:
    block = _object("wood_block")  # 0.16 x 0.06 x 0.10 m, base on z = 0
    a, b, c = 0.16, 0.06, 0.10
    mass = turnover.DENSITY * a * b * c
    inertia = np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * mass / 12.0
    open_mesh = replace(block, primitives=(), triangles=block.triangles[:-1])  # one face missing: its hull
    for obj in (block, replace(block, primitives=()), open_mesh):
        m, com, J = mass_properties(obj)
        assert m == pytest.approx(mass, rel=1e-9)
        np.testing.assert_allclose(com, [0.0, 0.0, c / 2.0], atol=1e-12)
        np.testing.assert_allclose(J, inertia, rtol=1e-6, atol=1e-12)
