"""Capsules fitted to collision meshes: every vertex inside, near-minimal, written as
shapes.xacro's geom_capsule writes one, read by pinocchio and the collision model; a
robot description with collision meshes works as a cell; bad mesh references are one line."""

from __future__ import annotations

import math
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import open3d as o3d
import pinocchio as pin
import pytest
from lxml import etree

from recon_cli.errors import InputError
from recon_cli.geometry.transforms import pose_from_xyz_rpy, transform_points
from recon_cli.robot.capsule_fit import FittedCapsule, fit_capsule, fit_mesh_collisions, resolve_mesh
from recon_cli.robot.collision import shapes_from_urdf

SD = 0.02
ROT = (0.3, -0.5, 0.7)  # a rotation of the test meshes in their files (rpy)


def _segment_distance(points: np.ndarray, p1, p2) -> np.ndarray:
    p1, p2 = np.asarray(p1, float), np.asarray(p2, float)
    d = p2 - p1
    t = np.clip((points - p1) @ d / max(float(d @ d), 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (p1 + t[:, None] * d), axis=1)


def _cylinder(radius: float, length: float, resolution: int = 64, split: int = 4) -> o3d.geometry.TriangleMesh:
    """A cylinder along z, centred at the origin."""
    return o3d.geometry.TriangleMesh.create_cylinder(radius, length, resolution=resolution, split=split)


def _write(mesh: o3d.geometry.TriangleMesh, path: Path) -> np.ndarray:
    """The mesh written to path; the vertices as read back (STL holds single precision)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".stl":
        mesh.compute_triangle_normals()  # the STL writer needs them
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    return np.asarray(o3d.io.read_triangle_mesh(str(path)).vertices, dtype=np.float64)


# ----------------------------------------------------------------------------- the fit
def test_a_cylinder_gets_a_capsule_of_its_radius_and_axis():
    T = pose_from_xyz_rpy((0.1, -0.2, 0.3), ROT)
    points = transform_points(T, np.asarray(_cylinder(0.05, 0.3).vertices))
    p1, p2, r = fit_capsule(points)
    assert _segment_distance(points, p1, p2).max() <= r
    assert abs(r - 0.05) <= 0.05 * 0.05  # within 5 % of the true radius (0.9 % above it)
    axis = (p2 - p1) / np.linalg.norm(p2 - p1)
    assert abs(axis @ T[:3, 2]) > 0.9999
    assert 0.27 <= np.linalg.norm(p2 - p1) <= 0.3
    assert np.allclose((p1 + p2) / 2.0, T[:3, 3], atol=1e-3)
    # near-minimal: the capsule of the cylinder's own radius and length is larger
    volume = math.pi * r * r * np.linalg.norm(p2 - p1) + 4.0 / 3.0 * math.pi * r**3
    assert volume <= math.pi * 0.05**2 * 0.3 + 4.0 / 3.0 * math.pi * 0.05**3


def test_a_box_and_a_sphere_are_contained_tightly():
    box = o3d.geometry.TriangleMesh.create_box(0.1, 0.2, 0.6)
    points = transform_points(pose_from_xyz_rpy((0.0, 0.5, 0.0), ROT), np.asarray(box.vertices))
    p1, p2, r = fit_capsule(points)
    assert _segment_distance(points, p1, p2).max() <= r
    assert r < 0.13 and np.linalg.norm(p2 - p1) < 0.6  # the long edge is the axis
    sphere = np.asarray(o3d.geometry.TriangleMesh.create_sphere(0.1, resolution=40).vertices) + 1.0
    p1, p2, r = fit_capsule(sphere)
    assert _segment_distance(sphere, p1, p2).max() <= r
    assert abs(r - 0.1) < 1e-3 and np.linalg.norm(p2 - p1) < 1e-3


@pytest.mark.parametrize("points", [
    np.full((4, 3), 0.25),  # one point
    np.outer(np.linspace(-1.0, 1.0, 9), [0.1, 0.2, 0.3]),  # a line
    np.column_stack([np.random.default_rng(3).random((40, 2)), np.full(40, 0.5)]),  # a plane
    np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]]),  # three points
], ids=["point", "line", "plane", "triangle"])
def test_degenerate_points_give_a_valid_capsule(points):
    p1, p2, r = fit_capsule(points)
    assert np.isfinite([*p1, *p2, r]).all() and r > 0.0
    assert np.linalg.norm(p2 - p1) >= 1e-6 * 0.999
    assert _segment_distance(points, p1, p2).max() <= r


def test_a_50k_vertex_mesh_fits_fast_and_the_same_every_time():
    points = transform_points(pose_from_xyz_rpy((0.1, 0.0, 0.2), ROT),
                              np.asarray(_cylinder(0.05, 0.3, resolution=400, split=120).vertices))
    assert len(points) > 48000
    fit_capsule(points[:50])  # imports
    start = time.perf_counter()
    p1, p2, r = fit_capsule(points)
    elapsed = time.perf_counter() - start
    assert elapsed < 1.0, f"{elapsed:.2f} s"
    assert _segment_distance(points, p1, p2).max() <= r and abs(r - 0.05) < 0.0025
    again = fit_capsule(points)
    assert np.array_equal(again[0], p1) and np.array_equal(again[1], p2) and again[2] == r


# ----------------------------------------------------------------------------- a robot with meshes
URDF = """<?xml version="1.0"?>
<robot name="toy">
  <material name="grey"><color rgba="0.6 0.6 0.6 1"/></material>
  <link name="world"/>
  <joint name="table_joint" type="fixed">
    <parent link="world"/><child link="table"/><origin xyz="0.6 0 0" rpy="0 0 0"/>
  </joint>
  <link name="table">
    <visual><origin xyz="0 0 0.2"/><geometry><box size="0.4 0.8 0.4"/></geometry></visual>
    <collision name="table_top"><origin xyz="0 0 0.2"/><geometry><box size="0.4 0.8 0.4"/></geometry></collision>
  </link>
  <joint name="marker_joint" type="fixed">
    <parent link="table"/><child link="marker"/><origin xyz="-0.15 -0.1 0.4" rpy="0 0 0"/>
  </joint>
  <link name="marker"/>
  <joint name="base_joint" type="fixed">
    <parent link="world"/><child link="base_link"/><origin xyz="0 0 0" rpy="0 0 0"/>
  </joint>
  <link name="base_link">
    <visual><geometry><mesh filename="package://toy_description/meshes/base.dae"/></geometry>
      <material name="grey"/></visual>
    <collision><origin xyz="0 0 0.05" rpy="0 0 0"/><geometry><mesh filename="{base_link}"/></geometry></collision>
  </link>
  <joint name="joint_1" type="revolute">
    <parent link="base_link"/><child link="link_1"/><origin xyz="0 0 0.1" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2.9" upper="2.9" velocity="2.0" effort="100"/>
  </joint>
  <link name="link_1">
    <inertial><mass value="2.0"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <visual><origin xyz="0 0 0.15"/><geometry><mesh filename="{link_1}"/></geometry></visual>
    <collision><origin xyz="0 0 0.15" rpy="0 0 0"/><geometry><mesh filename="{link_1}"/></geometry></collision>
  </link>
  <joint name="joint_2" type="revolute">
    <parent link="link_1"/><child link="link_2"/><origin xyz="0 0 0.3" rpy="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2.0" upper="2.0" velocity="2.0" effort="100"/>
  </joint>
  <link name="link_2">
    <inertial><mass value="1.5"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision name="elbow"><origin xyz="0 0 0"/><geometry><sphere radius="0.05"/></geometry></collision>
    <collision><origin xyz="0 0 0" rpy="0 0 0"/>
      <geometry><mesh filename="{link_2}" scale="0.5 0.5 0.5"/></geometry></collision>
  </link>
  <joint name="joint_3" type="revolute">
    <parent link="link_2"/><child link="link_3"/><origin xyz="0 0 0.3" rpy="0 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2.0" upper="2.0" velocity="2.0" effort="100"/>
  </joint>
  <link name="link_3">
    <inertial><mass value="1.0"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <collision><origin xyz="0.1 0 0" rpy="0.2 1.2 -0.4"/><geometry><mesh filename="{link_3}"/></geometry></collision>
  </link>
  <joint name="flange_joint" type="fixed">
    <parent link="link_3"/><child link="flange"/><origin xyz="0.2 0 0" rpy="0 1.5707963267948966 0"/>
  </joint>
  <link name="flange"/>
  <joint name="camera_joint" type="fixed">
    <parent link="flange"/><child link="camera"/><origin xyz="0 0 0.05" rpy="0 0 0"/>
  </joint>
  <link name="camera">
    <visual><origin xyz="0 0 -0.02"/><geometry><box size="0.1 0.05 0.04"/></geometry></visual>
    <collision name="camera_body"><origin xyz="0 0 -0.02"/><geometry><box size="0.1 0.05 0.04"/></geometry></collision>
  </link>
</robot>
"""

#: the meshes' files (under toy_description/meshes/) and their URDF filenames
FILES = {"base_link": ("base.stl", "../meshes/base.stl"),
         "link_1": ("link_1.ply", "package://toy_description/meshes/link_1.ply"),
         "link_2": ("link_2.obj", "file://{root}/toy_description/meshes/link_2.obj"),
         "link_3": ("link_3.stl", "package://toy_description/meshes/link_3.stl")}


def _meshes() -> dict[str, o3d.geometry.TriangleMesh]:
    box = o3d.geometry.TriangleMesh.create_box(0.12, 0.12, 0.6)
    box.translate((-0.06, -0.06, 0.0))  # 0.06 x 0.06 x 0.3 m from the joint up, scaled by 0.5
    return {"base_link": _cylinder(0.08, 0.1), "link_1": _cylinder(0.05, 0.3), "link_2": box,
            "link_3": _cylinder(0.04, 0.2)}


def _robot(tmp_path: Path, **filenames: str) -> tuple[Path, dict[str, np.ndarray]]:
    """toy_description/urdf/toy.urdf with its meshes; and each mesh link's vertices in the
    link frame (computed here from the collision origins and scales written above)."""
    meshes = tmp_path / "toy_description" / "meshes"
    names = {link: uri.format(root=tmp_path) for link, (_, uri) in FILES.items()} | filenames
    vertices = {}
    for link, mesh in _meshes().items():
        written = _write(mesh, meshes / FILES[link][0])
        vertices[link] = written
    vertices["base_link"] = vertices["base_link"] + [0.0, 0.0, 0.05]
    vertices["link_1"] = vertices["link_1"] + [0.0, 0.0, 0.15]
    vertices["link_2"] = vertices["link_2"] * 0.5
    vertices["link_3"] = transform_points(pose_from_xyz_rpy((0.1, 0.0, 0.0), (0.2, 1.2, -0.4)), vertices["link_3"])
    path = tmp_path / "toy_description" / "urdf" / "toy.urdf"
    path.parent.mkdir(parents=True, exist_ok=True)
    text = URDF
    for link, uri in names.items():
        text = text.replace("{" + link + "}", uri)
    path.write_text(text)
    return path, vertices


def _elements(urdf: str, link: str, tag: str) -> list[etree._Element]:
    root = etree.fromstring(urdf.encode())
    return root.find(f"link[@name='{link}']").findall(tag)


def _origin(element: etree._Element) -> np.ndarray:
    o = element.find("origin")
    return pose_from_xyz_rpy([float(v) for v in o.get("xyz").split()], [float(v) for v in o.get("rpy").split()])


def _check_pieces(pieces: list[etree._Element], capsule: FittedCapsule, radius: float, suffix: str) -> None:
    """The pieces are geom_capsule's: cylinder at the midpoint along p2 - p1, spheres at p1, p2."""
    link = capsule.link
    assert [p.get("name") for p in pieces] == [f"{link}_fit_capsule{suffix}", f"{link}_fit_capsule_end_a{suffix}",
                                               f"{link}_fit_capsule_end_b{suffix}"]
    p1, p2 = np.array(capsule.p1), np.array(capsule.p2)
    cyl = pieces[0].find("geometry/cylinder")
    T = _origin(pieces[0])
    assert np.allclose(T[:3, 3], (p1 + p2) / 2.0, atol=1e-12)
    assert np.allclose(T[:3, 2] * capsule.length, p2 - p1, atol=1e-12)
    assert float(cyl.get("length")) == pytest.approx(capsule.length, abs=1e-15)
    assert float(cyl.get("radius")) == radius
    for piece, end in zip(pieces[1:], (p1, p2), strict=True):
        assert np.allclose(_origin(piece)[:3, 3], end, atol=0.0)
        assert float(piece.find("geometry/sphere").get("radius")) == radius


def test_a_robot_with_collision_meshes_gets_one_capsule_per_link(tmp_path):
    path, vertices = _robot(tmp_path)
    fit = fit_mesh_collisions(path.read_text(), path, SD)
    capsules = {c.link: c for c in fit.capsules}
    assert set(capsules) == {"base_link", "link_1", "link_2", "link_3"}
    assert "<mesh" not in fit.urdf  # the DAE visual is gone too: MuJoCo needs no mesh file
    for link, points in vertices.items():
        capsule = capsules[link]
        assert _segment_distance(points, capsule.p1, capsule.p2).max() <= capsule.radius, link
        collisions = [c for c in _elements(fit.urdf, link, "collision") if "_fit_" in c.get("name")]
        _check_pieces(collisions, capsule, capsule.radius + SD, "")
    # tight: the cylinders' radii within 5 %, the scaled box's half diagonal within 5 %
    assert capsules["link_1"].radius == pytest.approx(0.05, rel=0.05)
    assert capsules["link_3"].radius == pytest.approx(0.04, rel=0.05)
    assert capsules["link_2"].radius == pytest.approx(0.03 * math.sqrt(2.0), rel=0.05)
    assert capsules["link_1"].volume < 1.5 * math.pi * 0.05**2 * 0.3
    # primitives stay; the visuals are the capsules' pieces at real size, the material kept
    assert [c.get("name") for c in _elements(fit.urdf, "link_2", "collision")][0] == "elbow"
    visuals = _elements(fit.urdf, "base_link", "visual")
    _check_pieces(visuals, capsules["base_link"], capsules["base_link"].radius, "_visual")
    assert all(v.find("material").get("name") == "grey" for v in visuals)
    assert not _elements(fit.urdf, "link_2", "visual")
    # pinocchio and the collision model read it: one exact capsule per mesh link
    model = pin.buildModelFromXML(fit.urdf)
    assert model.nq == 3
    shapes = shapes_from_urdf(fit.urdf, SimpleNamespace(model=model))
    fitted = {s.link: s for s in shapes if s.name.endswith("_fit_capsule")}
    assert set(fitted) == set(capsules) and all(s.kind == "capsule" for s in fitted.values())
    for link, shape in fitted.items():
        assert shape.dims == (capsules[link].radius + SD, pytest.approx(capsules[link].length, abs=1e-15))
    assert {s.name for s in shapes if not s.name.endswith("_fit_capsule")} == {"table_top", "elbow", "camera_body"}


def test_the_rewrite_follows_the_safety_distance_and_the_mesh_files(tmp_path):
    path, _ = _robot(tmp_path)
    text = path.read_text()
    a = fit_mesh_collisions(text, path, 0.0)
    b = fit_mesh_collisions(text, path, 0.05)
    assert a.capsules == b.capsules and a.urdf != b.urdf
    end = _elements(b.urdf, "link_1", "collision")[1]
    assert end.get("name") == "link_1_fit_capsule_end_a"
    assert float(end.find("geometry/sphere").get("radius")) == a.capsules[1].radius + 0.05
    assert fit_mesh_collisions(text, path, 0.0) is a  # cached
    _write(_cylinder(0.07, 0.3), tmp_path / "toy_description" / "meshes" / "link_1.ply")
    c = fit_mesh_collisions(text, path, 0.0)
    assert c.capsules[1].radius == pytest.approx(0.07, rel=0.05)


def test_a_description_without_meshes_is_unchanged(tmp_path):
    text = URDF.replace('<mesh filename="package://toy_description/meshes/base.dae"/>', '<sphere radius="0.1"/>')
    root = etree.fromstring(text.encode())
    for col in root.iter("collision"):
        mesh = col.find("geometry/mesh")
        if mesh is not None:
            mesh.getparent().replace(mesh, etree.Element("sphere", radius="0.05"))
    for vis in root.iter("visual"):
        mesh = vis.find("geometry/mesh")
        if mesh is not None:
            mesh.getparent().replace(mesh, etree.Element("sphere", radius="0.05"))
    plain = etree.tostring(root, encoding="unicode")
    fit = fit_mesh_collisions(plain, tmp_path / "x.urdf", SD)
    assert fit.urdf is plain and fit.capsules == ()


# ----------------------------------------------------------------------------- refusals
def _refusal(tmp_path: Path, **filenames: str) -> str:
    path, _ = _robot(tmp_path, **filenames)
    with pytest.raises(InputError) as info:
        fit_mesh_collisions(path.read_text(), path, SD)
    text = info.value.one_line()
    assert "\n" not in text
    return text


def test_a_collada_collision_mesh_is_refused_in_one_line(tmp_path):
    text = _refusal(tmp_path, link_2="package://toy_description/meshes/link_2.dae")
    assert "link 'link_2'" in text and "link_2.dae" in text and "Collada" in text
    assert "convert it to STL or OBJ" in text


def test_a_missing_mesh_file_is_refused_naming_the_link(tmp_path):
    text = _refusal(tmp_path, link_3="../meshes/nope.stl")
    assert "link 'link_3'" in text and "nope.stl does not exist" in text
    assert str(tmp_path / "toy_description" / "urdf" / ".." / "meshes" / "nope.stl") in text
    text = _refusal(tmp_path, link_1="package://other_description/meshes/link_1.ply")
    assert "link 'link_1'" in text and "no folder named 'other_description'" in text


def test_package_uris_are_found_above_the_description(tmp_path):
    description = tmp_path / "cell" / "robots" / "arm.urdf"
    (tmp_path / "cell" / "vendor_description" / "meshes").mkdir(parents=True)
    # a folder named like the package beside an ancestor of the description
    assert resolve_mesh("package://vendor_description/meshes/a.stl", description) == \
        tmp_path / "cell" / "vendor_description" / "meshes" / "a.stl"
    # an ancestor named like the package
    assert resolve_mesh("package://cell/meshes/b.stl", description) == tmp_path / "cell" / "meshes" / "b.stl"
    assert resolve_mesh("meshes/c.stl", description) == tmp_path / "cell" / "robots" / "meshes" / "c.stl"
    assert resolve_mesh("file:///abs/d.stl", description) == Path("/abs/d.stl")


# ----------------------------------------------------------------------------- end to end
CELL = """format: 1
name: toy
description:
  file: toy_description/urdf/toy.urdf
joints:
  planning: [joint_1, joint_2, joint_3]
base: base_link
flange: flange
camera:
  frame: camera
  sensor: camera.yaml
table:
  shape: table_top
board:
  frame: marker
  spec: board.yaml
objects:
  position: [0.6, 0.0, 0.4]
limits:
  joints:
    joint_1: {{acceleration: 90}}
    joint_2: {{acceleration: 90}}
    joint_3: {{acceleration: 90}}
safety_distance: {sd}
poses:
  home: [0, 20, -60]
collision:
  allowed: []
"""


def test_a_cell_file_naming_a_urdf_with_meshes_builds_a_cell(tmp_path):
    from recon_cli.robot.cell import Cell
    from recon_cli.robot.description import CellConfig, expand_urdf, mesh_capsules

    _robot(tmp_path)
    path = tmp_path / "toy.yaml"
    path.write_text(CELL.format(sd=SD))
    config = CellConfig(kind=str(path))
    capsules = {c.link: c for c in mesh_capsules(config)}
    assert set(capsules) == {"base_link", "link_1", "link_2", "link_3"}
    cell = Cell(config)
    assert cell.joint_names == ("joint_1", "joint_2", "joint_3")
    robot = {s.link: s for s in cell.collision.robot_shapes if s.kind == "capsule"}
    assert set(robot) == {"link_1", "link_2", "link_3"}
    assert all(robot[link].dims[0] == capsules[link].radius + SD for link in robot)
    home = config.cell_file.pose("home", cell.joint_names)
    assert not cell.collision.check(home).colliding
    assert np.isfinite(cell.collision.distance(home).minimum)
    # the safety distance of the configuration, not the file's, inflates the capsules
    wider = expand_urdf(CellConfig(kind=str(path), safety_distance=0.05))
    end = _elements(wider, "link_3", "collision")[-1]
    assert end.get("name") == "link_3_fit_capsule_end_b"
    assert float(end.find("geometry/sphere").get("radius")) == capsules["link_3"].radius + 0.05


def test_a_plain_urdfs_primitives_are_inflated_by_the_safety_distance(tmp_path):
    """A URDF takes no safety distance: recon inflates its primitives itself (boxes by sd on
    every face, spheres by sd), so the table top's surface stays where the URDF puts it."""
    from recon_cli.robot.cell import Cell
    from recon_cli.robot.description import CellConfig, expand_urdf

    _robot(tmp_path)
    path = tmp_path / "toy.yaml"
    path.write_text(CELL.format(sd=SD))
    for sd in (0.0, 0.03):
        urdf = expand_urdf(CellConfig(kind=str(path), safety_distance=sd))
        top = next(c for c in etree.fromstring(urdf.encode()).iter("collision") if c.get("name") == "table_top")
        assert [float(v) for v in top.find("geometry/box").get("size").split()] == pytest.approx(
            [0.4 + 2 * sd, 0.8 + 2 * sd, 0.4 + 2 * sd])
        visual = next(v for v in etree.fromstring(urdf.encode()).iter("visual") if v.find("geometry/box") is not None)
        assert visual.find("geometry/box").get("size") is not None  # visuals keep their real size
        cell = Cell(CellConfig(kind=str(path), safety_distance=sd))
        assert cell.table_surface_z == pytest.approx(0.4)
