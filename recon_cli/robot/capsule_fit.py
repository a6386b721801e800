"""Capsules fitted to the collision meshes of a robot description.

recon's collision model (:mod:`recon_cli.robot.collision`) reads only primitives: boxes,
cylinders, spheres and capsules. A capsule is written the way ``geom_capsule`` in
robot/parts/shapes.xacro writes it: a ``<collision name="X_capsule">`` cylinder between the
two segment ends (origin at the midpoint, rpy turning local z onto the segment, length the
segment length) and two end spheres ``X_capsule_end_a`` / ``X_capsule_end_b``, all with the
radius inflated by the safety distance. Most robot vendors' URDFs (Franka, UR, xArm, ...)
give collision meshes instead; :func:`fit_mesh_collisions` replaces every link's mesh
``<collision>`` elements by one capsule that contains every vertex of them, named
``LINK_fit_capsule`` (with ``LINK_fit_capsule_end_a/b``) and inflated by the safety
distance. The link's primitive collisions stay as they are.

Reading. Mesh files are read by recon's one guarded mesh reader
(:func:`recon_cli.inputs.meshes.read_mesh`: PLY, OBJ, STL with size limits). A Collada
(.dae) or other collision mesh is refused with one line naming the link and the file (fix:
convert it to STL or OBJ, or give the link primitive shapes). Where a mesh file is looked
for:

- ``package://PKG/REST``: from the description file's folder upwards, the first folder
  that is named PKG, or holds a folder named PKG, gives PKG/REST (no ROS package index is
  asked);
- ``file:///abs/path`` and an absolute path: as written; ``file://rel/path`` and a
  relative path: relative to the description file's folder.

A cell's meshes must lie inside the cell file's folder or recon's robot/ folder (links
resolved; absolute paths refused), checked before any mesh is read.

A mesh's ``scale`` (one or three factors) and the ``<collision>``'s origin (xyz, rpy) place
its vertices in the link frame.

Fitting (:func:`fit_capsule`): a capsule is convex, so it contains a point set exactly when
it contains the set's convex hull vertices; the fit runs on those (scipy's qhull; a mesh of
more than :data:`PREFILTER_POINTS` vertices is first cut down to its extreme vertices in
:data:`DIRECTIONS` fixed directions, which are hull vertices too, since qhull takes most of
a second for 50 000 vertices on a sphere; the line is optimised on at most that many hull
vertices, the segment and radius are then computed from all of them). For a fixed axis line the best segment is found
in one dimension: with a point's axial coordinate s_i and distance rho_i from the line, a
radius r >= max rho_i needs the segment [a, b] with a = min(s_i + w_i), b = max(s_i - w_i),
w_i = sqrt(r^2 - rho_i^2); the volume pi r^2 (b - a) + 4/3 pi r^3 is minimised over r on a
refined grid. The line (direction and offset, four numbers) is optimised by Nelder-Mead,
starting from the principal axes of the hull vertices (PCA; the axes whose start is within
:data:`START_RATIO` of the best are tried). The result is near-minimal, not proven minimal.
Containment is exact: the radius returned is the largest distance of every input vertex to
the final segment plus :data:`CONTAINMENT_MARGIN`. Everything is deterministic (no random
numbers). Degenerate input (one point, points on a line or in a plane) gives a valid
capsule: a segment of at least :data:`MIN_SEGMENT` length and a radius that may be tiny.

Visuals. MuJoCo would need the mesh files of ``<visual>`` elements too (and cannot read
``package://`` paths), so every mesh ``<visual>`` is dropped; a link with a fitted capsule
gets the capsule's visual pieces instead (cylinder and two end spheres at the real size,
not inflated, named ``LINK_fit_capsule_visual``, ``..._end_a_visual``, ``..._end_b_visual``,
with the material of the first mesh visual). A link with mesh visuals but no collision
meshes keeps its other visuals only: the simulated camera sees no geometry of its meshes.
Visual mesh files are never read (a Collada visual is fine).

Rewrites are cached per process, keyed by the URDF text, its folder, the safety distance
and the version (modification time, size) of the collision mesh files. A mesh file's size is
checked from its stat before anything reads it; only the guarded reader reads it.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import numpy as np
import numpy.typing as npt
from lxml import etree

from recon_cli.errors import FileError, InputError, ScriptError
from recon_cli.expansion.readable import ReadRule, readable
from recon_cli.geometry.transforms import pose_from_xyz_rpy, transform_points
from recon_cli.inputs.files import version_stamp
from recon_cli.inputs.meshes import MESH_SUFFIXES, check_mesh_file, read_mesh

Array = npt.NDArray[np.float64]

#: added to the largest vertex distance, so that rounding never puts a vertex outside [m]
CONTAINMENT_MARGIN = 1e-9
#: shortest segment written (a sphere-like link): MuJoCo and coal take no zero-length cylinder [m]
MIN_SEGMENT = 1e-6
#: above this many vertices, only the extreme vertices in DIRECTIONS directions go to qhull
PREFILTER_POINTS = 4000
#: fixed directions (a Fibonacci sphere) of the pre-filter
DIRECTIONS = 512
#: principal axes whose start volume is within this factor of the best start are optimised
START_RATIO = 1.5
#: Nelder-Mead's budget of objective evaluations per start
MAX_EVALUATIONS = 600
_SUFFIX = "_fit_capsule"
_MESH_HINT = "repair or simplify the mesh, or give the link primitive <collision> shapes"
_DAE_HINT = ("convert it to STL or OBJ (e.g. with MeshLab or Blender), or give the link primitive "
             "<collision> shapes (box, cylinder, sphere)")


@dataclass(frozen=True)
class FittedCapsule:
    """A capsule fitted to one link's collision meshes, in the link frame [m].

    p1, p2: the segment's ends; radius: before the safety distance is added.
    """

    link: str
    p1: tuple[float, float, float]
    p2: tuple[float, float, float]
    radius: float

    @property
    def length(self) -> float:
        """Segment length [m]."""
        return math.dist(self.p1, self.p2)

    @property
    def volume(self) -> float:
        """[m^3] before inflation."""
        return math.pi * self.radius**2 * self.length + 4.0 / 3.0 * math.pi * self.radius**3


@dataclass(frozen=True)
class MeshFit:
    """A URDF with its meshes replaced, and the capsules fitted (empty: it had no collision meshes)."""

    urdf: str
    capsules: tuple[FittedCapsule, ...]


# ----------------------------------------------------------------------------- the fit
def _fibonacci_sphere(n: int) -> Array:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    a = math.pi * (1.0 + math.sqrt(5.0)) * i
    return np.column_stack([r * np.cos(a), r * np.sin(a), z])


def _extreme_points(points: Array) -> Array:
    """The vertices extreme in :data:`DIRECTIONS` fixed directions (each a hull vertex)."""
    directions = _fibonacci_sphere(DIRECTIONS).astype(np.float32)  # a choice of candidates: single precision will do
    best = np.full(DIRECTIONS, -np.inf)
    index = np.zeros(DIRECTIONS, dtype=np.intp)
    centred = (points - points.mean(axis=0)).astype(np.float32)
    rows = np.arange(DIRECTIONS)
    for start in range(0, len(points), 8192):
        proj = directions @ centred[start:start + 8192].T  # (directions, points): argmax along rows
        k = np.argmax(proj, axis=1)
        value = proj[rows, k]
        better = value > best
        best[better], index[better] = value[better], k[better] + start
    return points[np.unique(index)]


def _principal_axes(points: Array) -> tuple[Array, Array]:
    """(rows: the principal axes, largest spread first; extents of the points along them)."""
    _, _, vt = np.linalg.svd(points - points.mean(axis=0), full_matrices=False)
    axes = np.zeros((3, 3))
    axes[: len(vt)] = vt
    if len(vt) < 3:  # fewer than three points: complete the frame
        axes = np.linalg.qr(np.column_stack([axes[: len(vt)].T, np.eye(3)]))[0][:, :3].T
    proj = (points - points.mean(axis=0)) @ axes.T
    return axes, np.ptp(proj, axis=0)


def _hull_vertices(points: Array) -> Array:
    """The convex hull's vertices of the points (or of their plane or line when flat)."""
    from scipy.spatial import ConvexHull, QhullError

    candidates = _extreme_points(points) if len(points) > PREFILTER_POINTS else points
    axes, extent = _principal_axes(candidates)
    tol = 1e-9 * max(float(extent.max()), 1e-300)
    rank = int(np.count_nonzero(extent > tol))
    proj = (candidates - candidates.mean(axis=0)) @ axes.T
    index: npt.NDArray[np.intp] | None = None
    for dims in (3, 2):  # a flat hull (qhull refuses it) in its plane
        if rank >= dims and index is None:
            try:
                index = np.asarray(ConvexHull(proj[:, :dims]).vertices, dtype=np.intp)
            except QhullError:
                index = None
    if index is None:  # a point or a line: its two extremes
        index = np.unique([np.argmin(proj[:, 0]), np.argmax(proj[:, 0])])
    hull: Array = candidates[index]
    return hull


