"""Turning an object over between the two sides of a two-sided scan, by physics.

An operator turns the object over and puts it back on its spot; in simulation MuJoCo does
the turning: the object is tipped by about 90 deg about a random horizontal axis through
its bounding-box centre (onto a flank: its old resting face then faces sideways and is
seen, and the two sides share its top and a flank, whose shape fixes their registration;
turned upside down instead, a box's sides would share only flat flanks, along which they
can slide), given a random yaw, dropped from a few mm onto a plane at the surface it stands
on, and simulated until it lies still. Where it comes to rest is a stable pose that
physics chose, not one picked by hand. It is then moved in x, y so
that its world bounding-box centre is where it was (the operator puts it back on the spot),
keeping the settled height and orientation.

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
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import pose, pose_error, rot_z, transform_points
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
FLIP_DEG = (75.0, 105.0)
"""Range of the turning angle about the horizontal axis [deg]."""
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
"""A turn that tilts the object's up axis by less than this [deg] left the same face down."""
MAX_ATTEMPTS = 8
"""Draws tried before an object that always falls back onto the same face is an error."""
_GRID = 64  # cells along the longest side when integrating a union of primitives


@dataclass(frozen=True)
class TurnOver:
    """Where an object came to rest after it was turned over."""

    world_T_object: np.ndarray  # (4, 4) the new resting pose, object frame -> world
    down_object: np.ndarray  # (3,) unit vector in the object frame that now points down (-z world)
    tilt_deg: float  # angle between the old and the new object "up" axis [deg]
    settle_s: float  # simulated seconds until at rest [s]
    dropped_from: float  # height of the drop above the rest surface [m]


def turned(obj: SceneObject, t: TurnOver) -> SceneObject:
    """A copy of ``obj`` at the resting pose of ``t``."""
    return replace(obj, world_T_object=t.world_T_object.copy())


def turn_over(obj: SceneObject, rng: np.random.Generator, surface_z: float | None = None) -> TurnOver:
    """Turn ``obj`` over onto another face and let it settle on the plane ``surface_z`` [m]
    (default: the lowest world z of its vertices, the surface it rests on now).

    Each draw tips it by 75-105 deg about a random horizontal axis through its bounding-box
    centre, with a random yaw, and drops it from 2-5 mm. An object can fall back onto the face
    it stood on (a tilt of the up axis below :data:`MIN_TILT_DEG`); then the next draw of
    ``rng`` is tried, :data:`MAX_ATTEMPTS` at most, after which a ReconError is raised. A
    ReconError too when it is still moving after :data:`TIMEOUT_S` of simulated time.
    """
    old = obj.world_T_object
    surface = float(obj.world_vertices()[:, 2].min()) if surface_z is None else float(surface_z)
    up_object = old[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # the object axis that points up now
    lo, hi = obj.world_aabb()
    centre = (lo + hi) / 2.0
    sim = _Sim(obj, surface)
    tilts = []
    for attempt in range(1, MAX_ATTEMPTS + 1):
        axis_angle = rng.uniform(0.0, 2.0 * math.pi)
        flip = math.radians(rng.uniform(*FLIP_DEG))
        yaw = rng.uniform(0.0, 2.0 * math.pi)
        drop = float(rng.uniform(*DROP_M))
        axis = np.array([math.cos(axis_angle), math.sin(axis_angle), 0.0])
        turn = rot_z(yaw) @ _axis_angle(axis, flip)  # world frame, about the bounding-box centre
        start = pose(turn @ old[:3, :3], centre + turn @ (old[:3, 3] - centre))
        start[2, 3] += surface + drop - float(transform_points(start, obj.vertices)[:, 2].min())
        rest, settle_s = sim.settle(start, obj.name)
        tilt = math.degrees(math.acos(float(np.clip((rest[:3, :3] @ up_object)[2], -1.0, 1.0))))
        if tilt > MIN_TILT_DEG:
            v = transform_points(rest, obj.vertices)
            rest[:2, 3] += centre[:2] - (v.min(axis=0)[:2] + v.max(axis=0)[:2]) / 2.0  # back on the spot
            down = rest[:3, :3].T @ np.array([0.0, 0.0, -1.0])
            log.debug("%s turned over in attempt %d: tilt %.1f deg, at rest after %.2f s",
                      obj.name, attempt, tilt, settle_s)
            return TurnOver(rest, down / np.linalg.norm(down), tilt, settle_s, drop)
        tilts.append(tilt)
        log.debug("%s fell back onto the same face (tilt %.1f deg), attempt %d", obj.name, tilt, attempt)
    raise ReconError(f"the object '{obj.name}' fell back onto the face it stood on in all {MAX_ATTEMPTS} turns "
                     f"(tilts {', '.join(f'{t:.0f}' for t in tilts)} deg, wanted more than {MIN_TILT_DEG:g} deg)",
                     hint="try another seed")


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


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation (3, 3) by ``angle`` [rad] about the unit ``axis`` (Rodrigues)."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


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
