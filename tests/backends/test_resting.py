"""The faces an object can rest on (recon_cli/backends/sim/resting.py), and a bowl turned
over onto its rim by physics (recon_cli/backends/sim/turnover.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from recon_cli.backends.sim.resting import resting_faces
from recon_cli.backends.sim.turnover import mass_properties, other_faces, simulate_resting, turn_over, turned
from recon_cli.geometry.transforms import pose_error
from recon_cli.objects import load_object

from ..bowl import write_bowl


def test_a_box_rests_on_its_six_faces_the_widest_most_stable() -> None:
    block = load_object("wood_block")  # 0.16 x 0.06 x 0.10 m
    _, com, _ = mass_properties(block)
    faces = resting_faces(block.vertices, com)
    assert len(faces) == 6
    # on a 0.16 x 0.10 face (normal along y) the centre of mass is 0.03 m up and 0.05 m from the nearest edge
    assert abs(faces[0].down[1]) == pytest.approx(1.0)
    assert faces[0].height == pytest.approx(0.03) and faces[0].margin == pytest.approx(0.05)
    assert faces[0].tipping_deg == pytest.approx(math.degrees(math.atan2(0.05, 0.03)))
    assert faces[-1].tipping_deg == pytest.approx(math.degrees(math.atan2(0.03, 0.08)))  # on an end: 0.06 x 0.10
    assert faces[0].area == pytest.approx(0.016)


@pytest.fixture(scope="module")
def bowl(tmp_path_factory):
    return load_object(str(write_bowl(tmp_path_factory.mktemp("bowl") / "bowl.ply")))


def test_a_bowl_has_one_other_stable_face_its_rim(bowl) -> None:
    faces, down_now = other_faces(bowl)
    assert len(faces) == 1
    np.testing.assert_allclose(faces[0].down, [0.0, 0.0, 1.0], atol=1e-9)  # the opening goes down
    assert faces[0].tipping_deg > 60.0


def test_a_bowl_turns_over_onto_its_rim_and_stays(bowl) -> None:
    t = turn_over(bowl, np.random.default_rng(0))
    assert t.tilt_deg > 179.0 and t.tried == 1 and t.faces == 1
    after = turned(bowl, t)
    lo, hi = after.world_aabb()
    assert lo[2] == pytest.approx(bowl.world_aabb()[0][2], abs=1e-3)  # the rim on the board
    moved, turned_by = pose_error(after.world_T_object, simulate_resting(after, 1.0))
    assert moved < 1e-3 and math.degrees(turned_by) < 1.0
