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
from recon_cli.robot.batch_fk import BatchFK
from recon_cli.robot.broadphase import (
    bounding_box,
    bounding_capsule,
    segment_distance,
    segments_hit_boxes,
    world_aabbs,
)
from recon_cli.robot.kinematics import Kinematics
from recon_cli.robot.pair_field import PairField

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


@functools.lru_cache(maxsize=1)
def allowed_shape_pairs() -> frozenset[frozenset[str]]:
    """Shape pairs ("link/shape" labels) never checked, from robot/collision.yaml."""
    with open(ROBOT_DIR / "collision.yaml") as f:
        entries = yaml.safe_load(f).get("shapes", [])
    return frozenset(frozenset(pair) for pair in entries)


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
        shape_allowed = allowed_shape_pairs()
        self._self_pairs = np.array([
            (i, j) for i, j in itertools.combinations(range(len(self.robot_shapes)), 2)
            if frozenset((self.robot_shapes[i].link, self.robot_shapes[j].link)) not in self._allowed
            and frozenset((self.robot_shapes[i].label, self.robot_shapes[j].label)) not in shape_allowed
        ], dtype=int).reshape(-1, 2)
        self._self_r = self._cap_r[self._self_pairs[:, 0]] + self._cap_r[self._self_pairs[:, 1]]
        self._request = fcl.CollisionRequest()
        self._batch_fk = BatchFK(kin.model)
        self.lever = self._shape_lever_arms()  # (n, R)
        self._pair_lever = self._self_pair_levers()  # (P, n)
        self.certified_pairs = self._drop_separated_pairs()
        self._fields = self._pair_fields(urdf)  # (self pair index, PairField)
        self._static_separated: list[tuple[int, int, float]] | None = None
        self.set_object_box(object_box)

    def _separation_bound(self, distance, levers: np.ndarray, budget: int = 10000) -> float | None:
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

            def distance(q, i=i, j=j):
                poses = self.shape_poses(q)
                placed: set[int] = set()
                return fcl.distance(self._place(i, poses, placed), self._place(j, poses, placed), req,
                                    fcl.DistanceResult())

            bound = self._separation_bound(distance, self._pair_lever[p])
            if bound is not None:
                keep[p] = False
                certified.append((self.robot_shapes[i].label, self.robot_shapes[j].label, bound))
        self._self_pairs = self._self_pairs[keep]
        self._self_r = self._self_r[keep]
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

    def _build_field(self, i: int, j: int, joints: tuple[int, ...], levers: np.ndarray) -> PairField:
        req = fcl.DistanceRequest()
        lim = self.kin.limits

        def distances(x: np.ndarray) -> np.ndarray:
            qs = np.tile(pin.neutral(self.kin.model), (len(x), 1))
            qs[:, list(joints)] = x
            poses = self.shape_poses_batch(qs)
            out = np.empty(len(x))
            for k in range(len(x)):
                out[k] = fcl.distance(self._place(i, poses[k], set()), self._place(j, poses[k], set()), req,
                                      fcl.DistanceResult())
            return out

        return PairField.build(distances, joints, levers, lim.lower[list(joints)], lim.upper[list(joints)])

    def _field_cleared(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Indices of the self pairs whose distance tables clear the whole motion a -> b."""
        return np.array([p for p, field in self._fields if field.along(a, b) > 0.0], dtype=int)

    def _separated_env_pairs(self, env: list[CollisionShape], objs: list[fcl.CollisionObject],
                             skip: np.ndarray) -> list[tuple[int, int, float]]:
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

                def distance(q, r=r, obj=obj):
                    poses = self.shape_poses(q)
                    return fcl.distance(self._place(r, poses, set()), obj, req, fcl.DistanceResult())

                bound = self._separation_bound(distance, levers)
                if bound is not None:
                    out.append((r, e, bound))
        return out

    def _self_pair_levers(self) -> np.ndarray:
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

    def _shape_lever_arms(self) -> np.ndarray:
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
        # broad phase: world-aligned boxes around the (static) environment shapes
        self._env_c, self._env_h = world_aabbs(
            np.stack([s.joint_T_shape[:3, :3] for s in env]),
            np.stack([s.joint_T_shape[:3, 3] for s in env]),
            np.stack([bounding_box(s.kind, s.dims) for s in env]))  # (E, 3) each
        shape_allowed = allowed_shape_pairs()
        skip = np.array([
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

    # ------------------------------------------------------------------ placement
    def shape_poses(self, q: np.ndarray) -> np.ndarray:
        """World poses of the robot shapes at q, shape (R, 4, 4)."""
        pin.forwardKinematics(self.kin.model, self._data, q)
        oMi = np.stack([self._data.oMi[j].homogeneous for j in range(self.kin.model.njoints)])
        return oMi[self._robot_joints] @ self._robot_local

    def _candidates(self, poses: np.ndarray, grow: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Broad phase for poses (..., R, 4, 4): env candidates (..., R, E) and self
        candidates (..., P) (indices into the checked self pairs). ``grow`` (R,) enlarges
        each robot shape's bounding capsule [m] (swept-motion checks)."""
        R, t = poses[..., :3, :3], poses[..., :3, 3]
        a = (R @ self._cap_a[:, :, None])[..., 0] + t
        b = (R @ self._cap_b[:, :, None])[..., 0] + t
        radius = self._cap_r if grow is None else self._cap_r + grow
        env = segments_hit_boxes(a, b, radius, self._env_c, self._env_h)
        env &= ~self._env_allowed
        # self pairs: capsule boxes first, exact segment distances for the overlapping ones
        i, j = self._self_pairs[:, 0], self._self_pairs[:, 1]
        r = radius[..., :, None]
        lo, hi = np.minimum(a, b) - r, np.maximum(a, b) + r  # (..., R, 3)
        near = np.all((lo[..., i, :] <= hi[..., j, :]) & (hi[..., i, :] >= lo[..., j, :]), axis=-1)
        idx = np.nonzero(near)
        if len(idx[0]):
            pi, pj = i[idx[-1]], j[idx[-1]]
            rows = idx[:-1]
            dist = segment_distance(a[rows + (pi,)], b[rows + (pi,)], a[rows + (pj,)], b[rows + (pj,)])
            reach = self._self_r[idx[-1]]
            if grow is not None:
                g = np.broadcast_to(grow, a.shape[:-1])  # (..., R)
                reach = reach + g[rows + (pi,)] + g[rows + (pj,)]
            near[idx] = dist <= reach
        return env, near

    def _exact(self, poses: np.ndarray, env_c: np.ndarray, self_c: np.ndarray,
               first_only: bool) -> list[tuple[str, str]]:
        """Narrow phase with FCL on the candidate pairs of one configuration."""
        pairs: list[tuple[str, str]] = []
        placed: set[int] = set()
        for r, e in zip(*np.nonzero(env_c), strict=True):
            if fcl.collide(self._place(r, poses, placed), self._env_objs[e], self._request,
                           fcl.CollisionResult()):
                pairs.append((self.robot_shapes[r].label, self.env_shapes[e].label))
                if first_only:
                    return pairs
        for p in np.nonzero(self_c)[0]:
            i, j = self._self_pairs[p]
            if fcl.collide(self._place(i, poses, placed), self._place(j, poses, placed), self._request,
                           fcl.CollisionResult()):
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

    def shape_poses_batch(self, qs: np.ndarray) -> np.ndarray:
        """World poses of the robot shapes at many configurations, (K, R, 4, 4)."""
        oMi = self._batch_fk.joint_poses(qs)
        return oMi[:, self._robot_joints] @ self._robot_local

    def point_step_bound(self, dq: np.ndarray) -> np.ndarray:
        """Bound on the displacement [m] of any robot point for joint steps dq (..., n)."""
        return np.max(np.abs(dq) @ self.lever, axis=-1)

    def segment_free(self, a: np.ndarray, b: np.ndarray, max_step: float = 0.005,
                     sweep: float = 0.05, end_known_free: bool = False) -> bool:
        """Is the straight joint-space motion a -> b collision-free?

        1. Coarse samples, at which every shape's bounding capsule is grown by half the
           largest motion of that shape between samples (at most ``sweep`` [m]), cover the
           swept volume in one vectorized broad phase; a pair that never meets there cannot
           collide anywhere on the segment.
        2. Around coarse samples where a grown capsule meets something, the flagged shape
           pairs are followed by conservative advancement with FCL distances: at distance d
           a pair cannot touch before its shapes have moved d, so the next check is that far
           along - but never further than ``max_step`` [m] of robot-point motion, the
           resolution every executed trajectory is checked at.

        A planner's tree extends toward random states and most blocked extensions end in
        collision: the end configuration is checked alone first (one configuration is far
        cheaper than the segment), unless the caller knows it is free (``end_known_free``).
        """
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        if not end_known_free and self.in_collision(b):
            return False
        per_shape = np.abs(b - a) @ self.lever  # (R,) motion bound of each shape over a -> b
        longest = float(per_shape.max())
        m = max(1, int(np.ceil(longest / (2.0 * sweep))))
        t = np.linspace(0.0, 1.0, m + 1)
        poses = self.shape_poses_batch(a + t[:, None] * (b - a))
        env_c, self_c = self._candidates(poses, per_shape / (2.0 * m))
        cleared = self._field_cleared(a, b) if self_c.any() else np.zeros(0, dtype=int)
        self_c[:, cleared] = False
        flagged = env_c.any(axis=(1, 2)) | self_c.any(axis=1)
        if not flagged.any():
            return True
        # a blocked motion usually collides where the most pairs are near: check the
        # coarse sample with the most candidates exactly before following pairs along it
        k = int(np.argmax(env_c.sum(axis=(1, 2)) + self_c.sum(axis=1)))
        if self._exact(poses[k], *self._candidates(poses[k]), first_only=True):
            return False
        min_dt = max_step / longest if longest > 0 else 1.0
        k = 0
        while k <= m:
            if not flagged[k]:
                k += 1
                continue
            first = k
            while k + 1 <= m and flagged[k + 1]:
                k += 1
            lo, hi = max(first - 1, 0), min(k + 1, m)
            env_pairs = np.argwhere(env_c[lo:hi + 1].any(axis=0))
            chosen = np.nonzero(self_c[lo:hi + 1].any(axis=0))[0]
            pair_speed = self._pair_lever[chosen] @ np.abs(b - a)
            if not self._advance(a, b, t[lo], t[hi], env_pairs, self._self_pairs[chosen], pair_speed,
                                 per_shape, min_dt):
                return False
            k += 1
        return True

    def _advance(self, a, b, t0: float, t1: float, env_pairs: np.ndarray, self_pairs: np.ndarray,
                 pair_speed: np.ndarray, per_shape: np.ndarray, min_dt: float) -> bool:
        """Conservative advancement of a few shape pairs over a -> b for t in [t0, t1].

        A pair whose distance exceeds the motion it can still make before t1 is dropped."""
        req = fcl.DistanceRequest()
        env = [(int(s_idx), int(e_idx), float(per_shape[s_idx])) for s_idx, e_idx in env_pairs]
        slf = [(int(i), int(j), float(v)) for (i, j), v in zip(self_pairs, pair_speed, strict=True)]
        t = t0
        while env or slf:
            poses = self.shape_poses(a + t * (b - a))
            placed: set[int] = set()
            dt = np.inf
            remaining = t1 - t
            keep_env = []
            for s_idx, e_idx, speed in env:
                d = fcl.distance(self._place(s_idx, poses, placed), self._env_objs[e_idx], req,
                                 fcl.DistanceResult())
                if d <= 0.0:
                    return False
                if speed * remaining >= d:
                    keep_env.append((s_idx, e_idx, speed))
                    dt = min(dt, d / speed)
            keep_self = []
            for i, j, speed in slf:
                d = fcl.distance(self._place(i, poses, placed), self._place(j, poses, placed), req,
                                 fcl.DistanceResult())
                if d <= 0.0:
                    return False
                if speed * remaining >= d:
                    keep_self.append((i, j, speed))
                    dt = min(dt, d / speed)
            env, slf = keep_env, keep_self
            if t >= t1:
                return True
            t = min(t + max(dt, min_dt), t1) if np.isfinite(dt) else t1
        return True

    def _place(self, k: int, poses: np.ndarray, placed: set[int]) -> fcl.CollisionObject:
        obj = self._robot_objs[k]
        if k not in placed:
            T = poses[k]
            obj.setTransform(fcl.Transform(T[:3, :3], T[:3, 3]))
            placed.add(k)
        return obj

    def first_collision_sampled(self, qs: np.ndarray, block: int = 16) -> int:
        """Like ``first_collision`` for a densely sampled motion (K, n): samples are grouped
        in blocks; each shape's capsule at a block's middle sample is grown by how far that
        shape can be from there at any sample of the block (summed per-sample motion bounds),
        so a clean block needs no further checks. Only blocks where something is near are
        checked sample by sample. Same answer as checking every sample."""
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        K = len(qs)
        if K <= block:
            return self.first_collision(qs)
        step = np.abs(np.diff(qs, axis=0)) @ self.lever  # (K-1, R) per-shape motion bounds
        cum = np.vstack([np.zeros((1, step.shape[1])), np.cumsum(step, axis=0)])  # (K, R)
        starts = np.arange(0, K, block)
        mids = np.minimum(starts + block // 2, K - 1)
        ends = np.minimum(starts + block - 1, K - 1)
        grow = np.maximum(cum[mids] - cum[starts], cum[ends] - cum[mids])  # (B, R)
        poses = self.shape_poses_batch(qs[mids])
        R, t = poses[..., :3, :3], poses[..., :3, 3]
        a = (R @ self._cap_a[:, :, None])[..., 0] + t
        b = (R @ self._cap_b[:, :, None])[..., 0] + t
        env = segments_hit_boxes(a, b, self._cap_r + grow, self._env_c, self._env_h) & ~self._env_allowed
        i, j = self._self_pairs[:, 0], self._self_pairs[:, 1]
        dist = segment_distance(a[:, i, :], b[:, i, :], a[:, j, :], b[:, j, :])
        self_near = dist <= self._self_r + grow[:, i] + grow[:, j]  # (B, P)
        if self._fields:  # pairs whose distance tables are positive at every sample of a block
            block_of = np.arange(K) // block
            for p, field in self._fields:
                low = np.full(len(starts), np.inf)
                np.minimum.at(low, block_of, field.at(qs))
                self_near[low > 0.0, p] = False
        for k in np.nonzero(env.any(axis=(1, 2)) | self_near.any(axis=1))[0]:
            hit = self._advance_samples(qs, cum, int(starts[k]), int(ends[k]),
                                        np.argwhere(env[k]), self._self_pairs[self_near[k]])
            if hit >= 0:
                return hit
        return -1

    def _advance_samples(self, qs: np.ndarray, cum: np.ndarray, start: int, end: int,
                         env_pairs: np.ndarray, self_pairs: np.ndarray) -> int:
        """Conservative advancement over samples start..end of a dense motion for a few
        candidate pairs: after measuring distance d, samples whose accumulated motion bound
        (``cum``, per shape) stays below d are skipped. Returns the first colliding sample."""
        req = fcl.DistanceRequest()
        k = start
        while k <= end:
            poses = self.shape_poses(qs[k])
            placed: set[int] = set()
            nxt = end + 1
            for s_idx, e_idx in env_pairs:
                d = fcl.distance(self._place(s_idx, poses, placed), self._env_objs[e_idx], req,
                                 fcl.DistanceResult())
                if d <= 0.0:
                    return k
                moved = cum[k + 1:end + 1, s_idx] - cum[k, s_idx]
                nxt = min(nxt, k + 1 + int(np.searchsorted(moved, d)))
            for i, j in self_pairs:
                d = fcl.distance(self._place(i, poses, placed), self._place(j, poses, placed), req,
                                 fcl.DistanceResult())
                if d <= 0.0:
                    return k
                moved = (cum[k + 1:end + 1, i] - cum[k, i]) + (cum[k + 1:end + 1, j] - cum[k, j])
                nxt = min(nxt, k + 1 + int(np.searchsorted(moved, d)))
            k = max(nxt, k + 1)
        return -1

    def first_collision(self, qs: np.ndarray) -> int:
        """Index of the first colliding configuration of qs (K, n), or -1 if all are free.

        The broad phase runs for all K configurations in one vectorized call."""
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        hit = -1
        for start in range(0, len(qs), 256):
            chunk = qs[start:start + 256]
            poses = self.shape_poses_batch(chunk)  # (K, R, 4, 4)
            env_c, self_c = self._candidates(poses)
            suspect = np.nonzero(env_c.any(axis=(1, 2)) | self_c.any(axis=1))[0]
            for k in suspect:
                if self._exact(poses[k], env_c[k], self_c[k], first_only=True):
                    hit = start + int(k)
                    break
            if hit >= 0:
                return hit
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
