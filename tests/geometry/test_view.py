"""Property tests of the view geometry (thesis 2.1.2)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from recon_cli.errors import InvalidViewError
from recon_cli.geometry.transforms import invert, pose_from_xyz_rpy
from recon_cli.geometry.view import Frame, View, look_at_pose, world_T_camera

coord = st.floats(-1.0, 1.0)
angle = st.floats(-2 * np.pi, 2 * np.pi)
views = st.builds(
    View,
    focus=st.tuples(coord, coord, st.floats(0.0, 1.5)),
    radius=st.floats(0.05, 2.0),
    theta=st.floats(0.0, np.pi),
    phi=angle,
    alpha=angle,
)


@given(views)
def test_camera_z_axis_passes_through_focus(view):
    T = view.frame_T_camera()
    assert T[:3, :3].T @ T[:3, :3] == pytest.approx(np.eye(3), abs=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    # the focus point lies on the optical axis, r in front of the camera
    f_cam = invert(T) @ np.append(view.focus, 1.0)
    assert f_cam[:3] == pytest.approx([0, 0, view.radius], abs=1e-9)


@given(views)
def test_zero_roll_keeps_camera_x_horizontal(view):
    v0 = View(view.focus, view.radius, view.theta, view.phi, 0.0)
    T = v0.frame_T_camera()
    assert T[2, 0] == pytest.approx(0.0, abs=1e-12)
    if np.sin(view.theta) > 1e-6:  # image "down" points downward in the world
        assert T[2, 1] < 0


@given(views)
def test_roll_turns_about_the_viewing_axis(view):
    T0 = View(view.focus, view.radius, view.theta, view.phi, 0.0).frame_T_camera()
    Ta = view.frame_T_camera()
    assert Ta[:3, 3] == pytest.approx(T0[:3, 3])
    assert Ta[:3, 2] == pytest.approx(T0[:3, 2], abs=1e-12)
    c = float(Ta[:3, 0] @ T0[:3, 0])
    assert c == pytest.approx(np.cos(view.alpha), abs=1e-9)


@settings(max_examples=50)
@given(views, st.tuples(coord, coord, coord), st.tuples(angle, angle, angle))
def test_world_and_marker_frame_agree(view, xyz, rpy):
    world_T_marker = pose_from_xyz_rpy(xyz, rpy)
    in_marker = View(view.focus, view.radius, view.theta, view.phi, view.alpha, Frame.MARKER)
    T_from_marker = world_T_camera(in_marker, world_T_marker)
    # the same view expressed in the world: the camera pose in the marker frame, moved
    T_expected = world_T_marker @ in_marker.frame_T_camera()
    assert T_from_marker == pytest.approx(T_expected, abs=1e-12)
    # and the focus point, mapped to the world, still lies on the optical axis
    f_world = world_T_marker @ np.append(view.focus, 1.0)
    f_cam = invert(T_from_marker) @ f_world
    assert f_cam[:3] == pytest.approx([0, 0, view.radius], abs=1e-9)


def test_marker_view_on_the_real_board(gantry):
    """f given in the marker frame at the board centre equals f = (0, 0, 0.683) in the world
    with the azimuth turned by the board's 90 deg yaw."""
    m = View.from_degrees((0.1925, 0.1225, 0.0), 0.6, 60, 0, 0, Frame.MARKER)
    w = View.from_degrees((0.0, 0.0, 0.683), 0.6, 60, 90, 0, Frame.WORLD)
    assert gantry.view_pose(m) == pytest.approx(gantry.view_pose(w), abs=1e-12)


def test_eq_4_1_first_view():
    T = View.from_degrees((0, 0, 0.78), 0.6, 70, 0).frame_T_camera()
    assert T[:3, 3] == pytest.approx([0.6 * np.sin(np.radians(70)), 0, 0.78 + 0.6 * np.cos(np.radians(70))])
    assert T[:3, 0] == pytest.approx([0, 1, 0])  # x to the right when looking along -x


def test_look_at_pose():
    T = look_at_pose(np.array([1.0, 0, 1]), np.array([0.0, 0, 1]))
    assert T[:3, 2] == pytest.approx([-1, 0, 0])
    assert T[2, 0] == pytest.approx(0) and T[2, 1] == pytest.approx(-1)


def test_bad_radius_is_refused():
    with pytest.raises(InvalidViewError, match="not positive"):
        View((0, 0, 0), 0.0, 0.1, 0.0)
    with pytest.raises(InvalidViewError, match="non-finite"):
        View((0, 0, float("nan")), 0.5, 0.1, 0.0)
