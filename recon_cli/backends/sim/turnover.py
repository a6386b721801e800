"""Turning an object over between the two sides of a two-sided scan, by physics.

An operator turns the object over onto another face it can rest on and puts it back on its
spot; in simulation the faces it can rest on are the stable faces of its convex hull
(:mod:`recon_cli.backends.sim.resting`, upside down included: a bowl on its rim), and the
turn puts it on the one a ranking prefers (the two-sided scan's: the face that exposes most
of what side 1 missed while side 1's surface still fixes the registration,
recon_cli/both_sides.py; without one, a flank, the most stable first), with a random yaw,
drops it from a few mm onto a plane at the surface it stands on, and lets MuJoCo simulate
it until it lies still. Physics confirms the face: an object that settles elsewhere (it
rolled off a narrow face) is put on the next face of the ranking. It is then moved in x, y
so that its world bounding-box centre is where it was (the operator puts it back on the
spot), keeping the settled height and orientation. An object with no stable face but the
one it stands on cannot be turned over: one line says so.

The object is one free rigid body of uniform density (:data:`DENSITY`): mass, centre of
mass and inertia of the solid union of its primitives (built-in objects), else of its
closed mesh, else of its mesh's convex hull. Collision geometry: MuJoCo's own boxes,
cylinders and spheres for the primitives (exact round surfaces; a torus is its convex
hull), else the object mesh, of which MuJoCo takes the convex hull. Against a plane that is
exact, whatever the shape: a rigid body touches a plane only where its convex hull does,
so a concave object (a mug) rests as its hull rests, and a convex decomposition would give
the same poses; the primitives give round bodies that are really round. Friction: sliding
0.5 (wood, plastic on a printed board); round primitives add MuJoCo's torsional and rolling
friction (condim 6), made hard by its noslip solver, so that a bottle on its side stops
rolling as a real one does.

Random numbers come from the generator passed in, and MuJoCo is deterministic: the same
seed gives the same pose.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.backends.sim.resting import Rest, resting_faces, tilt_deg
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import pose, pose_error, rot_z, rotation_between, transform_points
from recon_cli.lazy import lazy_module
from recon_cli.objects import Primitive, SceneObject

if TYPE_CHECKING:
    import mujoco
else:
    mujoco = lazy_module("mujoco")

log = logging.getLogger(__name__)

DENSITY = 700.0
"""Uniform density of the simulated solid [kg/m^3] (wood, plastics; only the mass
distribution matters for the resting pose)."""
FRICTION = (0.5, 0.005, 0.0001)
"""Sliding [-], torsional [m] and rolling [m] friction of the object on the surface."""
TIMESTEP_S = 0.001
NOSLIP_ITERATIONS = 10
"""MuJoCo's noslip solver makes friction hard: without it, a soft rolling-friction constraint
lets a bottle on its side creep on for many seconds."""
DROP_M = (0.002, 0.005)
"""Range of the drop height of the lowest point above the surface [m]."""
REST_SPEED = 1e-3
"""At rest: linear speed [m/s] below this ..."""
REST_SPIN = math.radians(0.5)
"""... and angular speed [rad/s] below this ..."""
REST_HOLD_S = 0.25
"""... for this long [s]; speeds are the pose change over each ``REST_SAMPLE_S`` [s] divided by
it: a body resting on a finely tessellated hull (a YCB mesh) chatters in MuJoCo's soft
contacts at instantaneous speeds of about 1 deg/s while its pose stays within 0.01 deg."""
REST_SAMPLE_S = 0.05
TIMEOUT_S = 10.0
"""Simulated time [s] after which an object still moving is an error."""
MIN_TILT_DEG = 60.0
"""A face whose normal is within this [deg] of the face down now is the same face."""
CONFIRM_DEG = 15.0
"""The object settled on the face it was put on when that face's normal ends within this
[deg] of straight down (a round body rolls a strip or two on)."""
MAX_ATTEMPTS = 8
"""Faces tried (best ranked first) before an object that settles on none of them is an error."""
SIMILAR_DEG = 30.0
"""After a face that did not hold, faces within this [deg] of it are not tried: the strips of
a tessellated round side (a mug lying opposite its handle rolls onto the handle)."""
_GRID = 64  # cells along the longest side when integrating a union of primitives


@dataclass(frozen=True)
class TurnOver:
    """Where an object came to rest after it was turned over."""

    world_T_object: np.ndarray  # (4, 4) the new resting pose, object frame -> world
    down_object: np.ndarray  # (3,) unit vector in the object frame that now points down (-z world)
    tilt_deg: float  # angle between the old and the new object "up" axis [deg]
    settle_s: float  # simulated seconds until at rest [s]
    dropped_from: float  # height of the drop above the rest surface [m]
    rest: Rest | None = None  # the hull face it was put on and settled on
    faces: int = 0  # stable faces other than the one it stood on
    tried: int = 1  # faces put on until physics confirmed one


Rank = Callable[[Rest], float]
"""A face's preference (larger first) for the turn."""


