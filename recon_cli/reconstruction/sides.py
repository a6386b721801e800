"""Two-sided scanning: the partial models of an object's two sides registered by shape.

The object is scanned resting on the table (side 1), turned over and scanned again (side 2).
Within a side the board and the robot register the scans; between the sides only the shape
can. Each side's partial model is a cloud in the world frame, cropped to the object, and
misses what faced the table and what lies near it; the sides overlap where both saw the
object (mostly its flanks).

Open3D registers: both clouds down-sampled (their normals averaged, or estimated and turned
away from the centroid), FPFH features on the registration voxel and on twice it, global
registration on each (RANSAC on feature matches from several seeds, and fast global
registration), and every hypothesis refined by point-to-plane ICP with a Tukey kernel as
wide as the correspondence distance (partial overlap: points without a partner weigh
nothing) at decreasing distances, on a sparse copy (2 voxels) first and, for the best ones,
on a fine copy (half a voxel). Open3D runs on one thread here, so that the seed fixes the
result to the last digit.

Written here: more hypotheses, the ranking, the symmetry analysis and the confidence.

- Hypotheses: besides the features', the 4 poses that put side 2's principal axes and
  bounding-box centre onto side 1's (features fail where the sides share little: a flat
  object turned over shows its other face), and the best one turned about the merged
  model's principal axes by multiples of 360 deg / ``symmetry_steps`` (a box's or a mug's
  180 deg turns).
- Overlap and fit: a side-2 point, mapped onto side 1, is in the overlap when side 1's
  cameras (above the table, whose normal is ``up``) could have seen it: higher than side
  1's lowest points by ``overlap_margin`` and not facing down (``facing_down``). Lower than
  those points by more than ``support_band`` it would lie under side 1's table: impossible,
  a miss. Its partner is the nearest side-1 point within ``inlier_distance`` whose normal is
  within ``normal_angle`` of its own. ``fitness``: the share of side 2's overlap (and
  impossible) points with a partner; ``fitness_reverse`` the same from side 1 onto side 2;
  ``rmse``: of the partners' distances to each other's tangent plane, both ways. Poses
  rank by a truncated least-squares cost of both ways (:func:`_score`).
- Alternatives: poses more than ``angle_tol`` or ``distance_tol`` apart (the distance at
  side 2's centroid) are distinct; a distinct pose whose mean fitness and RMSE are within
  ``score_tol`` and ``rmse_tol`` of the lowest-cost one's fits equally well. Of those, the
  one whose merged model covers most (the smallest overlap) is reported: a turned-over
  object's sides complement each other, and a box turned by 180 deg would leave its
  bottom unseen. The reported pose's point-to-plane information (6 x 6, turns scaled by the
  overlap's radius) shows the motions its overlap hardly fixes (eigenvalues below
  ``weak_ratio`` of the largest: a body of revolution turned about its axis, a prism
  shifted along its flanks); side 2 moved along each by 1 and 3 ``weak_step`` both ways,
  scored where it lands (ICP would pull it back to where the edges of the overlap touch),
  gives more. The others that fit equally well are the ``alternatives``: the shape cannot
  fix the pose (``ambiguous``).
- Shape: an alternative changes the merged shape when side 2's points under it lie off the
  model merged under the reported pose, or the other way round (``shape_difference``,
  :func:`_shape_difference`), by more than ``shape_tol`` times the RMSE (the noise; at least
  a quarter voxel): then
  ``shape_ambiguous``. A body of revolution turned about its axis, or a box turned by 180
  deg, is ambiguous in pose but not in shape: the merged model is right although the pose
  is not unique. A prism is ambiguous in shape: what both sides missed near the table
  leaves its height open.
- Trust: ``reason`` says in words why the result is not to be trusted (no pose reaches
  ``min_fitness`` both ways, too little overlap, alternatives of another shape); None when
  it is.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.errors import InputError
from recon_cli.geometry.transforms import axis_angle, invert, pose, rotation_angle, rotation_between, transform_points
from recon_cli.randomness import open3d_draws

if TYPE_CHECKING:
    import open3d as o3d
    from scipy.spatial import cKDTree

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SidesOptions:
    """Knobs of :func:`register_sides`. Lengths given in voxels are multiples of the
    registration voxel."""

    ransac_runs: int = 3  # RANSAC runs on FPFH matches (their seeds drawn from the caller's seed)
    ransac_iterations: int = 2_000  # per run, on one thread
    symmetry_steps: int = 4  # probes at multiples of 360 deg / steps about each principal axis
    weak_ratio: float = 0.1  # information eigenvalue / largest below this: a motion the overlap may not fix
    weak_step: float = 1.0  # [voxels] probes moved 1 and 3 times this far (at the overlap's radius) along it
    max_alternatives: int = 6  # at most this many refined on the fine clouds, and reported
    inlier_distance: float = 1.0  # [voxels] a point with a partner this close is an inlier
    overlap_margin: float = 2.0  # [voxels] above the other side's lowest points: in the overlap
    support_band: float = 0.01  # [m] below the other side's lowest points by more: under its table
    facing_down: float = -0.85  # normal . up below this: cameras above the table cannot see it
    normal_angle: float = math.radians(45.0)  # [rad] partners' normals farther apart: no partners
    min_fitness: float = 0.4  # both ways; below it the pose is not trusted
    min_overlap: float = 0.15  # share of each side in the overlap; below it the pose is not trusted
    angle_tol: float = math.radians(1.0)  # [rad] poses farther apart are distinct
    distance_tol: float = 0.001  # [m] at side 2's centroid; poses farther apart are distinct
    score_tol: float = 0.03  # an alternative's mean fitness is at most this much below the lowest-cost pose's
    rmse_tol: float = 0.03  # and its RMSE at most this share above the best's (equal poses: 1-2 % apart)
    shape_tol: float = 3.0  # [RMSEs of the best pose, at least 1/4 voxel] a larger shape difference: another shape
    shape_radius: float = 4.0  # [voxels] farther from the other merged model: in its holes, no shape difference
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)  # the table's normal in the world frame

    def __post_init__(self) -> None:
        if self.ransac_runs < 1 or self.ransac_iterations < 1 or self.symmetry_steps < 0:
            raise InputError(f"side registration needs ransac_runs >= 1, ransac_iterations >= 1 and "
                             f"symmetry_steps >= 0 (got {self.ransac_runs}, {self.ransac_iterations}, "
                             f"{self.symmetry_steps})")
        if not np.linalg.norm(self.up) > 0:
            raise InputError(f"the table's normal {self.up} is not a direction", hint="e.g. (0, 0, 1)")


@dataclass(frozen=True)
class Alternative:
    """Another pose that fits within the tolerances, and how far it is from the best one."""

    side1_T_side2: np.ndarray  # (4, 4)
    fitness: float
    fitness_reverse: float
    rmse: float  # [m]
    angle: float  # [rad] from the best pose
    translation: float  # [m] from the best pose, at side 2's centroid
    shape_difference: float  # [m] between the models merged under it and the best pose (_shape_difference)

    def to_dict(self) -> dict:
        return {"side1_T_side2": self.side1_T_side2, "fitness": self.fitness,
                "fitness_reverse": self.fitness_reverse, "rmse_m": self.rmse, "angle_deg": math.degrees(self.angle),
                "translation_m": self.translation, "shape_difference_m": self.shape_difference}


@dataclass(frozen=True)
class SideRegistration:
    """Side 2 registered onto side 1 by shape, with the confidence in it."""

    side1_T_side2: np.ndarray  # (4, 4) maps side-2 points onto side 1 (both in the world frame)
    fitness: float  # share of side 2's overlap points with a side-1 neighbour within the inlier distance
    fitness_reverse: float  # the same from side 1 onto side 2
    rmse: float  # [m] of the inliers' distances to their partners' tangent planes, both ways
    overlap: float  # share of side 2 in the overlap region
    alternatives: tuple[Alternative, ...]  # other poses that fit within the tolerances, the best-fitting first
    ambiguous: bool  # the shape cannot fix the pose: there are alternatives
    shape_ambiguous: bool  # and one of them also changes the merged shape beyond the tolerance
    reason: str | None  # why the pose is not trusted, in words; None: trusted
    candidates: int  # poses tried: global-registration hypotheses, symmetry and weak-motion probes

    @property
    def trusted(self) -> bool:
        return self.reason is None

    def to_dict(self) -> dict:
        return {"side1_T_side2": self.side1_T_side2, "fitness": self.fitness, "fitness_reverse": self.fitness_reverse,
                "rmse_m": self.rmse, "overlap": self.overlap, "ambiguous": self.ambiguous,
                "shape_ambiguous": self.shape_ambiguous, "reason": self.reason, "candidates": self.candidates,
                "alternatives": [a.to_dict() for a in self.alternatives]}


# --------------------------------------------------------------------- clouds
@dataclass(frozen=True)
class _Side:
    """One side prepared for registration."""

    # (scale [voxels], cloud on it, its FPFH) for the registration voxel and twice it
    features: tuple[tuple[float, o3d.geometry.PointCloud, o3d.pipelines.registration.Feature], ...]
    sparse: o3d.geometry.PointCloud  # on 2 voxels: the first ICP stages and the second scale of features
    fine: o3d.geometry.PointCloud  # on half a voxel: the last ICP stages and the scores
    points: np.ndarray  # (N, 3) of the fine cloud
    normals: np.ndarray  # (N, 3) unit normals of the fine cloud
    tree: cKDTree  # of points
    floor: float  # [m] height of the lowest points along up (0.2 % quantile)


def _with_normals(cloud: o3d.geometry.PointCloud, radius: float) -> o3d.geometry.PointCloud:
    """The cloud's own normals made unit length, or estimated and turned away from its centroid."""
    import open3d as o3d

    if not cloud.has_normals():
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=radius, max_nn=30))
        cloud.orient_normals_towards_camera_location(np.asarray(cloud.points).mean(axis=0))
        cloud.normals = o3d.utility.Vector3dVector(-np.asarray(cloud.normals))
    else:
        n = np.asarray(cloud.normals)
        cloud.normals = o3d.utility.Vector3dVector(n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12))
    return cloud


