"""A cell written as docs/cells.md tells a new user to: the vendor's arm URDF as shipped (here
the FR3 arm of recon's own description, written out alone), wrapped in a xacro file that adds
the world, the table, the camera (its optical frame named as a RealSense description names
it) and the board. ``recon cell check`` builds and renders its simulation, and ``recon
autoscan`` scans with it; the vendor's URDF alone is told to hold the whole cell."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from lxml import etree

from recon_cli.cli import main
from recon_cli.paths import ROOT
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.robot.description import CellConfig, expand_urdf

#: the links and joints of recon's FR3 cell that are not the arm
NOT_THE_ARM = {"world", "table", "marker", "camera_bracket", "camera"}


def vendor_fr3_urdf() -> str:
    """The FR3 arm alone as a plain URDF (links fr3_link0 ... fr3_link8), as a vendor ships it."""
    root = etree.fromstring(expand_urdf(CellConfig(kind="fr3", safety_distance=0.0)).encode())
    for element in list(root):
        if not isinstance(element.tag, str):
            root.remove(element)  # comments
        elif element.tag == "link" and element.get("name") in NOT_THE_ARM:
            root.remove(element)
        elif element.tag == "joint" and ({element.find("parent").get("link"), element.find("child").get("link")}
                                         & NOT_THE_ARM):
            root.remove(element)
    root.set("name", "fr3")
    return etree.tostring(root, xml_declaration=True, encoding="utf-8").decode()


def wrapper_example() -> tuple[str, str]:
    """The wrapper xacro and the cell file of docs/cells.md, "A wrapper around a vendor's arm"."""
    text = (ROOT / "docs" / "cells.md").read_text()
    section = text.split("### A wrapper around a vendor's arm", 1)[1].split("\n### ", 1)[0]
    xml = re.search(r"```xml\n(.*?)```", section, re.S)
    yaml = re.search(r"```yaml\n(.*?)```", section, re.S)
    assert xml and yaml
    return xml.group(1), yaml.group(1)


@pytest.fixture()
def mycell(tmp_path: Path) -> Path:
    folder = tmp_path / "mycell"
    (folder / "fr3").mkdir(parents=True)
    (folder / "fr3" / "fr3.urdf").write_text(vendor_fr3_urdf())
    xacro, cell = wrapper_example()
    (folder / "cell.urdf.xacro").write_text(xacro)
    (folder / "cell.yaml").write_text(cell)
    return folder / "cell.yaml"


def test_the_wrapper_example_checks_and_scans(mycell, tmp_path, capsys):
    assert main(["cell", "check", str(mycell), "--step", "0.4", "-o", str(tmp_path / "check")]) == 0
    text = capsys.readouterr().out
    assert "simulation: MuJoCo scene built, its camera at the cell's camera frame" in text
    assert "my_fr3: no problems found; the cell is ready to scan" in text
    out = tmp_path / "scan"
    assert main(["autoscan", "--cell", str(mycell), "--n", "2", "-m", "10", "--resolution", "0.1",
                 "--no-pictures", "-o", str(out)]) == 0
    assert len(ScanStore(out)) == 2


def test_the_vendor_urdf_alone_is_told_to_hold_the_whole_cell(mycell, capsys):
    text = mycell.read_text().replace("file: cell.urdf.xacro", "file: fr3/fr3.urdf")
    mycell.write_text(text)
    assert main(["cell", "check", str(mycell)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "camera.frame camera_color_optical_frame is not a link of fr3.urdf" in err
    assert "the description must hold the whole cell (arm, camera, table, board)" in err
    assert "docs/cells.md" in err and "A wrapper around a vendor's arm" in err


def test_a_cell_the_simulation_cannot_load_fails_the_check_in_one_line(mycell, tmp_path, capsys):
    """A link a joint moves without mass loads into the kinematics but not into MuJoCo."""
    urdf = mycell.parent / "fr3" / "fr3.urdf"
    root = etree.fromstring(urdf.read_bytes())
    link7 = next(link for link in root.iter("link") if link.get("name") == "fr3_link7")
    link7.remove(link7.find("inertial"))
    urdf.write_bytes(etree.tostring(root))
    assert main(["cell", "check", str(mycell), "--step", "0.4", "-o", str(tmp_path / "check")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "the simulation (MuJoCo) cannot load the cell's description cell.urdf.xacro" in err
    assert f"{mycell}:" in err


def test_a_camera_on_the_flanges_rigid_body_hangs_on_the_flange(mycell):
    """The camera mounted on the wrist link the flange is fixed to (a sibling of the flange,
    not below it) rides rigidly on the flange: the same camera pose as mounted on the flange."""
    from recon_cli.cell_check import check_layout
    from recon_cli.robot.cell import Cell

    nominal = Cell(CellConfig(kind=str(mycell)))
    xacro = mycell.parent / "cell.urdf.xacro"
    text = xacro.read_text()
    mount = '<parent link="fr3_link8"/><child link="camera_link"/>'
    assert text.count(mount) == 1
    xacro.write_text(text.replace(mount, '<parent link="fr3_link7"/><child link="camera_link"/>'
                                         '<origin xyz="0 0 0.107"/>'))
    sibling = mycell.parent / "sibling.yaml"
    sibling.write_text(mycell.read_text())  # another cell file: nothing cached of the first
    moved = Cell(CellConfig(kind=str(sibling)))
    q = moved.config.cell_file.pose("home", moved.joint_names)
    assert moved.kin.world_T_camera(q) == pytest.approx(nominal.kin.world_T_camera(q), abs=1e-12)
    check_layout(moved)  # the camera's own housing is not "the robot" around its optical centre


def _tree(*joints: tuple[str, str, str, str]) -> str:
    """A URDF of (name, type, parent, child, xyz) joints."""
    links = {"world"} | {j[2] for j in joints} | {j[3] for j in joints}
    body = "".join(f'<link name="{n}"/>' for n in sorted(links))
    for name, kind, parent, child_, *xyz in joints:
        limit = '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>' if kind != "fixed" else ""
        body += (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child_}"/>'
                 f'<origin xyz="{xyz[0] if xyz else "0 0 0"}"/>{limit}</joint>')
    return f'<robot name="t">{body}</robot>'


def test_links_of_one_rigid_body_meet_in_either_direction():
    from recon_cli.robot.cell_file import parent_T_child, rigid_mount

    urdf = _tree(("j1", "revolute", "world", "wrist", "0 0 1"), ("f", "fixed", "wrist", "flange", "0 0 0.1"),
                 ("m", "fixed", "wrist", "mount", "0.05 0 0"), ("o", "fixed", "mount", "optical", "0 0 0.02"),
                 ("j2", "revolute", "wrist", "finger", "0 0 0.2"), ("t", "fixed", "finger", "tip", "0 0 0.01"))
    assert rigid_mount(urdf, "flange", "optical") == "wrist"  # siblings on the wrist
    assert rigid_mount(urdf, "mount", "optical") == "mount"  # below
    assert rigid_mount(urdf, "optical", "mount") == "mount"  # above
    assert rigid_mount(urdf, "flange", "tip") == "joint j2"
    assert rigid_mount(urdf, "world", "optical") == "joint j1"
    assert parent_T_child(urdf, "flange", "optical")[:3, 3] == pytest.approx([0.05, 0.0, -0.08])
    assert parent_T_child(urdf, "optical", "flange")[:3, 3] == pytest.approx([-0.05, 0.0, 0.08])
    assert parent_T_child(urdf, "mount", "optical")[:3, 3] == pytest.approx([0.0, 0.0, 0.02])