def _segment_on_line(points: Array, centre: Array, direction: Array,
                     stages: int = 2) -> tuple[float, float, float, float]:
    """The smallest-volume capsule with its segment on the line ``centre + t direction``:
    (t of end a, t of end b, radius, volume). The radius is searched on a grid refined
    ``stages`` times between the points' largest distance from the line and the radius of
    a sphere around the middle of their extent."""
    q = points - centre
    s = q @ direction
    rho2 = np.maximum(np.einsum("ij,ij->i", q, q) - s * s, 0.0)
    middle = (float(s.min()) + float(s.max())) / 2.0
    lo = math.sqrt(float(rho2.max()))
    hi = math.sqrt(float((rho2 + (s - middle) ** 2).max()))
    radii = np.array([hi])
    for _ in range(stages if hi > lo else 0):
        radii = np.linspace(lo, hi, 17)
        w = np.sqrt(np.maximum(radii[:, None] ** 2 - rho2[None, :], 0.0))
        length = np.maximum((s[None, :] - w).max(axis=1) - (s[None, :] + w).min(axis=1), 0.0)
        volume = math.pi * radii**2 * length + 4.0 / 3.0 * math.pi * radii**3
        k = int(np.argmin(volume))
        lo, hi = float(radii[max(k - 1, 0)]), float(radii[min(k + 1, 16)])
        radii = radii[k:k + 1]
    r = float(radii[0])
    w = np.sqrt(np.maximum(r * r - rho2, 0.0))
    a, b = float((s + w).min()), float((s - w).max())
    if b < a:  # a sphere of radius r holds them all: one point of [b, a] is the segment
        a = b = (a + b) / 2.0
    return a, b, r, math.pi * r * r * (b - a) + 4.0 / 3.0 * math.pi * r**3