def _prepare(cloud: o3d.geometry.PointCloud, voxel: float, up: np.ndarray, what: str) -> _Side:
    import open3d as o3d
    from scipy.spatial import cKDTree

    if len(cloud.points) < 100:
        raise InputError(f"{what} has {len(cloud.points)} points: too few to register by shape",
                         hint="scan the side from more views or check the crop box")
    coarse = _with_normals(cloud.voxel_down_sample(voxel), 2.0 * voxel)
    sparse = _with_normals(cloud.voxel_down_sample(2.0 * voxel), 4.0 * voxel)
    features = tuple((scale, c, o3d.pipelines.registration.compute_fpfh_feature(  # type: ignore[call-arg]
        c, o3d.geometry.KDTreeSearchParamHybrid(radius=5.0 * scale * voxel, max_nn=50)))
        for scale, c in ((1.0, coarse), (2.0, sparse)))
    fine = _with_normals(cloud.voxel_down_sample(voxel / 2.0), 2.0 * voxel)
    points = np.asarray(fine.points)
    return _Side(features, sparse, fine, points, np.asarray(fine.normals), cKDTree(points),
                 float(np.quantile(points @ up, 0.002)))


# --------------------------------------------------------------------- hypotheses
def _global_hypotheses(s1: _Side, s2: _Side, voxel: float, seed: int, opt: SidesOptions) -> list[np.ndarray]:
    """side1_T_side2 from RANSAC on feature matches (one seed per run, drawn from ``seed``)
    and from fast global registration, with the features of each scale."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    runs = opt.ransac_runs + 1
    seeds = np.random.default_rng(seed).integers(0, 2**31 - 1, size=runs * len(s1.features))
    out = []
    for k, ((scale, cloud1, features1), (_, cloud2, features2)) in enumerate(zip(s1.features, s2.features,
                                                                                  strict=True)):
        distance = 1.5 * scale * voxel
        checkers = [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(distance),
                    reg.CorrespondenceCheckerBasedOnNormal(opt.normal_angle)]
        for s in seeds[k * runs: (k + 1) * runs - 1]:
            with open3d_draws(int(s), single_thread=True):
                r = reg.registration_ransac_based_on_feature_matching(
                    cloud2, cloud1, features2, features1, False, distance,
                    reg.TransformationEstimationPointToPoint(False), 3, checkers,
                    reg.RANSACConvergenceCriteria(opt.ransac_iterations, 0.9999))
            out.append(np.asarray(r.transformation))
        with open3d_draws(int(seeds[(k + 1) * runs - 1]), single_thread=True):
            r = reg.registration_fgr_based_on_feature_matching(
                cloud2, cloud1, features2, features1,
                reg.FastGlobalRegistrationOption(maximum_correspondence_distance=distance))
        out.append(np.asarray(r.transformation))
    return out


def _box_hypotheses(s1: _Side, s2: _Side) -> list[np.ndarray]:
    """side1_T_side2 that put side 2's principal axes onto side 1's (the 4 proper ways) and
    the centres of their bounding boxes along them onto each other: global registration by
    the moments, which needs no overlap of features (a flat object turned over shows its
    other face)."""
    frames = []
    for side in (s1, s2):
        centroid = side.points.mean(axis=0)
        axes = np.linalg.eigh(np.cov((side.points - centroid).T))[1]  # (3, 3) columns: principal axes
        local = (side.points - centroid) @ axes
        frames.append((axes, centroid + axes @ ((local.min(axis=0) + local.max(axis=0)) / 2.0)))
    (axes1, centre1), (axes2, centre2) = frames
    out = []
    for signs in ((1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)):
        R = axes1 @ np.diag(signs) @ axes2.T
        if np.linalg.det(R) < 0:  # eigh's axes may form a left-handed frame
            R = axes1 @ np.diag(np.multiply(signs, (1, 1, -1))) @ axes2.T
        out.append(pose(R, centre1 - R @ centre2))
    return out


#: yaws tried about the vertical for a turn whose face down is known (360 deg / this apart)
TURN_YAWS = 16


def _turn_hypotheses(s1: _Side, s2: _Side, down_world: np.ndarray, up: np.ndarray) -> list[np.ndarray]:
    """side1_T_side2 of a turn that put the side-1 world direction ``down_world`` straight
    down (opposite ``up``), at :data:`TURN_YAWS` yaws about ``up`` (the yaw is not known),
    the bounding-box centres of the two sides onto each other."""
    u = np.asarray(down_world, dtype=float) / np.linalg.norm(down_world)
    tip = rotation_between(u, -up)
    c1 = (s1.points.min(axis=0) + s1.points.max(axis=0)) / 2.0
    c2 = (s2.points.min(axis=0) + s2.points.max(axis=0)) / 2.0
    # along up, the face the object rests on: side 1's farthest points along down_world lie on
    # side 2's table (its lowest points)
    support = float(np.quantile(s1.points @ u, 0.998))
    out = []
    for k in range(TURN_YAWS):
        R = axis_angle(up, 2.0 * math.pi * k / TURN_YAWS) @ tip  # side 1 -> side 2
        t = c2 - R @ c1  # side 2 = R side 1 + t: the boxes' centres onto each other ...
        t += up * (s2.floor - (-support + float(t @ up)))  # ... and the face on the table
        out.append(invert(pose(R, t)))
    return out


def _turned(side1_T_side2: np.ndarray, rotvec: np.ndarray, shift: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The pose followed by a turn ``rotvec`` [rad] about ``centre`` and a ``shift`` [m] (side-1 frame)."""
    from scipy.spatial.transform import Rotation

    turn = pose(Rotation.from_rotvec(rotvec).as_matrix(), centre + shift) @ pose(None, -centre)
    return turn @ side1_T_side2


