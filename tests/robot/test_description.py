"""The xacro description expands for both cells and carries the documented limits."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import yaml

from recon_cli.errors import InputError, UnknownNameError
from recon_cli.paths import ROBOT_DIR
from recon_cli.robot.description import CellConfig, CellKind, expand_urdf

GANTRY_JOINTS = ("base_joint_1", "base_joint_2") + tuple(f"arm_joint_{i}" for i in range(1, 8))


@pytest.mark.parametrize("kind, nq", [(CellKind.GANTRY, 9), (CellKind.CEILING, 7)])
def test_urdf_loads_in_pinocchio(kind, nq):
    model = pin.buildModelFromXML(expand_urdf(CellConfig(kind=kind)))
    assert model.nq == nq
    assert tuple(model.names[1:]) == GANTRY_JOINTS[9 - nq:]
    for frame in ("camera", "marker", "arm_link_7", "table_link_2"):
        assert model.existFrame(frame)


def test_limits_follow_limits_yaml(gantry):
    spec = yaml.safe_load((ROBOT_DIR / "limits.yaml").read_text())
    lim = gantry.limits
    for i, name in enumerate(lim.names):
        entry = spec["joints"][name]
        k = math.pi / 180.0 if entry["type"] == "revolute" else 1.0
        assert lim.lower[i] == pytest.approx(entry["lower"] * k)
        assert lim.upper[i] == pytest.approx(entry["upper"] * k)
        assert lim.velocity[i] == pytest.approx(entry["velocity"] * k)
        assert lim.acceleration[i] == pytest.approx(entry["acceleration"] * k)
        margin = math.radians(10.0) if entry["type"] == "revolute" else 0.0
        assert lim.soft_lower[i] == pytest.approx(lim.lower[i] + margin)
        assert lim.soft_upper[i] == pytest.approx(lim.upper[i] - margin)


def test_published_iiwa_limits(gantry):
    lim = gantry.limits
    arm = slice(2, 9)
    assert np.degrees(lim.upper[arm]) == pytest.approx([170, 120, 170, 120, 170, 120, 175])
    assert np.degrees(lim.velocity[arm]) == pytest.approx([85, 85, 100, 75, 130, 135, 135])


def test_safety_distance_inflates_shapes():
    from recon_cli.robot.cell import Cell

    thin = Cell(CellConfig(safety_distance=0.0))
    fat = Cell(CellConfig(safety_distance=0.05))
    by_name = {s.label: s for s in thin.collision.env_shapes + thin.collision.robot_shapes}
    for s in fat.collision.env_shapes + fat.collision.robot_shapes:
        ref = by_name[s.label]
        if s.kind == "box":
            grow = np.array(s.dims) - np.array(ref.dims)
            assert grow[:2] == pytest.approx([0.1, 0.1])
            assert grow[2] in (pytest.approx(0.1), pytest.approx(0.05))  # floor boxes: +sd
        elif s.kind == "capsule":
            assert s.dims[0] == pytest.approx(ref.dims[0] + 0.05)
            assert s.dims[1] == pytest.approx(ref.dims[1])  # length between the centres
        else:
            assert s.dims[0] == pytest.approx(ref.dims[0] + 0.05)


def test_robot_collision_shapes_are_capsules_and_boxes(gantry):
    kinds = {s.link: s.kind for s in gantry.collision.robot_shapes}
    for i in range(1, 7):
        assert kinds[f"arm_link_{i}"] == "capsule"
    assert kinds["camera_link_1"] == "box"
    assert {s.kind for s in gantry.collision.env_shapes} == {"box"}


def test_unknown_cell_and_bad_arguments():
    with pytest.raises(UnknownNameError, match="gantry, ceiling"):
        CellConfig(kind="scara")
    with pytest.raises(InputError, match="safety distance"):
        CellConfig(safety_distance=-0.1)
    with pytest.raises(InputError, match="table lift"):
        CellConfig(table_lift=2.0)


def test_a_hand_eye_matrix_written_with_five_decimals_is_used_as_the_nearest_rotation():
    import math

    import numpy as np

    from recon_cli.errors import InputError
    from recon_cli.robot.description import CellConfig

    c, s = math.cos(0.3), math.sin(0.3)
    rows = [[0.0, round(-s, 5), round(c, 5), -0.0289], [1.0, 0.0, 0.0, 0.0], [0.0, round(c, 5), round(s, 5), 0.05],
            [0.0, 0.0, 0.0, 1.0]]
    written = np.array(rows)
    assert np.abs(written[:3, :3].T @ written[:3, :3] - np.eye(3)).max() > 1e-6  # not orthonormal to 1e-6
    used = np.array(CellConfig(flange_T_camera=tuple(v for r in rows for v in r)).flange_T_camera).reshape(4, 4)
    assert np.abs(used[:3, :3].T @ used[:3, :3] - np.eye(3)).max() < 1e-12
    assert np.abs(used - written).max() < 1e-5 and np.array_equal(used[:3, 3], written[:3, 3])
    mirrored = [[-1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]]
    with pytest.raises(InputError, match="not a rigid"):
        CellConfig(flange_T_camera=tuple(v for r in mirrored for v in r))
