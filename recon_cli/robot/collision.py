"""Collision model of the cell with python-fcl (thesis section 2.2.4).

The shapes come from the ``<collision>`` elements of the expanded URDF: capsules for the
iiwa links, boxes for everything else (frame, axes, table, board, camera), all already
inflated by the cell's safety distance. A cylinder named ``*_capsule`` becomes one exact FCL
capsule; its end spheres ``*_capsule_end_*`` are then skipped. An optional object bounding
box (the scan object, thesis 4.1/4.2) is added to the environment, inflated by the same
safety distance.

Checked pairs: every robot shape against every environment shape, and robot shapes of
different links against each other, except links on the same rigid body, a link and its
URDF parent, and the pairs listed with a reason in robot/collision.yaml.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass

import fcl
import numpy as np
import pinocchio as pin
import yaml
from lxml import etree

from recon_cli.geometry.transforms import pose_from_xyz_rpy
from recon_cli.paths import ROBOT_DIR
from recon_cli.robot.kinematics import Kinematics

OBJECT_LINK = "object"


@dataclass(frozen=True)
class ObjectBox:
    """Axis-aligned bounding box of the object in the world [m] (before inflation).

    center: (3,) box centre in the world; size: (3,) full edge lengths.
    """

    center: tuple[float, float, float]
    size: tuple[float, float, float]

    @classmethod
    def on_table(cls, size, xy=(0.0, 0.0), table_top_z: float = 0.68) -> ObjectBox:
        sx, sy, sz = (float(v) for v in size)
        return cls((float(xy[0]), float(xy[1]), table_top_z + sz / 2.0), (sx, sy, sz))

    @property
    def lower(self) -> np.ndarray:
        return np.asarray(self.center) - np.asarray(self.size) / 2.0

    @property
    def upper(self) -> np.ndarray:
        return np.asarray(self.center) + np.asarray(self.size) / 2.0


@dataclass(frozen=True)
class CollisionShape:
    """One collision primitive. ``joint_T_shape`` places it in its pinocchio joint frame."""

    name: str
    link: str
    joint: int  # pinocchio joint index the link moves with (0: fixed to the world)
    kind: str  # box | capsule | cylinder | sphere
    dims: tuple[float, ...]  # box (sx, sy, sz); capsule/cylinder (radius, length); sphere (r,)
    joint_T_shape: np.ndarray

    @property
    def label(self) -> str:
        return f"{self.link}/{self.name}"


@dataclass(frozen=True)
class CollisionReport:
    """Result of a collision check: the colliding pairs (shape labels), empty when free."""

    pairs: tuple[tuple[str, str], ...]

    @property
    def colliding(self) -> bool:
        return bool(self.pairs)


@dataclass(frozen=True)
class DistanceReport:
    """Smallest distances [m] of a configuration (negative: penetration depth estimate).

    environment: robot to environment (the clearance); self_: robot to itself.
    """

    environment: float
    environment_pair: tuple[str, str]
    self_: float
    self_pair: tuple[str, str]

    @property
    def minimum(self) -> float:
        return min(self.environment, self.self_)


def _geometry(kind: str, dims: tuple[float, ...]) -> fcl.CollisionGeometry:
    if kind == "box":
        return fcl.Box(*dims)
    if kind == "capsule":
        return fcl.Capsule(dims[0], dims[1])
    if kind == "cylinder":
        return fcl.Cylinder(dims[0], dims[1])
    if kind == "sphere":
        return fcl.Sphere(dims[0])
    raise ValueError(kind)


def shapes_from_urdf(urdf: str, kin: Kinematics) -> list[CollisionShape]:
    """Collision shapes of every link, placed in the frames of their pinocchio joints."""
    root = etree.fromstring(urdf.encode())
    shapes = []
    for link in root.iter("link"):
        link_name = link.get("name")
        fid = kin.model.getFrameId(link_name, pin.BODY)
        frame = kin.model.frames[fid]
        joint_T_link = frame.placement.homogeneous
        for i, col in enumerate(link.findall("collision")):
            name = col.get("name") or f"{link_name}_{i}"
            if "_capsule_end_" in name:
                continue  # covered by the exact capsule
            origin = col.find("origin")
            xyz = [float(v) for v in (origin.get("xyz", "0 0 0") if origin is not None else "0 0 0").split()]
            rpy = [float(v) for v in (origin.get("rpy", "0 0 0") if origin is not None else "0 0 0").split()]
            geom = col.find("geometry")[0]
            if geom.tag == "box":
                kind, dims = "box", tuple(float(v) for v in geom.get("size").split())
            elif geom.tag == "cylinder":
                kind = "capsule" if name.endswith("_capsule") else "cylinder"
                dims = (float(geom.get("radius")), float(geom.get("length")))
            elif geom.tag == "sphere":
                kind, dims = "sphere", (float(geom.get("radius")),)
            else:
                raise ValueError(f"unsupported collision geometry <{geom.tag}> in link {link_name}")
            shapes.append(CollisionShape(name, link_name, int(frame.parentJoint), kind, dims,
                                         joint_T_link @ pose_from_xyz_rpy(xyz, rpy)))
    return shapes


@functools.lru_cache(maxsize=1)
def _declared_allowed() -> tuple[frozenset[str], ...]:
    with open(ROBOT_DIR / "collision.yaml") as f:
        entries = yaml.safe_load(f)["allowed"]
    return tuple(frozenset(e["links"]) for e in entries)


def allowed_link_pairs(urdf: str, kin: Kinematics) -> set[frozenset[str]]:
    """Link pairs that are never checked (same rigid body, URDF parent/child, declared)."""
    root = etree.fromstring(urdf.encode())
    allowed: set[frozenset[str]] = set(_declared_allowed())
    links = [link.get("name") for link in root.iter("link")]
    body = {name: kin.model.frames[kin.model.getFrameId(name, pin.BODY)].parentJoint
            for name in links}
    allowed.update(frozenset((a,)) for a in links)  # shapes of one link
    for a, b in itertools.combinations(links, 2):
        if body[a] == body[b]:
            allowed.add(frozenset((a, b)))
    for joint in root.iter("joint"):
        allowed.add(frozenset((joint.find("parent").get("link"), joint.find("child").get("link"))))
    return allowed


class CollisionModel:
    """Yes/no collision checks and distance queries for configurations of one cell."""

    def __init__(self, urdf: str, kin: Kinematics, object_box: ObjectBox | None = None,
                 safety_distance: float = 0.0) -> None:
        self.kin = kin
        self.safety_distance = float(safety_distance)
        self._data = kin.model.createData()
        self._allowed = allowed_link_pairs(urdf, kin)
        shapes = shapes_from_urdf(urdf, kin)
        self.robot_shapes = [s for s in shapes if s.joint != 0]
        self._static_env_shapes = [s for s in shapes if s.joint == 0]
        self._robot_geoms = [_geometry(s.kind, s.dims) for s in self.robot_shapes]
        self._robot_objs = [fcl.CollisionObject(g, fcl.Transform()) for g in self._robot_geoms]
        self._robot_index = {id(g): i for i, g in enumerate(self._robot_geoms)}
        self._robot_joints = np.array([s.joint for s in self.robot_shapes])
        self._robot_local = np.stack([s.joint_T_shape for s in self.robot_shapes])  # (R, 4, 4)
        self._robot_manager = fcl.DynamicAABBTreeCollisionManager()
        self._robot_manager.registerObjects(self._robot_objs)
        self._robot_manager.setup()
        # robot shape pairs to check against each other
        self._self_pairs = [
            (i, j) for i, j in itertools.combinations(range(len(self.robot_shapes)), 2)
            if frozenset((self.robot_shapes[i].link, self.robot_shapes[j].link)) not in self._allowed
        ]
        self._self_allowed = np.ones((len(self.robot_shapes),) * 2, dtype=bool)
        for i, j in self._self_pairs:
            self._self_allowed[i, j] = self._self_allowed[j, i] = False
        self.set_object_box(object_box)

    # ------------------------------------------------------------------ environment
    def set_object_box(self, box: ObjectBox | None) -> None:
        """Replace the object bounding box (None removes it). Inflated by the safety distance."""
        self.object_box = box
        env = list(self._static_env_shapes)
        if box is not None:
            size = tuple(float(s) + 2.0 * self.safety_distance for s in box.size)
            T = np.eye(4)
            T[:3, 3] = box.center
            env.append(CollisionShape("object_box", OBJECT_LINK, 0, "box", size, T))
        self.env_shapes = env
        self._env_geoms = [_geometry(s.kind, s.dims) for s in env]
        self._env_objs = [
            fcl.CollisionObject(g, fcl.Transform(s.joint_T_shape[:3, :3], s.joint_T_shape[:3, 3]))
            for g, s in zip(self._env_geoms, env, strict=True)
        ]
        self._env_index = {id(g): i for i, g in enumerate(self._env_geoms)}
        self._env_manager = fcl.DynamicAABBTreeCollisionManager()
        self._env_manager.registerObjects(self._env_objs)
        self._env_manager.setup()
        self._env_allowed = np.array([
            [frozenset((r.link, e.link)) in self._allowed for e in env] for r in self.robot_shapes
        ], dtype=bool)  # (R, E)

    # ------------------------------------------------------------------ placement
    def shape_poses(self, q: np.ndarray) -> np.ndarray:
        """World poses of the robot shapes at q, shape (R, 4, 4)."""
        pin.forwardKinematics(self.kin.model, self._data, q)
        oMi = np.stack([self._data.oMi[j].homogeneous for j in range(self.kin.model.njoints)])
        return oMi[self._robot_joints] @ self._robot_local

    def _place(self, q: np.ndarray) -> None:
        poses = self.shape_poses(q)
        for obj, T in zip(self._robot_objs, poses, strict=True):
            obj.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
        self._robot_manager.update()

    # ------------------------------------------------------------------ queries
    def check(self, q: np.ndarray) -> CollisionReport:
        """All colliding shape pairs at q (robot-environment and self)."""
        self._place(np.asarray(q, dtype=float))
        pairs: list[tuple[str, str]] = []
        req = fcl.CollisionRequest(num_max_contacts=10_000, enable_contact=False)
        data = fcl.CollisionData(request=req)
        self._robot_manager.collide(self._env_manager, data, fcl.defaultCollisionCallback)
        for c in data.result.contacts:
            i, j = self._robot_index.get(id(c.o1)), self._env_index.get(id(c.o2))
            if i is None:  # the manager may report the pair the other way round
                i, j = self._robot_index[id(c.o2)], self._env_index[id(c.o1)]
            if not self._env_allowed[i, j]:
                pairs.append((self.robot_shapes[i].label, self.env_shapes[j].label))
        data = fcl.CollisionData(request=req)
        self._robot_manager.collide(data, fcl.defaultCollisionCallback)
        for c in data.result.contacts:
            i, j = self._robot_index[id(c.o1)], self._robot_index[id(c.o2)]
            if not self._self_allowed[i, j]:
                a, b = sorted((i, j))
                pairs.append((self.robot_shapes[a].label, self.robot_shapes[b].label))
        return CollisionReport(tuple(dict.fromkeys(pairs)))

    def in_collision(self, q: np.ndarray) -> bool:
        return self.check(q).colliding

    def distance(self, q: np.ndarray) -> DistanceReport:
        """Smallest robot-environment and robot-self distances at q [m]."""
        self._place(np.asarray(q, dtype=float))
        req = fcl.DistanceRequest()
        best_env, env_pair = np.inf, ("", "")
        for i, ro in enumerate(self._robot_objs):
            for j, eo in enumerate(self._env_objs):
                if self._env_allowed[i, j]:
                    continue
                d = fcl.distance(ro, eo, req, fcl.DistanceResult())
                if d < best_env:
                    best_env, env_pair = d, (self.robot_shapes[i].label, self.env_shapes[j].label)
        best_self, self_pair = np.inf, ("", "")
        for i, j in self._self_pairs:
            d = fcl.distance(self._robot_objs[i], self._robot_objs[j], req, fcl.DistanceResult())
            if d < best_self:
                best_self = d
                self_pair = (self.robot_shapes[i].label, self.robot_shapes[j].label)
        return DistanceReport(float(best_env), env_pair, float(best_self), self_pair)

    def point_inside_environment(self, point: np.ndarray) -> str | None:
        """Label of the environment shape (inflated) that contains a world point, if any."""
        probe = fcl.CollisionObject(fcl.Sphere(1e-6), fcl.Transform(np.asarray(point, float)))
        for shape, obj in zip(self.env_shapes, self._env_objs, strict=True):
            if fcl.collide(probe, obj, fcl.CollisionRequest(), fcl.CollisionResult()):
                return shape.label
        return None