def _symmetry_probes(s1: _Side, s2: _Side, side1_T_side2: np.ndarray, steps: int) -> list[np.ndarray]:
    """The pose turned about the principal axes of the merged model (through its centroid)
    by multiples of 360 deg / steps."""
    merged = np.vstack([s1.points, transform_points(side1_T_side2, s2.points)])
    centroid = merged.mean(axis=0)
    axes = np.linalg.eigh(np.cov((merged - centroid).T))[1].T  # (3, 3) rows: principal axes
    return [_turned(side1_T_side2, axis * 2.0 * math.pi * k / steps, np.zeros(3), centroid)
            for axis in axes for k in range(1, steps)]


# --------------------------------------------------------------------- refinement and scores
def _icp(s1: _Side, s2: _Side, side1_T_side2: np.ndarray, voxel: float, fine: bool,
         seen_only: bool = False) -> np.ndarray:
    """Point-to-plane ICP with a Tukey kernel (as wide as the correspondence distance) at
    decreasing correspondence distances: on the sparse clouds, or on the fine ones; with
    ``seen_only``, the sparse ones restricted to the points the other side could have seen
    at the start pose (:func:`_seen_by_other`; a bowl's inside, which side 2 upside down
    cannot see, would otherwise pull side 2's outside into its wall)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    source, target = (s2.fine, s1.fine) if fine else (s2.sparse, s1.sparse)
    if not fine and seen_only:
        source, target = _seen_by_other(s2.sparse, s1, side1_T_side2), _seen_by_other(s1.sparse, s2,
                                                                                     invert(side1_T_side2))
    T = side1_T_side2
    for d in ((voxel, 0.4 * voxel) if fine else (5.0 * voxel, 2.5 * voxel)):
        T = reg.registration_icp(source, target, d, T,
                                 reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=d)),
                                 reg.ICPConvergenceCriteria(1e-6 if fine else 1e-4, 1e-6 if fine else 1e-4, 30)
                                 ).transformation
    return np.asarray(T)


def _seen_by_other(cloud: o3d.geometry.PointCloud, other: _Side, other_T_cloud: np.ndarray,
                   opt: SidesOptions | None = None) -> o3d.geometry.PointCloud:
    """The points of ``cloud`` the other side's cameras could have seen, placed by
    ``other_T_cloud`` (:func:`_match`'s overlap: above the other side's lowest points, not
    facing down); the whole cloud when fewer than 100 are."""
    opt = opt or SidesOptions()
    up = np.asarray(opt.up, dtype=float) / np.linalg.norm(opt.up)
    p = transform_points(other_T_cloud, np.asarray(cloud.points))
    n = np.asarray(cloud.normals) @ other_T_cloud[:3, :3].T
    keep = np.flatnonzero((p @ up - other.floor > 0.0) & (n @ up >= opt.facing_down))
    return cloud.select_by_index(keep.tolist()) if len(keep) >= 100 else cloud


@dataclass(frozen=True)
class _Fit:
    side1_T_side2: np.ndarray  # (4, 4)
    fitness: float  # side 2 onto side 1, in the overlap (misses: also points under side 1's table)
    fitness_reverse: float  # side 1 onto side 2, likewise
    rmse: float  # [m] of the inliers' distances to their partners' tangent planes, both ways
    cost: float  # the truncated least-squares cost of both ways, 0 (all match exactly) ... 1 (none matches)
    overlap: float  # share of side 2 in the overlap
    overlap_reverse: float  # share of side 1 in the overlap
    enough_overlap: bool  # both shares at least min_overlap

    @property
    def mean_fitness(self) -> float:
        return (self.fitness + self.fitness_reverse) / 2.0

    @property
    def key(self) -> tuple[bool, float]:
        """Larger is better: enough overlap, then the lower cost."""
        return (self.enough_overlap, -self.cost)


@dataclass(frozen=True)
class _Matches:
    """One side's points mapped into the other side's frame, against the other side."""

    overlap: np.ndarray  # (N,) bool: the other side could have seen them
    impossible: np.ndarray  # (N,) bool: under the other side's table
    found: np.ndarray  # (M,) bool for the overlap points: a point of the other side within the inlier distance
    index: np.ndarray  # (K,) that point's index, for the found ones
    residual: np.ndarray  # (K,) [m] their distances to its tangent plane


def _match(points: np.ndarray, normals: np.ndarray, other: _Side, voxel: float, up: np.ndarray,
           opt: SidesOptions) -> _Matches:
    """``points`` and ``normals`` (N, 3) in the other side's frame."""
    height = points @ up - other.floor
    overlap = (height > opt.overlap_margin * voxel) & (normals @ up >= opt.facing_down)
    impossible = height < -opt.support_band
    q = points[overlap]
    distance, index = map(np.asarray, other.tree.query(q, distance_upper_bound=opt.inlier_distance * voxel))
    found = np.isfinite(distance)
    found[found] = np.sum(normals[overlap][found] * other.normals[index[found]], axis=1) > math.cos(opt.normal_angle)
    index = index[found]
    residual = np.sum((q[found] - other.points[index]) * other.normals[index], axis=1)
    return _Matches(overlap, impossible, found, index, residual)


