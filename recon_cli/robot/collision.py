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
from recon_cli.robot.broadphase import (
    bounding_box,
    bounding_capsule,
    segment_distance,
    segments_hit_boxes,
    world_aabbs,
)
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
    """Yes/no collision checks and distance queries for configurations of one cell.

    Broad phase in numpy (bounding capsules of the robot shapes against bounding boxes of
    the environment shapes and against each other, for many configurations at once,
    ``recon_cli.robot.broadphase``); narrow phase with FCL on the candidate pairs only.
    """

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
        self._robot_joints = np.array([s.joint for s in self.robot_shapes])
        self._robot_local = np.stack([s.joint_T_shape for s in self.robot_shapes])  # (R, 4, 4)
        caps = [bounding_capsule(s.kind, s.dims) for s in self.robot_shapes]
        self._cap_a = np.stack([c[0] for c in caps])  # (R, 3) in the shape frame
        self._cap_b = np.stack([c[1] for c in caps])
        self._cap_r = np.array([c[2] for c in caps])  # (R,)
        # robot shape pairs to check against each other
        self._self_pairs = np.array([
            (i, j) for i, j in itertools.combinations(range(len(self.robot_shapes)), 2)
            if frozenset((self.robot_shapes[i].link, self.robot_shapes[j].link)) not in self._allowed
        ], dtype=int).reshape(-1, 2)
        self._self_r = self._cap_r[self._self_pairs[:, 0]] + self._cap_r[self._self_pairs[:, 1]]
        self._request = fcl.CollisionRequest()
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
        self._env_objs = [
            fcl.CollisionObject(_geometry(s.kind, s.dims),
                                fcl.Transform(s.joint_T_shape[:3, :3], s.joint_T_shape[:3, 3]))
            for s in env
        ]
        # broad phase: world-aligned boxes around the (static) environment shapes
        self._env_c, self._env_h = world_aabbs(
            np.stack([s.joint_T_shape[:3, :3] for s in env]),
            np.stack([s.joint_T_shape[:3, 3] for s in env]),
            np.stack([bounding_box(s.kind, s.dims) for s in env]))  # (E, 3) each
        self._env_allowed = np.array([
            [frozenset((r.link, e.link)) in self._allowed for e in env] for r in self.robot_shapes
        ], dtype=bool)  # (R, E)

    # ------------------------------------------------------------------ placement
    def shape_poses(self, q: np.ndarray) -> np.ndarray:
        """World poses of the robot shapes at q, shape (R, 4, 4)."""
        pin.forwardKinematics(self.kin.model, self._data, q)
        oMi = np.stack([self._data.oMi[j].homogeneous for j in range(self.kin.model.njoints)])
        return oMi[self._robot_joints] @ self._robot_local

    def _candidates(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Broad phase for poses (..., R, 4, 4): env candidates (..., R, E) and self
        candidates (..., P) (indices into the checked self pairs)."""
        R, t = poses[..., :3, :3], poses[..., :3, 3]
        a = (R @ self._cap_a[:, :, None])[..., 0] + t
        b = (R @ self._cap_b[:, :, None])[..., 0] + t
        env = segments_hit_boxes(a, b, self._cap_r, self._env_c, self._env_h)
        env &= ~self._env_allowed
        i, j = self._self_pairs[:, 0], self._self_pairs[:, 1]
        dist = segment_distance(a[..., i, :], b[..., i, :], a[..., j, :], b[..., j, :])
        return env, dist <= self._self_r

    def _exact(self, poses: np.ndarray, env_c: np.ndarray, self_c: np.ndarray,
               first_only: bool) -> list[tuple[str, str]]:
        """Narrow phase with FCL on the candidate pairs of one configuration."""
        pairs: list[tuple[str, str]] = []
        placed: set[int] = set()

        def place(k: int) -> fcl.CollisionObject:
            obj = self._robot_objs[k]
            if k not in placed:
                T = poses[k]
                obj.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
                placed.add(k)
            return obj

        for r, e in zip(*np.nonzero(env_c), strict=True):
            if fcl.collide(place(r), self._env_objs[e], self._request, fcl.CollisionResult()):
                pairs.append((self.robot_shapes[r].label, self.env_shapes[e].label))
                if first_only:
                    return pairs
        for p in np.nonzero(self_c)[0]:
            i, j = self._self_pairs[p]
            if fcl.collide(place(i), place(j), self._request, fcl.CollisionResult()):
                pairs.append((self.robot_shapes[i].label, self.robot_shapes[j].label))
                if first_only:
                    return pairs
        return pairs

    # ------------------------------------------------------------------ queries
    def check(self, q: np.ndarray) -> CollisionReport:
        """All colliding shape pairs at q (robot-environment and self)."""
        poses = self.shape_poses(np.asarray(q, dtype=float))
        env_c, self_c = self._candidates(poses)
        return CollisionReport(tuple(self._exact(poses, env_c, self_c, first_only=False)))

    def in_collision(self, q: np.ndarray) -> bool:
        poses = self.shape_poses(np.asarray(q, dtype=float))
        env_c, self_c = self._candidates(poses)
        if not env_c.any() and not self_c.any():
            return False
        return bool(self._exact(poses, env_c, self_c, first_only=True))

    def first_collision(self, qs: np.ndarray) -> int:
        """Index of the first colliding configuration of qs (K, n), or -1 if all are free.

        The broad phase runs for all K configurations in one vectorized call."""
        qs = np.asarray(qs, dtype=float)
        poses = np.stack([self.shape_poses(q) for q in qs])  # (K, R, 4, 4)
        env_c, self_c = self._candidates(poses)
        suspect = np.nonzero(env_c.any(axis=(1, 2)) | self_c.any(axis=1))[0]
        for k in suspect:
            if self._exact(poses[k], env_c[k], self_c[k], first_only=True):
                return int(k)
        return -1

    def distance(self, q: np.ndarray) -> DistanceReport:
        """Smallest robot-environment and robot-self distances at q [m] (exact, all pairs)."""
        poses = self.shape_poses(np.asarray(q, dtype=float))
        for obj, T in zip(self._robot_objs, poses, strict=True):
            obj.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
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
