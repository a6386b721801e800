"""Collision model of the cell (thesis section 2.2.4).

The shapes come from the ``<collision>`` elements of the expanded URDF: capsules for the
iiwa links, boxes for everything else (frame, axes, table, board, camera), all already
inflated by the cell's safety distance. A cylinder named ``*_capsule`` becomes one exact FCL
capsule; its end spheres ``*_capsule_end_*`` are then skipped. An optional object bounding
box (the scan object, thesis 4.1/4.2) is added to the environment, inflated by the same
safety distance.

Checked pairs: every robot shape against every environment shape, and robot shapes of
different links against each other, except links on the same rigid body, a link and its
URDF parent, the pairs listed with a reason in the cell file's collision section, and the pairs proven
apart over the whole joint range. Yes/no queries run batched in C++ (pinocchio + coal,
``motion_check``); python-fcl on the same shapes answers distance queries, proves the
certificates and names the pairs of a collision report.

One module of about 500 lines on purpose: the shapes, the pair filter, the separation
certificates and both checkers index the same shape list, and keeping them together keeps
that invariant in one place.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
from lxml import etree

from recon_cli.errors import InputError
from recon_cli.geometry.transforms import pose_from_xyz_rpy
from recon_cli.lazy import lazy_module
from recon_cli.robot.batch_fk import BatchFK
from recon_cli.robot.cell_file import DEFAULT_CELL, CellFile, load_cell
from recon_cli.robot.kinematics import Kinematics
from recon_cli.robot.motion_check import BatchChecker
from recon_cli.robot.pair_field import PairField
from recon_cli.robot.shapes import CollisionShape
from recon_cli.robot.urdf import attribute, child

if TYPE_CHECKING:
    import fcl
    import pinocchio as pin
else:
    fcl = lazy_module("fcl")
    pin = lazy_module("pinocchio")

OBJECT_LINK = "object"
_FIELD_CACHE: dict[tuple[str, str, str], PairField] = {}


@dataclass(frozen=True)
class ObjectBox:
    """Axis-aligned bounding box of the object in the world [m] (before inflation).

    center: (3,) box centre in the world; size: (3,) full edge lengths.
    """

    center: tuple[float, float, float]
    size: tuple[float, float, float]

    @classmethod
    def on_table(cls, size: Iterable[float], xy: Sequence[float] = (0.0, 0.0),
                 table_top_z: float = 0.68) -> ObjectBox:
        sx, sy, sz = (float(v) for v in size)
        return cls((float(xy[0]), float(xy[1]), table_top_z + sz / 2.0), (sx, sy, sz))

    @property
    def lower(self) -> npt.NDArray[np.float64]:
        return np.asarray(self.center) - np.asarray(self.size) / 2.0

    @property
    def upper(self) -> npt.NDArray[np.float64]:
        return np.asarray(self.center) + np.asarray(self.size) / 2.0


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


def _shape_reach(shape: CollisionShape) -> float:
    """Largest distance of a shape's points from its own origin [m]."""
    d = shape.dims
    if shape.kind == "box":
        return float(np.linalg.norm(np.asarray(d) / 2.0))
    if shape.kind in ("capsule", "cylinder"):
        return float(np.hypot(d[1] / 2.0, d[0])) if shape.kind == "cylinder" else float(d[1] / 2.0 + d[0])
    return float(d[0])


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
    for link in root.iterfind("link"):
        link_name = attribute(link, "name")
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
            geom = child(col, "geometry")[0]
            dims: tuple[float, ...]
            if geom.tag == "box":
                kind, dims = "box", tuple(float(v) for v in attribute(geom, "size").split())
            elif geom.tag == "cylinder":
                kind = "capsule" if name.endswith("_capsule") else "cylinder"
                dims = (float(attribute(geom, "radius")), float(attribute(geom, "length")))
            elif geom.tag == "sphere":
                kind, dims = "sphere", (float(attribute(geom, "radius")),)
            else:
                raise ValueError(f"unsupported collision geometry <{geom.tag!s}> in link {link_name}")
            shapes.append(CollisionShape(name, link_name, int(frame.parentJoint), kind, dims,
                                         joint_T_link @ pose_from_xyz_rpy(xyz, rpy)))
    return shapes