def _matches(s1: _Side, s2: _Side, side1_T_side2: np.ndarray, voxel: float, up: np.ndarray, opt: SidesOptions,
             stride: int = 1) -> tuple[_Matches, _Matches]:
    """Side 2 against side 1 (in the side-1 frame) and side 1 against side 2 (in the side-2
    frame); every ``stride``-th point of the one against all of the other."""
    side2_T_side1 = invert(side1_T_side2)
    forward = _match(transform_points(side1_T_side2, s2.points[::stride]),
                     s2.normals[::stride] @ side1_T_side2[:3, :3].T, s1, voxel, up, opt)
    reverse = _match(transform_points(side2_T_side1, s1.points[::stride]),
                     s1.normals[::stride] @ side2_T_side1[:3, :3].T, s2, voxel, up, opt)
    return forward, reverse


def _score(s1: _Side, s2: _Side, side1_T_side2: np.ndarray, voxel: float, up: np.ndarray, opt: SidesOptions,
           stride: int = 1) -> _Fit:
    """Fitness both ways, the inliers' RMSE and the truncated least-squares cost, on the fine
    clouds (every ``stride``-th point). The cost of one way: the mean over its overlap and
    impossible points of the squared distance to the partner's tangent plane, a point
    without a partner counted as the inlier distance, in units of its square; the cost is
    the mean of both ways."""
    forward, reverse = _matches(s1, s2, side1_T_side2, voxel, up, opt, stride)
    tau = opt.inlier_distance * voxel

    def fitness(m: _Matches) -> float:
        return float(m.found.sum() / max(len(m.found) + int(m.impossible.sum()), 1))

    def cost(m: _Matches) -> float:
        n = max(len(m.found) + int(m.impossible.sum()), 1)
        return float((np.sum(m.residual**2) / tau**2 + n - len(m.residual)) / n)

    residuals = np.concatenate([forward.residual, reverse.residual])
    return _Fit(side1_T_side2, fitness(forward), fitness(reverse),
                float(np.sqrt(np.mean(residuals**2))) if len(residuals) else math.inf,
                (cost(forward) + cost(reverse)) / 2.0, float(forward.overlap.mean()), float(reverse.overlap.mean()),
                min(float(forward.overlap.mean()), float(reverse.overlap.mean())) >= opt.min_overlap)