def turned(obj: SceneObject, t: TurnOver) -> SceneObject:
    """A copy of ``obj`` at the resting pose of ``t``."""
    return replace(obj, world_T_object=t.world_T_object.copy())


def other_faces(obj: SceneObject) -> tuple[list[Rest], np.ndarray]:
    """The stable faces of ``obj``'s hull (:func:`resting_faces`) other than the one it
    stands on now, and the object-frame direction that points down now."""
    down_now = obj.world_T_object[:3, :3].T @ np.array([0.0, 0.0, -1.0])
    _, com, _ = mass_properties(obj)
    return [r for r in resting_faces(obj.vertices, com) if tilt_deg(r.down, down_now) > MIN_TILT_DEG], down_now


def flank_first(down_now: np.ndarray) -> Rank:
    """The ranking without one of the caller's: a flank (tilted by 60-120 deg: the old resting
    face is then seen from the side, and the two sides share the old top and a flank), the
    most stable first; then the others, the most stable first."""
    return lambda r: (1000.0 if tilt_deg(r.down, down_now) <= 120.0 else 0.0) + r.tipping_deg


def turn_over(obj: SceneObject, rng: np.random.Generator, surface_z: float | None = None,
              rank: Rank | None = None) -> TurnOver:
    """Turn ``obj`` over onto another stable face of its hull and let it settle on the plane
    ``surface_z`` [m] (default: the lowest world z of its vertices, the surface it rests on
    now).

    The faces are tried in the order of ``rank`` (default :func:`flank_first`), each with a
    random yaw from ``rng`` and a drop of 2-5 mm, until physics confirms one (the face ends
    within :data:`CONFIRM_DEG` of straight down), :data:`MAX_ATTEMPTS` at most. A ReconError
    when the object has no other stable face, when it settles on none of those tried, or
    when it is still moving after :data:`TIMEOUT_S` of simulated time.
    """
    old = obj.world_T_object
    surface = float(obj.world_vertices()[:, 2].min()) if surface_z is None else float(surface_z)
    up_object = old[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # the object axis that points up now
    faces, down_now = other_faces(obj)
    if not faces:
        raise ReconError(f"the object '{obj.name}' cannot be turned over: its convex hull has no stable face but the "
                         f"one it stands on (a face within {MIN_TILT_DEG:g} deg of it is the same face)",
                         hint="scan it on one side (--sides 1)")
    lo, hi = obj.world_aabb()
    centre = (lo + hi) / 2.0
    sim = _Sim(obj, surface)
    ordered = sorted(faces, key=rank or flank_first(down_now), reverse=True)
    landed: list[float] = []
    tried: list[Rest] = []
    for face in ordered:
        if len(tried) == MAX_ATTEMPTS:
            break
        if any(tilt_deg(face.down, t.down) < SIMILAR_DEG for t in tried):
            continue  # a strip of the same round side as a face that did not hold
        tried.append(face)
        attempt = len(tried)
        yaw = rng.uniform(0.0, 2.0 * math.pi)
        drop = float(rng.uniform(*DROP_M))
        R = rot_z(yaw) @ rotation_between(face.down, [0.0, 0.0, -1.0])
        start = pose(R, np.zeros(3))
        v = transform_points(start, obj.vertices)
        start[:2, 3] = centre[:2] - (v.min(axis=0)[:2] + v.max(axis=0)[:2]) / 2.0
        start[2, 3] = surface + drop - float(v[:, 2].min())
        rest, settle_s = sim.settle(start, obj.name)
        off = tilt_deg(rest[:3, :3] @ face.down, np.array([0.0, 0.0, -1.0]))
        tilt = math.degrees(math.acos(float(np.clip((rest[:3, :3] @ up_object)[2], -1.0, 1.0))))
        if off <= CONFIRM_DEG and tilt > MIN_TILT_DEG:
            v = transform_points(rest, obj.vertices)
            rest[:2, 3] += centre[:2] - (v.min(axis=0)[:2] + v.max(axis=0)[:2]) / 2.0  # back on the spot
            down = rest[:3, :3].T @ np.array([0.0, 0.0, -1.0])
            log.debug("%s turned over onto face %d of %d: tilt %.1f deg, at rest after %.2f s",
                      obj.name, attempt, len(ordered), tilt, settle_s)
            return TurnOver(rest, down / np.linalg.norm(down), tilt, settle_s, drop, face, len(faces), attempt)
        landed.append(off)
        log.debug("%s put on face %d settled %.1f deg off it", obj.name, attempt, off)
    raise ReconError(f"the object '{obj.name}' settled on none of the {len(landed)} stable faces it was put on "
                     f"(it ended {', '.join(f'{a:.0f}' for a in landed)} deg off them, wanted at most "
                     f"{CONFIRM_DEG:g} deg)", hint="try another seed")


def simulate_resting(obj: SceneObject, seconds: float, surface_z: float | None = None) -> np.ndarray:
    """The pose (4, 4) of ``obj`` after ``seconds`` [s] of simulation from rest at its pose,
    on the plane ``surface_z`` [m] (default: its lowest world z): a stable pose barely moves."""
    surface = float(obj.world_vertices()[:, 2].min()) if surface_z is None else float(surface_z)
    sim = _Sim(obj, surface)
    return sim.run(obj.world_T_object, seconds)


# --------------------------------------------------------------------- the simulation
class _Sim:
    """One free body (the object, body frame = object frame) above a plane at ``surface_z``."""

    def __init__(self, obj: SceneObject, surface_z: float) -> None:
        self.model = _build_model(obj, surface_z)
        self.data = mujoco.MjData(self.model)

    def _start(self, world_T_object: np.ndarray) -> None:
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:3] = world_T_object[:3, 3]
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(world_T_object[:3, :3]).ravel())
        self.data.qpos[3:7] = quat

    def _pose(self) -> np.ndarray:
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, self.data.qpos[3:7])
        return pose(R.reshape(3, 3), self.data.qpos[:3])

    def run(self, world_T_object: np.ndarray, seconds: float) -> np.ndarray:
        self._start(world_T_object)
        mujoco.mj_step(self.model, self.data, nstep=round(seconds / TIMESTEP_S))
        return self._pose()

    def settle(self, world_T_object: np.ndarray, name: str) -> tuple[np.ndarray, float]:
        """Pose (4, 4) at rest and the simulated time [s] when the object came to rest: its
        speeds, sampled every ``REST_SAMPLE_S``, below ``REST_SPEED`` and ``REST_SPIN`` for
        ``REST_HOLD_S``."""
        self._start(world_T_object)
        m, d = self.model, self.data
        steps = round(REST_SAMPLE_S / TIMESTEP_S)
        last, quiet_since = self._pose(), None
        speed = spin = math.inf
        while d.time < TIMEOUT_S:
            mujoco.mj_step(m, d, nstep=steps)
            now = self._pose()
            move, turn = pose_error(last, now)
            last, speed, spin = now, move / REST_SAMPLE_S, turn / REST_SAMPLE_S
            if speed >= REST_SPEED or spin >= REST_SPIN:
                quiet_since = None
            elif quiet_since is None:
                quiet_since = float(d.time) - REST_SAMPLE_S
            elif d.time - quiet_since >= REST_HOLD_S - 1e-9:
                return now, quiet_since
        raise ReconError(f"the object '{name}' did not come to rest within {TIMEOUT_S:g} s of simulated time after it "
                         f"was turned over (still moving at {speed * 1e3:.2g} mm/s, {math.degrees(spin):.2g} deg/s)",
                         hint="try another seed")