def _line_of(x: Array, start: int, axes: Array, centre: Array, scale: float) -> tuple[Array, Array]:
    """(point, unit direction) of the line: the principal axis ``start`` tilted by x[0:2]
    towards the other two, moved by scale * x[2:4] along them."""
    d0, e1, e2 = axes[start], axes[(start + 1) % 3], axes[(start + 2) % 3]
    d = d0 + x[0] * e1 + x[1] * e2
    return centre + scale * (x[2] * e1 + x[3] * e2), d / np.linalg.norm(d)


def _best_line(hull: Array) -> tuple[Array, Array]:
    """The axis line of a near-minimal capsule around the hull vertices (Nelder-Mead from
    the promising principal axes)."""
    from scipy.optimize import minimize

    axes, extent = _principal_axes(hull)
    centre = hull.mean(axis=0) + axes.T @ (((hull - hull.mean(axis=0)) @ axes.T).min(axis=0) + extent / 2.0)
    scale = max(float(np.linalg.norm(extent)), 1e-12)

    def objective(start: int) -> Callable[[Array], float]:
        return lambda x: _segment_on_line(hull, *_line_of(x, start, axes, centre, scale))[3]

    x0 = np.zeros(4)
    starts = [objective(k)(x0) for k in range(3)]
    best: tuple[float, int, Array] = (math.inf, 0, x0)
    for k in range(3):
        if starts[k] > START_RATIO * min(starts):
            continue
        simplex = np.vstack([x0, 0.1 * np.eye(4)])
        result = minimize(objective(k), x0, method="Nelder-Mead",
                          options={"initial_simplex": simplex, "xatol": 1e-4, "maxfev": MAX_EVALUATIONS,
                                   "fatol": 1e-6 * max(starts[k], 1e-300)})
        if float(result.fun) < best[0]:
            best = (float(result.fun), k, np.asarray(result.x, dtype=np.float64))
    return _line_of(best[2], best[1], axes, centre, scale)