def _weak_probes(s1: _Side, s2: _Side, side1_T_side2: np.ndarray, voxel: float, up: np.ndarray,
                 opt: SidesOptions) -> list[np.ndarray]:
    """The pose moved both ways along each motion the overlap hardly constrains: eigenvectors
    of the point-to-plane information J^T J of the inliers (side 2 onto side 1; a row per
    inlier: ((p - c) x n / r, n), c their centroid, r their RMS distance from it) with
    eigenvalues below ``weak_ratio`` of the largest; moved by ``weak_step`` voxels at r."""
    forward, _ = _matches(s1, s2, side1_T_side2, voxel, up, opt)
    if len(forward.index) < 6:
        return []
    p = transform_points(side1_T_side2, s2.points)[forward.overlap][forward.found]  # (M, 3)
    n = s1.normals[forward.index]  # (M, 3)
    c = p.mean(axis=0)
    r = float(np.sqrt(np.mean(np.sum((p - c) ** 2, axis=1))))
    J = np.hstack([np.cross(p - c, n) / r, n])  # (M, 6)
    values, vectors = np.linalg.eigh(J.T @ J / len(J))
    out = []
    for value, v in zip(values, vectors.T, strict=True):
        if value < opt.weak_ratio * values[-1]:
            out += [_turned(side1_T_side2, step * v[:3] / r, step * v[3:], c)
                    for step in (opt.weak_step * voxel, -opt.weak_step * voxel, 3.0 * opt.weak_step * voxel,
                                 -3.0 * opt.weak_step * voxel)]
    return out