def _build_model(obj: SceneObject, surface_z: float) -> mujoco.MjModel:
    spec = mujoco.MjSpec()
    spec.option.timestep = TIMESTEP_S
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.noslip_iterations = NOSLIP_ITERATIONS
    floor = spec.worldbody.add_geom()
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = [0.0, 0.0, 1.0]  # infinite
    floor.pos = [0.0, 0.0, surface_z]
    floor.friction = list(FRICTION)
    floor.condim = 3

    body = spec.worldbody.add_body()
    body.name = obj.name
    body.add_freejoint()
    mass, com, inertia = mass_properties(obj)
    body.explicitinertial = True
    body.mass = mass
    body.ipos = com.tolist()
    body.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
    for i, prim in enumerate(obj.primitives or (None,)):
        g = body.add_geom()
        g.friction = list(FRICTION)
        g.condim = 3
        if prim is not None and prim.kind != "torus":
            _primitive_geom(g, prim)
            continue
        # a mesh: the object's (no primitives) or the torus'; MuJoCo collides with its convex hull
        vertices = obj.vertices if prim is None else np.asarray(prim.mesh().vertices)
        mesh = spec.add_mesh()
        mesh.name = f"hull_{i}"
        mesh.uservert = _hull_vertices(vertices).astype(np.float32).ravel().tolist()
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX
        g.type = mujoco.mjtGeom.mjGEOM_MESH
        g.meshname = mesh.name
    try:
        return spec.compile()
    except ValueError as exc:
        reason = str(exc).strip().splitlines()[0].removeprefix("Error: ").strip()
        raise ReconError(f"the object '{obj.name}' cannot be turned over in simulation: MuJoCo refuses it ({reason})",
                         hint="give a closed surface of the object (a solid)") from None


