"""The MuJoCo scene, compiled from the same expanded URDF as everything else.

The URDF's visual geometry (real sizes, safety distance 0) becomes the scene; its collision
geometry is dropped (planning checks collisions with the coal/pinocchio collision model;
the robot only moves along checked trajectories). Added through the MjSpec API: the camera
on the cell file's ``camera.frame`` (MuJoCo cameras look along -z, so the OpenCV optical
frame is turned by pi about x), the ChArUco board as a texture on its ``board.frame`` (each
on the body of its link, or at its pose on the body that carries it), the object to scan as
a mesh, lights, joint motors, and the drive data of the cell's drives file (reflected rotor
inertia, plant-only viscous friction). A description MuJoCo cannot load is one error line.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from lxml import etree

from recon_cli.errors import InputError
from recon_cli.geometry.transforms import pose_from_xyz_rpy
from recon_cli.inputs.schema import check
from recon_cli.inputs.yamlfile import read_yaml
from recon_cli.lazy import lazy_module
from recon_cli.objects import SceneObject
from recon_cli.paths import ROBOT_DIR
from recon_cli.perception.camera_model import GL_T_CV
from recon_cli.perception.charuco import BoardSpec, cell_board
from recon_cli.perception.sensor import SensorModel, cell_sensor
from recon_cli.robot.cell_file import CellFile, parent_T_child, rigid_ancestors
from recon_cli.robot.description import CellConfig, expand_urdf
from recon_cli.robot.limits import limits_from_urdf

os.environ.setdefault("MUJOCO_GL", "egl")  # read when MuJoCo is first used
if TYPE_CHECKING:
    import mujoco
else:
    mujoco = lazy_module("mujoco")

CAMERA_NAME = "depth_camera"
BOARD_PRINT_NAME = "charuco_print"
OBJECT_NAME = "scan_object"
BOARD_PIXELS_PER_METRE = 8000.0  # texture resolution of the printed board (0.125 mm per texel)


#: the thesis cells' drives file, whose controller gains a cell without a drives file gets
DEFAULT_DRIVES = ROBOT_DIR / "drives.yaml"


@dataclass(frozen=True)
class Drives:
    """Drive data of a cell's joints (a drives file; schemas/drives.schema.json).

    armature: reflected rotor inertia per joint [kg m^2 or kg]; friction: viscous friction of
    the simulated plant per joint, unknown to the controller [N m s/rad or N s/m]; K0, K1, KI:
    the computed-torque gains of eq. 2.14 [1/s^2, 1/s, 1/s^3]. Joints a file leaves out get 0.
    """

    armature: tuple[tuple[str, float], ...]
    friction: tuple[tuple[str, float], ...]
    K0: float
    K1: float
    KI: float

    def armature_of(self, joint: str) -> float:
        return dict(self.armature).get(joint, 0.0)

    def friction_of(self, joint: str) -> float:
        return dict(self.friction).get(joint, 0.0)


def drives(cell: CellFile | None = None) -> Drives:
    """The drives of a cell (its cell file's ``drives``; without one: no armature, no plant
    friction, the thesis cells' controller gains)."""
    if cell is None or cell.drives_file is None:
        d = _drives_file(DEFAULT_DRIVES)
        return d if cell is None else dataclasses.replace(d, armature=(), friction=())
    return _drives_file(cell.drives_file)


@functools.lru_cache(maxsize=8)
def _drives_file(path: Path) -> Drives:
    d = read_yaml(path, "drives file")
    check(d, "drives", path)
    c = d["controller"]
    return Drives(tuple((str(k), float(v)) for k, v in d.get("armature", {}).items()),
                  tuple((str(k), float(v)) for k, v in d.get("plant_viscous_friction", {}).items()),
                  float(c["K0"]), float(c["K1"]), float(c["KI"]))


@dataclass
class SimScene:
    """A compiled scene and the indices the backends need."""

    model: mujoco.MjModel
    joint_names: tuple[str, ...]
    qpos_index: np.ndarray  # (n,) qpos address of each joint, in recon's joint order
    dof_index: np.ndarray  # (n,) dof address of each joint
    camera_id: int
    sensor: SensorModel
    scene_object: SceneObject | None
    drives: Drives


def mujoco_urdf(config: CellConfig) -> str:
    """URDF text of the cell (real sizes, the config's robot base and hand-eye transform)
    with MuJoCo's compiler options inside <robot>."""
    urdf = expand_urdf(dataclasses.replace(config, safety_distance=0.0))
    root = etree.fromstring(urdf.encode())
    mj = etree.SubElement(root, "mujoco")
    etree.SubElement(mj, "compiler", fusestatic="false", discardvisual="false",
                     balanceinertia="true", strippath="false")
    return etree.tostring(root).decode()


def _board_rgb(board: BoardSpec) -> np.ndarray:
    """The printed board as an RGB texture. MuJoCo puts the first texture row at the
    plane's +y edge, which is where the board image's top row belongs (marker y max);
    tests/backends check the orientation by detecting the board in a render."""
    grey = board.image(BOARD_PIXELS_PER_METRE)
    return np.ascontiguousarray(np.repeat(grey[:, :, None], 3, axis=2))


def frame_on_body(spec: mujoco.MjSpec, urdf: str, link: str, where: str) -> tuple[mujoco.MjsBody, np.ndarray]:
    """The MuJoCo body that carries a URDF link's frame, and the frame's pose on it: the link's
    own body, or, where MuJoCo holds no body of that name (a link fused into its parent), the
    nearest link above it through fixed joints that has one, with the frame's pose from the
    URDF's fixed joints."""
    for name in (link, *rigid_ancestors(urdf, link)):
        body = spec.body(name)
        if body is not None:
            return body, parent_T_child(urdf, name, link)
    raise InputError(f"{where}: the simulation has no body that carries the frame {link}",
                     hint="hang the frame on a link through fixed joints (a link with a body in the scene)")


#: characters of MuJoCo's reason quoted at most
_REASON_CHARS = 160


def _refused(cell: CellFile, exc: ValueError) -> InputError:
    """One line for a description MuJoCo refuses: its reason and the element it names."""
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    reason = "; ".join(re.sub(r"^Element name '(.*)', id \d+$", r"at \1", line.removeprefix("Error: "))
                       for line in lines)[:_REASON_CHARS]
    return InputError(f"{cell.where('description.file')}: the simulation (MuJoCo) cannot load the cell's "
                      f"description {cell.description.name} ({reason})",
                      hint="fix the description where MuJoCo says (a link a joint moves needs a mass and an "
                           "inertia above zero); recon cell check builds the simulation too")


def _place(element: mujoco.MjsCamera | mujoco.MjsGeom, body_T_element: np.ndarray) -> None:
    """Set a MuJoCo element's position and orientation on its body."""
    element.pos = body_T_element[:3, 3].tolist()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(body_T_element[:3, :3]).ravel())
    element.quat = quat.tolist()