def _apart(a: np.ndarray, b: np.ndarray, centroid: np.ndarray) -> tuple[float, float]:
    """Angle [rad] between two poses and the distance [m] between their images of ``centroid``."""
    return (rotation_angle(a[:3, :3].T @ b[:3, :3]),
            float(np.linalg.norm(transform_points(a, centroid[None]) - transform_points(b, centroid[None]))))


def _distinct(fits: list[_Fit], centroid: np.ndarray, opt: SidesOptions) -> list[_Fit]:
    """The best of each group of poses within the tolerances of each other, best first."""
    out: list[_Fit] = []
    for f in sorted(fits, key=lambda f: f.key, reverse=True):
        if not any(_near(f.side1_T_side2, g.side1_T_side2, centroid, opt) for g in out):
            out.append(f)
    return out


def _near(a: np.ndarray, b: np.ndarray, centroid: np.ndarray, opt: SidesOptions) -> bool:
    """Two poses within the tolerances of each other."""
    angle, distance = _apart(a, b, centroid)
    return angle <= opt.angle_tol and distance <= opt.distance_tol


def _fits_like(f: _Fit, best: _Fit, opt: SidesOptions, slack: float = 1.0) -> bool:
    """f fits within the tolerances (times ``slack``) of the best fit."""
    return (f.enough_overlap and f.mean_fitness >= best.mean_fitness - slack * opt.score_tol
            and f.rmse <= (1.0 + slack * opt.rmse_tol) * best.rmse)