def allowed_shape_pairs(cell: CellFile | None = None) -> frozenset[frozenset[str]]:
    """Shape pairs ("link/shape" labels) never checked, from the cell file (None: the default cell)."""
    cell = cell if cell is not None else load_cell(DEFAULT_CELL)
    return frozenset(frozenset(pair) for pair in cell.allowed_shapes)


def allowed_link_pairs(urdf: str, kin: Kinematics) -> set[frozenset[str]]:
    """Link pairs that are never checked (same rigid body, URDF parent/child, declared in the
    cell file of ``kin``)."""
    root = etree.fromstring(urdf.encode())
    allowed: set[frozenset[str]] = {frozenset(pair.links) for pair in kin.cell.allowed_links}
    links = [attribute(link, "name") for link in root.iterfind("link")]
    body = {name: kin.model.frames[kin.model.getFrameId(name, pin.BODY)].parentJoint
            for name in links}
    allowed.update(frozenset((a,)) for a in links)  # shapes of one link
    for a, b in itertools.combinations(links, 2):
        if body[a] == body[b]:
            allowed.add(frozenset((a, b)))
    for joint in root.iterfind("joint"):
        allowed.add(frozenset((attribute(child(joint, "parent"), "link"), attribute(child(joint, "child"), "link"))))
    return allowed