def _distance_to_segment(points: Array, p1: Array, p2: Array) -> Array:
    d = p2 - p1
    t = np.clip((points - p1) @ d / max(float(d @ d), 1e-300), 0.0, 1.0)
    closest: Array = p1 + t[:, None] * d
    distance: Array = np.linalg.norm(points - closest, axis=1)
    return distance


def fit_capsule(points: npt.ArrayLike) -> tuple[Array, Array, float]:
    """A near-minimal capsule containing every point: (segment end a, end b, radius) [m].

    ``points``: (N, 3), N >= 1, finite. See the module docstring for the method.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(pts) or not np.isfinite(pts).all():
        raise ValueError("a capsule is fitted to at least one point, all finite")
    hull = _hull_vertices(pts)
    if len(hull) <= 2:  # a point or a line: the segment between the extremes
        p1, p2 = hull[0], hull[-1]
    else:  # the line optimised on at most DIRECTIONS hull vertices, the segment on all of them
        centre, direction = _best_line(_extreme_points(hull) if len(hull) > DIRECTIONS else hull)
        a, b, _, _ = _segment_on_line(hull, centre, direction, stages=3)
        p1, p2 = centre + a * direction, centre + b * direction
    p1, p2 = _at_least(p1, p2, MIN_SEGMENT)
    radius = float(_distance_to_segment(pts, p1, p2).max()) + CONTAINMENT_MARGIN
    return p1, p2, radius


def _at_least(p1: Array, p2: Array, length: float) -> tuple[Array, Array]:
    """The segment lengthened symmetrically to ``length`` if shorter (along z if a point)."""
    d = p2 - p1
    n = float(np.linalg.norm(d))
    if n >= length:
        return p1, p2
    u = d / n if n > 0.0 else np.array([0.0, 0.0, 1.0])
    mid = (p1 + p2) / 2.0
    return mid - u * length / 2.0, mid + u * length / 2.0


# ----------------------------------------------------------------------------- mesh files
@dataclass(frozen=True)
class _MeshRef:
    """One mesh ``<collision>`` of a link: its file and how its vertices go into the link frame."""

    link: str
    uri: str
    path: Path
    scale: tuple[float, float, float]
    link_T_mesh: Array


def _floats(text: str | None, default: str, count: Sequence[int], what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in (text if text is not None else default).split())
    except ValueError:
        values = ()
    if len(values) not in count or not all(math.isfinite(v) for v in values):
        raise InputError(f"{what} '{text}' is not {' or '.join(map(str, count))} finite numbers",
                         hint="write it as in URDF, e.g. xyz=\"0 0 0.1\"")
    return values


def resolve_mesh(uri: str, description: Path, where: str = "", rule: ReadRule | None = None) -> Path:
    """The file of a mesh ``filename`` (rules in the module docstring); an InputError
    (message prefixed by ``where``) when no package:// folder is found. With a read ``rule``
    (a cell file's), the file must lie inside its folders (links resolved), an absolute path
    is refused and package:// is searched only inside them, before anything is read."""
    folder = description.parent
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        for above in (folder, *folder.parents):
            if rule is not None and not any(above.resolve().is_relative_to(r) for r in rule.roots):
                break
            if above.name == package:
                return _inside(above / unquote(rest), uri, where, rule)
            if (above / package).is_dir():
                return _inside(above / package / unquote(rest), uri, where, rule)
        inside = f" inside {rule.places}" if rule is not None else ""
        raise InputError(f"{where}no folder named '{package}' at or above {folder}{inside} for the mesh {uri}",
                         hint=f"put the robot's package folder '{package}' beside or above the description file, "
                              "or write the mesh paths relative to it")
    if uri.startswith("file://"):
        uri = unquote(uri[len("file://"):])
    elif "://" in uri:
        raise InputError(f"{where}the mesh {uri} is neither a package://, a file:// nor a file path",
                         hint="give a path relative to the description file")
    if rule is not None:
        try:
            return readable(uri, rule, None, f"the mesh {uri}", beside=folder)
        except ScriptError as exc:
            if "does not exist" in exc.message:
                return folder / uri  # named as missing by the caller
            raise InputError(f"{where}{exc.message}", hint=exc.hint) from None
    path = Path(uri).expanduser()
    return path if path.is_absolute() else folder / path


def _inside(path: Path, uri: str, where: str, rule: ReadRule | None) -> Path:
    if rule is None:
        return path
    try:
        real = path.resolve()
    except (OSError, RuntimeError, ValueError):
        real = path
    if not any(real.is_relative_to(r) for r in rule.roots):
        raise InputError(f"{where}the mesh {uri} leads outside {rule.places}", hint=rule.hint)
    return real


def _mesh_refs(root: etree._Element, description: Path, rule: ReadRule | None = None) -> list[_MeshRef]:
    """Every mesh ``<collision>`` of the URDF, its file resolved and checked to exist."""
    refs = []
    where = str(description)
    for link in root.findall("link"):
        name = str(link.get("name"))
        for col in link.findall("collision"):
            mesh = col.find("geometry/mesh")
            if mesh is None:
                continue
            uri = mesh.get("filename")
            if not uri:
                raise InputError(f"{where}: link '{name}': a collision <mesh> without a filename",
                                 hint="give filename=\"...\" or a primitive shape")
            suffix = Path(uri).suffix.lower()
            if suffix not in MESH_SUFFIXES:
                kind = {".dae": "a Collada (.dae) file", "": "a file without a type"}.get(suffix, f"a {suffix} file")
                raise InputError(f"{where}: link '{name}': collision mesh {uri} is {kind}, which recon does not "
                                 "read (it reads STL, OBJ, PLY)", hint=_DAE_HINT)
            path = resolve_mesh(uri, description, f"{where}: link '{name}': ", rule)
            if not path.is_file():
                raise InputError(f"{where}: link '{name}': collision mesh {uri} does not exist ({path})",
                                 hint="put the mesh file there (package:// is searched from the description's "
                                      "folder upwards, other paths are relative to it) or fix the filename")
            try:  # its size from its stat, before anything reads it (the cache key, the reader)
                check_mesh_file(path, f"collision mesh of link '{name}'", _MESH_HINT)
            except FileError as exc:
                raise FileError(f"{exc.message} (filename {uri})", hint=exc.hint) from None
            scale = _floats(mesh.get("scale"), "1 1 1", (1, 3), f"{where}: link '{name}': mesh scale")
            origin = col.find("origin")
            xyz = _floats(None if origin is None else origin.get("xyz"), "0 0 0", (3,), f"{where}: link '{name}': xyz")
            rpy = _floats(None if origin is None else origin.get("rpy"), "0 0 0", (3,), f"{where}: link '{name}': rpy")
            sx, sy, sz = scale * 3 if len(scale) == 1 else scale
            refs.append(_MeshRef(name, uri, path, (sx, sy, sz), pose_from_xyz_rpy(xyz, rpy)))
    return refs


def _link_vertices(ref: _MeshRef) -> Array:
    """The vertices of one collision mesh in its link frame."""
    factor = max(abs(v) for v in ref.scale) or 1.0
    try:
        mesh = read_mesh(ref.path, f"collision mesh of link '{ref.link}'", scale=factor, hint=_MESH_HINT)
    except FileError as exc:
        raise FileError(f"{exc.message} (filename {ref.uri})", hint=exc.hint) from None
    vertices = np.asarray(mesh.vertices, dtype=np.float64) * np.asarray(ref.scale)
    return transform_points(ref.link_T_mesh, vertices)


def _digest(refs: list[_MeshRef]) -> str:
    """The cache key of the meshes: their names and versions (modification time, size), read
    from their stat (a mesh is read only by the guarded reader)."""
    h = hashlib.sha256()
    for ref in refs:
        h.update(f"{ref.link}\0{ref.path}\0{version_stamp(ref.path)}\0".encode())
    return h.hexdigest()


# ----------------------------------------------------------------------------- the rewrite
def _fmt(values: Sequence[float]) -> str:
    return " ".join(repr(float(v)) for v in values)


def _piece(tag: str, name: str, xyz: Sequence[float], rpy: Sequence[float], shape: str,
           size: dict[str, float]) -> etree._Element:
    element = etree.Element(tag, name=name)
    etree.SubElement(element, "origin", xyz=_fmt(xyz), rpy=_fmt(rpy))
    etree.SubElement(etree.SubElement(element, "geometry"), shape, {k: repr(float(v)) for k, v in size.items()})
    return element


def capsule_elements(capsule: FittedCapsule, tag: str, inflate: float = 0.0) -> list[etree._Element]:
    """The three pieces of a capsule as ``geom_capsule`` in robot/parts/shapes.xacro writes
    them: the cylinder ``LINK_fit_capsule`` (midpoint, rpy = (roll, 0, yaw) turning local z
    onto p2 - p1, the segment length) and the end spheres ``..._end_a``, ``..._end_b``, with
    the radius + ``inflate``; ``tag``: "collision" or "visual" (names end in ``_visual``)."""
    p1, p2 = np.asarray(capsule.p1), np.asarray(capsule.p2)
    dx, dy, dz = (p2 - p1).tolist()
    dh = math.hypot(dx, dy)
    roll, yaw = math.atan2(dh, dz), (math.atan2(dx, -dy) if dh > 1e-12 else 0.0)
    r = capsule.radius + inflate
    end = "_visual" if tag == "visual" else ""
    name = f"{capsule.link}{_SUFFIX}"
    mid = ((p1 + p2) / 2.0).tolist()
    return [_piece(tag, f"{name}{end}", mid, (roll, 0.0, yaw), "cylinder", {"radius": r, "length": capsule.length}),
            _piece(tag, f"{name}_end_a{end}", capsule.p1, (0.0, 0.0, 0.0), "sphere", {"radius": r}),
            _piece(tag, f"{name}_end_b{end}", capsule.p2, (0.0, 0.0, 0.0), "sphere", {"radius": r})]


def _replace(link: etree._Element, tag: str, new: list[etree._Element]) -> None:
    """Replace the link's ``tag`` elements with mesh geometry by ``new`` (at the first one's place)."""
    old = [e for e in link.findall(tag) if e.find("geometry/mesh") is not None]
    if not old:
        return
    at = link.index(old[0])
    material = old[0].find("material") if tag == "visual" else None
    if material is not None:
        for piece in new:
            piece.append(copy.deepcopy(material))
    for element in old:
        link.remove(element)
    for i, piece in enumerate(new):
        link.insert(at + i, piece)


def _fit_links(refs: list[_MeshRef]) -> tuple[FittedCapsule, ...]:
    by_link: dict[str, list[Array]] = {}
    for ref in refs:
        by_link.setdefault(ref.link, []).append(_link_vertices(ref))
    capsules = []
    for link, parts in by_link.items():
        p1, p2, radius = fit_capsule(np.vstack(parts))
        (x1, y1, z1), (x2, y2, z2) = p1.tolist(), p2.tolist()
        capsules.append(FittedCapsule(link, (x1, y1, z1), (x2, y2, z2), radius))
    return tuple(capsules)


@functools.lru_cache(maxsize=16)
def _rewrite(urdf: str, description: str, safety_distance: float, digest: str) -> MeshFit:
    root = etree.fromstring(urdf.encode())
    capsules = _fit_links(_mesh_refs(root, Path(description)))
    fitted = {c.link: c for c in capsules}
    for link in root.findall("link"):
        capsule = fitted.get(str(link.get("name")))
        _replace(link, "collision", capsule_elements(capsule, "collision", safety_distance) if capsule else [])
        _replace(link, "visual", capsule_elements(capsule, "visual") if capsule else [])
    etree.indent(root, space="  ")
    return MeshFit('<?xml version="1.0"?>\n' + etree.tostring(root, encoding="unicode"), capsules)


def has_meshes(urdf: str) -> bool:
    """Whether the URDF has a ``<mesh>`` in a collision or visual geometry."""
    if "mesh" not in urdf:
        return False
    root = etree.fromstring(urdf.encode())
    return any(True for _ in root.iterfind("link/*/geometry/mesh"))


def fit_mesh_collisions(urdf: str, description: Path | str, safety_distance: float,
                        rule: ReadRule | None = None) -> MeshFit:
    """The URDF with every link's collision meshes replaced by one fitted capsule inflated by
    ``safety_distance`` [m], and its mesh visuals by the capsule at real size (module
    docstring); unchanged when it has no meshes. ``description``: the URDF or xacro file the
    text came from (mesh paths are relative to its folder); ``rule``: the folders the meshes
    must lie in (a cell file's, :func:`~recon_cli.expansion.readable.cell_rule`). Refusals are
    one line naming the link and the file."""
    if not has_meshes(urdf):
        return MeshFit(urdf, ())
    path = Path(description).resolve()
    refs = _mesh_refs(etree.fromstring(urdf.encode()), path, rule)
    return _rewrite(urdf, str(path), float(safety_distance), _digest(refs))