def _shape_difference(s1: _Side, s2: _Side, a: np.ndarray, b: np.ndarray, voxel: float, opt: SidesOptions) -> float:
    """How far the models merged under poses a and b are apart [m]: the 95th percentile of
    the distances of side 2's points under one pose to the tangent plane of their nearest
    point of the model merged under the other, both ways. A point lies in a hole of the
    other model (what the pose puts there was not seen under the other one: a box's bottom
    face under its 180 deg turn), and does not count, when that model has no point within
    ``shape_radius`` voxels or only one that faces another way (normals more than 60 deg apart)."""
    from scipy.spatial import cKDTree

    out = 0.0
    for one, other in ((a, b), (b, a)):
        model = np.vstack([s1.points, transform_points(other, s2.points)])
        model_normals = np.vstack([s1.normals, s2.normals @ other[:3, :3].T])
        q, qn = transform_points(one, s2.points), s2.normals @ one[:3, :3].T
        distance, index = map(np.asarray, cKDTree(model).query(q, distance_upper_bound=opt.shape_radius * voxel))
        seen = np.isfinite(distance)
        q, qn, m, mn = q[seen], qn[seen], model[index[seen]], model_normals[index[seen]]
        same = np.sum(qn * mn, axis=1) > 0.5
        if same.any():
            off = np.abs(np.sum((q[same] - m[same]) * mn[same], axis=1))
            out = max(out, float(np.quantile(off, 0.95)))
    return out


# --------------------------------------------------------------------- the registration
def register_sides(side1: o3d.geometry.PointCloud, side2: o3d.geometry.PointCloud, voxel: float, seed: int = 0,
                   options: SidesOptions | None = None, down_world: np.ndarray | None = None) -> SideRegistration:
    """Side 2's partial model registered onto side 1's by shape alone (see the module docstring).

    side1, side2: clouds in the world frame, cropped to the object, the table cropped away
    (normals optional; colours are not used). voxel [m]: the registration voxel (a few
    millimetres for objects of 0.1-0.3 m; the result is refined on half of it). seed: of
    every random draw; the result depends on it and the inputs only. down_world: the side-1
    world direction that was turned to point straight down, when known (the face the object
    was put on: :func:`_turn_hypotheses` adds its yaws to the hypotheses; a body of
    revolution upside down shares only smooth surface, where features find no match)."""
    if not (math.isfinite(voxel) and voxel > 0):
        raise InputError(f"registration voxel {voxel!r} m is not a positive number", hint="e.g. 0.003")
    opt = options or SidesOptions()
    # one thread: Open3D's ICP sums over several threads in varying order, and the poses would
    # differ in their last digits from run to run
    with open3d_draws(seed, single_thread=True):
        return _register(side1, side2, voxel, seed, opt, down_world)