class CollisionModel:
    """Yes/no collision checks and distance queries for configurations of one cell.

    This class decides what is checked (shapes from the URDF, allowed pairs, pairs certified
    separated over the whole joint range, distance tables). Yes/no queries of configurations
    and motions run batched in C++ (pinocchio + coal, ``recon_cli.robot.motion_check``);
    distances, certificates and collision reports use python-fcl on the same shapes.
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
        if not self.robot_shapes:
            raise InputError(f"{kin.cell.description}: no link that a joint moves has a <collision> shape, so "
                             "nothing keeps the robot from hitting the table or itself",
                             hint="give the robot's links <collision> shapes (boxes, cylinders, spheres or meshes)")
        self._robot_geoms = [_geometry(s.kind, s.dims) for s in self.robot_shapes]
        self._robot_objs = [fcl.CollisionObject(g, fcl.Transform()) for g in self._robot_geoms]
        self._robot_joints: npt.NDArray[np.intp] = np.array([s.joint for s in self.robot_shapes])
        self._robot_local = np.stack([s.joint_T_shape for s in self.robot_shapes])  # (R, 4, 4)
        # robot shape pairs to check against each other
        shape_allowed = allowed_shape_pairs(self.kin.cell)
        self._self_pairs: npt.NDArray[np.intp] = np.array([
            (i, j) for i, j in itertools.combinations(range(len(self.robot_shapes)), 2)
            if frozenset((self.robot_shapes[i].link, self.robot_shapes[j].link)) not in self._allowed
            and frozenset((self.robot_shapes[i].label, self.robot_shapes[j].label)) not in shape_allowed
        ], dtype=int).reshape(-1, 2)
        self._request = fcl.CollisionRequest()
        self._batch_fk = BatchFK(kin.model)
        self.lever = self._shape_lever_arms()  # (n, R)
        self._pair_lever = self._self_pair_levers()  # (P, n)
        self.certified_pairs = self._drop_separated_pairs()
        self._fields = self._pair_fields(urdf)  # (self pair index, PairField)
        self._static_separated: list[tuple[int, int, float]] | None = None
        self.set_object_box(object_box)

    def _separation_bound(self, distance: Callable[[npt.NDArray[np.float64]], float],
                          levers: npt.NDArray[np.float64], budget: int = 10000) -> float | None:
        """Certify that a shape pair cannot touch anywhere in the joint range.

        ``distance(q)`` is the pair's exact distance at q; ``levers`` (n,) bound how far the
        two shapes can move relative to each other per unit of each joint (0 for joints that
        do not change their relative pose). The box of joint ranges is split recursively: in
        a box with centre c and half widths h the pair moves by at most levers . h from its
        pose at c, so the box is clear when distance(c) is larger. Returns a positive lower
        bound of the pair's distance over all configurations, or None when the pair can touch
        (or the proof needs more than ``budget`` distance queries)."""
        joints = np.nonzero(levers)[0]
        lim = self.kin.limits
        q = pin.neutral(self.kin.model)
        stack = [(lim.lower[joints].astype(float), lim.upper[joints].astype(float))]
        bound, evals = np.inf, 0
        while stack:
            lo, hi = stack.pop()
            centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
            q[joints] = centre
            d = distance(q)
            evals += 1
            if d <= 1e-4 or evals > budget:
                return None
            reach = float(levers[joints] @ half)
            if d > reach:
                bound = min(bound, d - reach)
                continue
            k = int(np.argmax(levers[joints] * half))
            mid = centre[k]
            hi_a, lo_b = hi.copy(), lo.copy()
            hi_a[k], lo_b[k] = mid, mid
            stack += [(lo, hi_a), (lo_b, hi)]
        return float(bound)

    def _drop_separated_pairs(self) -> list[tuple[str, str, float]]:
        """Remove self pairs whose relative pose depends on at most two joints and that no
        configuration can bring into contact (``_separation_bound``). Returns the certified
        pairs with their distance lower bound [m]."""
        keep = np.ones(len(self._self_pairs), dtype=bool)
        certified = []
        req = fcl.DistanceRequest()
        for p, (i, j) in enumerate(self._self_pairs):
            if np.count_nonzero(self._pair_lever[p]) > 2:
                continue

            def distance(q: npt.NDArray[np.float64], i: int = i, j: int = j) -> float:
                poses = self.shape_poses(q)
                placed: set[int] = set()
                return float(fcl.distance(self._place(i, poses, placed), self._place(j, poses, placed), req,
                                          fcl.DistanceResult()))

            bound = self._separation_bound(distance, self._pair_lever[p])
            if bound is not None:
                keep[p] = False
                certified.append((self.robot_shapes[i].label, self.robot_shapes[j].label, bound))
        self._self_pairs = self._self_pairs[keep]
        self._pair_lever = self._pair_lever[keep]
        return certified

    def _pair_fields(self, urdf: str) -> list[tuple[int, PairField]]:
        """Distance lower-bound tables for the checked self pairs moved by two joints or fewer
        relative to each other (``PairField``); cached per robot description."""
        out = []
        for p, (i, j) in enumerate(self._self_pairs):
            joints = tuple(int(k) for k in np.nonzero(self._pair_lever[p])[0])
            if not 1 <= len(joints) <= 2:
                continue
            key = (urdf, self.robot_shapes[i].label, self.robot_shapes[j].label)
            if key not in _FIELD_CACHE:
                _FIELD_CACHE[key] = self._build_field(i, j, joints, self._pair_lever[p][list(joints)])
            out.append((p, _FIELD_CACHE[key]))
        return out

    def _build_field(self, i: int, j: int, joints: tuple[int, ...], levers: npt.NDArray[np.float64]) -> PairField:
        req = fcl.DistanceRequest()
        lim = self.kin.limits

        def distances(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            qs = np.tile(pin.neutral(self.kin.model), (len(x), 1))
            qs[:, list(joints)] = x
            poses = self.shape_poses_batch(qs)
            out = np.empty(len(x))
            for k in range(len(x)):
                out[k] = fcl.distance(self._place(i, poses[k], set()), self._place(j, poses[k], set()), req,
                                      fcl.DistanceResult())
            return out

        return PairField.build(distances, joints, levers, lim.lower[list(joints)], lim.upper[list(joints)])

    def _separated_env_pairs(self, env: list[CollisionShape], objs: list[fcl.CollisionObject],
                             skip: npt.NDArray[np.bool_]) -> list[tuple[int, int, float]]:
        """Robot-environment pairs that can never touch: robot shapes moved by at most two
        joints (the gantry axes and what rides on them) against every environment shape."""
        req = fcl.DistanceRequest()
        out = []
        for r in range(len(self.robot_shapes)):
            levers = self.lever[:, r]
            if np.count_nonzero(levers) > 2:
                continue
            for e, obj in enumerate(objs):
                if skip[r, e]:
                    continue

                def distance(q: npt.NDArray[np.float64], r: int = r, obj: fcl.CollisionObject = obj) -> float:
                    poses = self.shape_poses(q)
                    return float(fcl.distance(self._place(r, poses, set()), obj, req, fcl.DistanceResult()))

                bound = self._separation_bound(distance, levers)
                if bound is not None:
                    out.append((r, e, bound))
        return out

    def _self_pair_levers(self) -> npt.NDArray[np.float64]:
        """Relative-motion levers of the checked self pairs, (P, n): joints that move both
        shapes alike (common ancestors) do not change their distance."""
        model = self.kin.model

        def ancestors(joint: int) -> set[int]:
            out = set()
            while joint > 0:
                out.add(int(model.joints[joint].idx_q))
                joint = model.parents[joint]
            return out

        levers = np.zeros((len(self._self_pairs), model.nq))
        for p, (i, j) in enumerate(self._self_pairs):
            ai = ancestors(self.robot_shapes[i].joint)
            aj = ancestors(self.robot_shapes[j].joint)
            for k in ai - aj:
                levers[p, k] += self.lever[k, i]
            for k in aj - ai:
                levers[p, k] += self.lever[k, j]
        return levers

    def _shape_lever_arms(self) -> npt.NDArray[np.float64]:
        """r[j, s]: bound on how far any point of robot shape s moves per unit motion of
        joint j [m/rad, or 1 for a prismatic joint; 0 when j does not move s]. Triangle
        inequality along the chain: joint-origin offsets from j to the shape's joint, plus the
        shape's offset and reach."""
        model = self.kin.model
        lever = np.zeros((model.nq, len(self.robot_shapes)))
        for s_idx, shape in enumerate(self.robot_shapes):
            reach = float(np.linalg.norm(shape.joint_T_shape[:3, 3])) + _shape_reach(shape)
            k, dist = shape.joint, reach
            while k > 0:
                iq = model.joints[k].idx_q
                lever[iq, s_idx] = 1.0 if model.joints[k].shortname().startswith("JointModelP") else dist
                dist += float(np.linalg.norm(model.jointPlacements[k].translation))
                k = model.parents[k]
        return lever

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
        shape_allowed = allowed_shape_pairs(self.kin.cell)
        skip: npt.NDArray[np.bool_] = np.array([
            [frozenset((r.link, e.link)) in self._allowed or frozenset((r.label, e.label)) in shape_allowed
             for e in env] for r in self.robot_shapes
        ], dtype=bool)  # (R, E)
        # pairs certified separated over the whole joint range are not checked either; the
        # static environment is certified once, the object box each time it changes
        n_static = len(self._static_env_shapes)
        if self._static_separated is None:
            self._static_separated = self._separated_env_pairs(
                env[:n_static], self._env_objs[:n_static], skip[:, :n_static])
        separated = list(self._static_separated)
        if box is not None:
            separated += [(r, n_static, b) for r, _, b in self._separated_env_pairs(
                env[n_static:], self._env_objs[n_static:], skip[:, n_static:])]
        for r, e, _ in separated:
            skip[r, e] = True
        self.certified_env_pairs = [(self.robot_shapes[r].label, env[e].label, b) for r, e, b in separated]
        self._env_allowed = skip
        self._batch = self._batch_checker()

    def _batch_checker(self) -> BatchChecker:
        """The checked pairs, handed to pinocchio/coal for batched checks; the pairs with
        distance tables stay out of its inflated copies."""
        n_robot = len(self.robot_shapes)
        env_pairs = [(int(r), n_robot + int(e)) for r, e in zip(*np.nonzero(~self._env_allowed), strict=True)]
        self_pairs = [(int(i), int(j)) for i, j in self._self_pairs]
        tabled = {p for p, _ in self._fields}
        swept = env_pairs + [pair for p, pair in enumerate(self_pairs) if p not in tabled]
        return BatchChecker(self.kin.model, self.robot_shapes + self.env_shapes, n_robot,
                            env_pairs + self_pairs, swept, self.lever, [f for _, f in self._fields])

    # ------------------------------------------------------------------ placement
    def shape_poses(self, q: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """World poses of the robot shapes at q, shape (R, 4, 4)."""
        pin.forwardKinematics(self.kin.model, self._data, q)
        oMi: npt.NDArray[np.float64] = np.stack([self._data.oMi[j].homogeneous for j in range(self.kin.model.njoints)])
        return oMi[self._robot_joints] @ self._robot_local

    def _collide(self, i: int, obj: fcl.CollisionObject, poses: npt.NDArray[np.float64], placed: set[int]) -> bool:
        return bool(fcl.collide(self._place(i, poses, placed), obj, self._request, fcl.CollisionResult()))

    # ------------------------------------------------------------------ queries
    def check(self, q: npt.NDArray[np.float64]) -> CollisionReport:
        """All colliding shape pairs at q (robot-environment and self), every checked pair
        tested with python-fcl: the reference the batch checker is tested against, and the
        report behind every collision message."""
        poses = self.shape_poses(np.asarray(q, dtype=float))
        placed: set[int] = set()
        pairs = [(self.robot_shapes[r].label, self.env_shapes[e].label)
                 for r, e in zip(*np.nonzero(~self._env_allowed), strict=True)
                 if self._collide(int(r), self._env_objs[e], poses, placed)]
        pairs += [(self.robot_shapes[i].label, self.robot_shapes[j].label) for i, j in self._self_pairs
                  if self._collide(int(i), self._place(int(j), poses, placed), poses, placed)]
        return CollisionReport(tuple(pairs))

    def in_collision(self, q: npt.NDArray[np.float64]) -> bool:
        return self._batch.in_collision(np.asarray(q, dtype=float))

    def shape_poses_batch(self, qs: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """World poses of the robot shapes at many configurations, (K, R, 4, 4)."""
        oMi = self._batch_fk.joint_poses(qs)
        return oMi[:, self._robot_joints] @ self._robot_local

    def point_step_bound(self, dq: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Bound on the displacement [m] of any robot point for joint steps dq (..., n)."""
        bound: npt.NDArray[np.float64] = np.max(np.abs(dq) @ self.lever, axis=-1)
        return bound

    def segment_free(self, a: npt.NDArray[np.float64], b: npt.NDArray[np.float64], max_step: float = 0.005,
                     end_known_free: bool = False) -> bool:
        """Is the straight joint-space motion a -> b collision-free? Every instant is proved
        free or lies within ``max_step`` / 2 of robot-point motion of an exactly checked
        sample (``recon_cli.robot.motion_check``). A planner's tree extends toward random
        states and most blocked extensions end in collision, so the end configuration is
        checked first, unless the caller knows it is free (``end_known_free``)."""
        return self._batch.segment_free(a, b, max_step, check_end=not end_known_free)

    def first_collision(self, qs: npt.NDArray[np.float64]) -> int:
        """Index of the first colliding configuration of qs (K, n), or -1 if all are free
        (batched: inflated copies clear runs of nearby samples, exact checks for the rest)."""
        return self._batch.first_collision(qs)

    def _place(self, k: int, poses: npt.NDArray[np.float64], placed: set[int]) -> fcl.CollisionObject:
        obj = self._robot_objs[k]
        if k not in placed:
            T = poses[k]
            obj.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
            placed.add(k)
        return obj

    def distance(self, q: npt.NDArray[np.float64]) -> DistanceReport:
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

    def point_inside_environment(self, point: npt.NDArray[np.float64]) -> str | None:
        """Label of the environment shape (inflated) that contains a world point, if any."""
        probe = fcl.CollisionObject(fcl.Sphere(1e-6), fcl.Transform(np.asarray(point, float)))
        for shape, obj in zip(self.env_shapes, self._env_objs, strict=True):
            if fcl.collide(probe, obj, fcl.CollisionRequest(), fcl.CollisionResult()):
                return shape.label
        return None