def _primitive_geom(g: mujoco.MjsGeom, prim: Primitive) -> None:
    """MuJoCo's own geom for a box, cylinder or sphere (object frame = body frame)."""
    kinds = {"box": mujoco.mjtGeom.mjGEOM_BOX, "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
             "sphere": mujoco.mjtGeom.mjGEOM_SPHERE}
    g.type = kinds[prim.kind]
    if prim.kind == "box":
        g.size = [d / 2.0 for d in prim.dims]
    elif prim.kind == "cylinder":
        g.size = [prim.dims[0], prim.dims[1] / 2.0, 0.0]
    else:
        g.size = [prim.dims[0], 0.0, 0.0]
    if prim.kind != "box":
        g.condim = 6  # torsional and rolling friction: a round body stops rolling and spinning
    g.pos = prim.object_T_prim[:3, 3].tolist()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(prim.object_T_prim[:3, :3]).ravel())
    g.quat = quat.tolist()


def _hull_vertices(vertices: np.ndarray) -> np.ndarray:
    """The vertices (K, 3) of the convex hull of ``vertices`` (N, 3)."""
    from scipy.spatial import ConvexHull

    return vertices[ConvexHull(vertices).vertices]


# --------------------------------------------------------------------- mass properties
def mass_properties(obj: SceneObject, density: float = DENSITY) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass [kg], centre of mass (3,) [m] and inertia (3, 3) about it [kg m^2], object frame,
    of the object as a solid of uniform ``density`` [kg/m^3]: the union of its primitives
    (on a grid), else its mesh when that is closed, else its mesh's convex hull."""
    volume, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
    if obj.primitives:
        volume, first, second = _union_moments(obj.primitives, obj.vertices)
    elif _closed(obj.vertices, obj.triangles):
        volume, first, second = _mesh_moments(obj.vertices, obj.triangles)
    if volume <= 0.0:  # an open or inside-out mesh
        volume, first, second = _mesh_moments(*_hull(obj.vertices))
    com = first / volume
    C = density * (second - volume * np.outer(com, com))  # mass-weighted covariance about the com
    return density * volume, com, np.trace(C) * np.eye(3) - C


def _mesh_moments(vertices: np.ndarray, triangles: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, first moment (3,) and second moment (3, 3) (integral of x x^T) of the solid a
    closed, outward-oriented triangle mesh bounds (signed tetrahedra from the origin)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))  # (M, 3) each
    v = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0  # (M,)
    s = a + b + c
    first = (v[:, None] * s).sum(axis=0) / 4.0
    second = sum(np.einsum("i,ij,ik->jk", v, x, x) for x in (a, b, c, s))
    return float(v.sum()), first, np.asarray(second) / 20.0


def _closed(vertices: np.ndarray, triangles: np.ndarray) -> bool:
    """Every edge of the mesh (vertices merged by position) has its reverse: a closed,
    consistently oriented surface."""
    _, index = np.unique(np.round(vertices, 7), axis=0, return_inverse=True)
    t = index.ravel()[triangles]
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    n = int(t.max()) + 1
    forward = np.unique(edges[:, 0] * n + edges[:, 1])
    backward = np.unique(edges[:, 1] * n + edges[:, 0])
    return len(forward) == len(edges) and np.array_equal(forward, backward)


def _hull(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of ``vertices`` as outward-oriented triangles."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(vertices)
    tri = hull.simplices.copy()
    p = vertices[tri]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    inward = np.einsum("ij,ij->i", normal, hull.equations[:, :3]) < 0.0
    tri[inward] = tri[inward][:, ::-1]
    return vertices, tri


def _union_moments(primitives: tuple[Primitive, ...], vertices: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume, first and second moment of the union of primitives, summed over the cells of a
    grid over the vertices' bounding box (a cell counts when its centre is inside)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    h = float((hi - lo).max()) / _GRID
    n = np.ceil((hi - lo) / h).astype(int)
    axes = [(lo[k] + hi[k]) / 2.0 + (np.arange(n[k]) - (n[k] - 1) / 2.0) * h for k in range(3)]  # centred
    p = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = np.zeros(len(p), dtype=bool)
    for prim in primitives:
        inside |= prim.contains(p, eps=0.0)
    p = p[inside]
    cell = h**3
    second = cell * (p.T @ p) + len(p) * cell * (h**2 / 12.0) * np.eye(3)  # plus each cell's own spread
    return len(p) * cell, cell * p.sum(axis=0), second