def _register(side1: o3d.geometry.PointCloud, side2: o3d.geometry.PointCloud, voxel: float, seed: int,
              opt: SidesOptions, down_world: np.ndarray | None = None) -> SideRegistration:
    up = np.asarray(opt.up, dtype=float) / np.linalg.norm(opt.up)
    s1, s2 = _prepare(side1, voxel, up, "side 1"), _prepare(side2, voxel, up, "side 2")
    centroid = s2.points.mean(axis=0)

    def refine(inits: list[np.ndarray], fine: bool) -> list[_Fit]:
        if not fine:
            return [_score(s1, s2, _icp(s1, s2, T, voxel, False), voxel, up, opt, 4) for T in inits]
        # the fine ICP can slide onto the wrong one of two close surfaces (a thin wall's inside
        # and outside: it does not compare normals); the pose it starts from stays when that scores better
        return [max((_score(s1, s2, T, voxel, up, opt), _score(s1, s2, _icp(s1, s2, T, voxel, True), voxel, up, opt)),
                    key=lambda f: f.key) for T in inits]

    inits = _global_hypotheses(s1, s2, voxel, seed, opt) + _box_hypotheses(s1, s2)
    fits = refine(inits, False)
    if down_world is not None:  # near the truth: refined as the others, and with each side's ICP
        # partners only where the other side could see (a thin wall's other face does not pull)
        turns = _turn_hypotheses(s1, s2, down_world, up)
        fits += refine(turns, False) + [_score(s1, s2, _icp(s1, s2, T, voxel, False, seen_only=True), voxel, up,
                                               opt, 4) for T in turns] + \
            [_score(s1, s2, T, voxel, up, opt, 4) for T in turns]  # as they are: the face exactly on the table
        inits += 3 * turns
    fits = _distinct(fits, centroid, opt)
    probes = _symmetry_probes(s1, s2, fits[0].side1_T_side2, opt.symmetry_steps)
    fits = _distinct(fits + refine(probes, False), centroid, opt)
    if min(fits[0].fitness, fits[0].fitness_reverse) < opt.min_fitness:  # nothing fits (the fine stage adds
        # a few per cent at most): no alternatives either
        best = _score(s1, s2, _icp(s1, s2, fits[0].side1_T_side2, voxel, True), voxel, up, opt)
        return SideRegistration(best.side1_T_side2, best.fitness, best.fitness_reverse, best.rmse, best.overlap, (),
                                False, False, _reason(best, [], False, opt), len(inits) + len(probes))
    # the fine stage for the best pose and those near it
    near = [f for f in fits[1:] if _fits_like(f, fits[0], opt, slack=2.0)][: opt.max_alternatives]
    fits = _distinct(refine([f.side1_T_side2 for f in [fits[0], *near]], True), centroid, opt)
    equal = [fits[0], *(f for f in fits[1:] if _fits_like(f, fits[0], opt))]
    # of poses that fit equally well, the one whose merged model covers most (its overlap share
    # smaller by more than score_tol)
    best = min(equal, key=lambda f: f.overlap) if min(f.overlap for f in equal) < fits[0].overlap - opt.score_tol \
        else fits[0]
    # the motions the reported pose's overlap hardly fixes, scored where they lead
    weak = _weak_probes(s1, s2, best.side1_T_side2, voxel, up, opt)
    moved = [f for f in (_score(s1, s2, T, voxel, up, opt) for T in weak) if _fits_like(f, fits[0], opt)]
    others = [f for f in _distinct([f for f in equal if f is not best] + moved, centroid, opt)
              if not _near(f.side1_T_side2, best.side1_T_side2, centroid, opt)]
    alternatives = []
    for f in others[: opt.max_alternatives]:
        angle, distance = _apart(best.side1_T_side2, f.side1_T_side2, centroid)
        alternatives.append(Alternative(f.side1_T_side2, f.fitness, f.fitness_reverse, f.rmse, angle, distance,
                                        _shape_difference(s1, s2, best.side1_T_side2, f.side1_T_side2, voxel, opt)))
    shape_ambiguous = any(a.shape_difference > max(opt.shape_tol * best.rmse, 0.25 * voxel) for a in alternatives)
    candidates = len(inits) + len(probes) + len(weak)
    log.debug("sides: %d candidates, best fitness %.3f / %.3f, %d alternatives", candidates, best.fitness,
              best.fitness_reverse, len(alternatives))
    return SideRegistration(best.side1_T_side2, best.fitness, best.fitness_reverse, best.rmse, best.overlap,
                            tuple(alternatives), bool(alternatives), shape_ambiguous,
                            _reason(best, alternatives, shape_ambiguous, opt), candidates)


def _reason(best: _Fit, alternatives: list[Alternative], shape_ambiguous: bool, opt: SidesOptions) -> str | None:
    """Why the pose is not trusted, in words; None when it is."""
    if min(best.fitness, best.fitness_reverse) < opt.min_fitness:
        return (f"no pose fits the two sides together: the best one matches {best.fitness:.0%} of side 2 and "
                f"{best.fitness_reverse:.0%} of side 1 where they overlap ({opt.min_fitness:.0%} needed)")
    if not best.enough_overlap:
        return (f"the sides overlap too little: {best.overlap:.0%} of side 2 lies where side 1 could see it, "
                f"{best.overlap_reverse:.0%} of side 1 where side 2 could ({opt.min_overlap:.0%} needed)")
    if shape_ambiguous:
        worst = max(a.shape_difference for a in alternatives)
        return (f"{len(alternatives) + 1} poses fit the sides equally well and give shapes up to "
                f"{worst * 1e3:.1f} mm apart: the shape does not fix how side 2 lies on side 1")
    return None