def build_scene(config: CellConfig, scene_object: SceneObject | None = None,
                sensor: SensorModel | None = None, board: BoardSpec | None = None,
                timestep: float = 0.001) -> SimScene:
    sensor = sensor or cell_sensor(config.cell_file)
    board = board or cell_board(config.cell_file)
    urdf = mujoco_urdf(config)
    try:
        spec = mujoco.MjSpec.from_string(urdf)
    except ValueError as exc:
        raise _refused(config.cell_file, exc) from None
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.visual.global_.offwidth = max(sensor.width, 640)
    spec.visual.global_.offheight = max(sensor.height, 480)
    spec.visual.quality.shadowsize = 0
    spec.visual.headlight.ambient = [0.45, 0.45, 0.45]
    spec.visual.headlight.diffuse = [0.35, 0.35, 0.35]
    spec.visual.headlight.specular = [0.0, 0.0, 0.0]

    # keep the visual geometry only: no contacts in the plant
    for geom in list(spec.geoms):
        if geom.contype != 0 or geom.conaffinity != 0:
            spec.delete(geom)

    # depth camera on the cell's optical frame: OpenGL axes = OpenCV axes turned by pi about x
    cf = config.cell_file
    cam_body, body_T_camera = frame_on_body(spec, urdf, cf.camera_frame, cf.where("camera.frame"))
    cam = cam_body.add_camera()
    cam.name = CAMERA_NAME
    _place(cam, body_T_camera @ GL_T_CV)
    cam.fovy = float(np.degrees(sensor.fovy))

    # the printed board on the carrier plate (top face of the plate is z = 0 of "marker")
    tex = spec.add_texture()
    tex.name = "charuco"
    tex.type = mujoco.mjtTexture.mjTEXTURE_2D
    rgb = _board_rgb(board)
    tex.width, tex.height, tex.nchannel = rgb.shape[1], rgb.shape[0], 3
    tex.data = rgb.tobytes()
    mat = spec.add_material()
    mat.name = "charuco"
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "charuco"
    mat.texrepeat = [1, 1]
    mat.texuniform = False
    mat.specular = 0.0
    mat.shininess = 0.0
    sx, sy = board.size
    board_body, body_T_marker = frame_on_body(spec, urdf, cf.board_frame, cf.where("board.frame"))
    g = board_body.add_geom()
    g.name = BOARD_PRINT_NAME
    g.type = mujoco.mjtGeom.mjGEOM_PLANE
    g.size = [sx / 2.0, sy / 2.0, 0.01]
    _place(g, body_T_marker @ pose_from_xyz_rpy([sx / 2.0, sy / 2.0, 1e-5], [0.0, 0.0, 0.0]))
    g.material = "charuco"
    g.contype = g.conaffinity = 0

    if scene_object is not None:
        mesh = spec.add_mesh()
        mesh.name = OBJECT_NAME
        mesh.uservert = scene_object.vertices.astype(np.float32).ravel().tolist()
        mesh.userface = scene_object.triangles.astype(np.int32).ravel().tolist()
        og = spec.worldbody.add_geom()
        og.name = OBJECT_NAME
        og.type = mujoco.mjtGeom.mjGEOM_MESH
        og.meshname = OBJECT_NAME
        og.rgba = list(scene_object.rgba)
        og.contype = og.conaffinity = 0
        T = scene_object.world_T_object
        og.pos = T[:3, 3].tolist()
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, T[:3, :3].ravel())
        og.quat = quat.tolist()

    light = spec.worldbody.add_light()
    light.pos = [0.4, -0.6, 2.5]
    light.dir = [-0.15, 0.25, -1.0]
    light.diffuse = [0.5, 0.5, 0.5]
    light.castshadow = False

    d = drives(config.cell_file)
    joint_names = []
    movable = [j.name for j in spec.joints]
    effort = dict(zip(movable, limits_from_urdf(urdf, movable, config.cell_file.limits).effort, strict=True))
    for joint in spec.joints:
        joint_names.append(joint.name)
        joint.armature = d.armature_of(joint.name)
        joint.damping = [d.friction_of(joint.name), 0.0, 0.0]
        act = spec.add_actuator()
        act.name = f"motor_{joint.name}"
        act.target = joint.name
        act.trntype = mujoco.mjtTrn.mjTRN_JOINT
        act.gainprm[0] = 1.0
        act.ctrllimited = True
        act.ctrlrange = [-float(effort[joint.name]), float(effort[joint.name])]  # URDF effort

    try:
        model = spec.compile()
    except ValueError as exc:  # the cell's description or the object's mesh
        if scene_object is None or OBJECT_NAME not in str(exc):
            raise _refused(config.cell_file, exc) from None
        reason = str(exc).strip().splitlines()[0].removeprefix("Error: ").strip()
        raise InputError(f"the object '{scene_object.name}' cannot be simulated: MuJoCo refuses its mesh ({reason})",
                         hint="give a closed surface of the object (a solid)") from None
    extent = model.stat.extent
    model.vis.map.znear = 0.05 / extent  # 5 cm: far inside the sensor's 0.497 m minimum range
    model.vis.map.zfar = 10.0 / extent
    names = tuple(joint_names)
    qpos_index = np.array([model.jnt_qposadr[model.joint(n).id] for n in names])
    dof_index = np.array([model.jnt_dofadr[model.joint(n).id] for n in names])
    return SimScene(model, names, qpos_index, dof_index, model.camera(CAMERA_NAME).id, sensor,
                    scene_object, d)


class BoardSheet:
    """A plain grey sheet that can be laid over the printed ChArUco board of a scene: the
    board is then not found, and registration has to use the robot's kinematics."""

    GREY = (0.6, 0.6, 0.6, 1.0)

    def __init__(self, model: mujoco.MjModel) -> None:
        self._model = model
        self._geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, BOARD_PRINT_NAME)
        self._printed = (int(model.geom_matid[self._geom]), model.geom_rgba[self._geom].copy())

    def cover(self, covered: bool) -> None:
        matid, rgba = (-1, self.GREY) if covered else self._printed
        self._model.geom_matid[self._geom] = matid
        self._model.geom_rgba[self._geom] = rgba
