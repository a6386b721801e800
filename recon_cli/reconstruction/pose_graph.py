"""Local registration of many scans (thesis 2.4.2, "Full Registration").

The clouds come globally registered (one common frame) and are down-sampled on a voxel grid
(``voxel``); their own normals, averaged per voxel, serve point-to-plane ICP (estimated
when a cloud has none).

Pairs: on sparser copies (``overlap_voxel``) a KD-tree per cloud counts, for every pair,
the points with a neighbour in the other cloud within the coarsest correspondence distance
(pairs whose bounding boxes are farther apart are skipped). A pair overlaps when that count
is at least ``min_overlap`` of the smaller copy. A maximum spanning tree of the counts picks
the odometry edges (the pairs that overlap most, whatever the scan order); every other
overlapping pair is a loop closure (or, with ``loop_closures_per_scan``, only those among
the largest overlaps of one of their scans).

Edges, with the prior (``anchor="prior"``, the default): every scan has an edge to the
common frame whose information is the global registration's (``prior_sigma``). Pairs are
registered by a point-to-plane ICP with the same prior (``regularized_icp``, numpy on the
clouds' KD-trees, several pairs at once): the coarser correspondence distances on a regular
subset of the points, the finest on all of them. The edge's information is the data's
point-to-plane information J^T J of that last step, counted as ``effective_samples``
measurements with the residual's RMS as their sigma: (nearly) singular along what the
overlap does not fix, where the prior holds. Loop closures initialized with the identity
(the thesis' choice, ``loop_closure_init="global"``) carry the same point-to-plane
information at the global alignment. Without the prior, pairs use Open3D's ICP and its
point-to-point information matrix. Loop closures enter the graph as uncertain edges that
Open3D's Levenberg-Marquardt pose-graph optimization may prune. The result is one
correction pose per cloud.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from recon_cli.geometry.transforms import pose
from recon_cli.reconstruction.options import MultiwayOptions  # noqa: F401 (re-exported)

if TYPE_CHECKING:
    from scipy.spatial import cKDTree


@dataclass(frozen=True)
class PairEdge:
    source: int
    target: int
    kind: str  # odometry | loop_closure
    correspondences: int  # at the global alignment (coarsest distance, overlap_voxel copies)
    fitness: float  # ICP fitness (share of source points with a correspondence)
    rmse: float  # ICP inlier RMSE [m]
    transformation: np.ndarray  # source -> target
    rejected: bool = False  # ICP moved farther than the global uncertainty allows: left out

    def to_dict(self) -> dict:
        return {"source": self.source, "target": self.target, "kind": self.kind, "rejected": self.rejected,
                "correspondences": self.correspondences, "fitness": self.fitness, "rmse_m": self.rmse,
                "transformation": self.transformation}


@dataclass(frozen=True)
class MultiwayResult:
    poses: list[np.ndarray]  # correction of each cloud: corrected = poses[i] @ cloud_i
    edges: list[PairEdge]
    counts: np.ndarray  # (n, n) correspondence counts at the global alignment
    pruned: int  # loop closures the optimization dropped


def prepare(cloud, voxel: float, normal_radius: float = 2.5, own_normals: bool = False,
            camera: npt.ArrayLike | None = None):
    """Down-sampled copy with normals for point-to-plane ICP: with ``own_normals`` those of
    the cloud averaged per voxel (when it has normals), else estimated within
    ``normal_radius`` voxels (small: normals near an object's edges stay those of their face),
    each turned toward the cloud's own normal there or, for a cloud without normals, toward
    ``camera`` (the position of the camera that took it, in the cloud's frame)."""
    import open3d as o3d

    down = cloud.voxel_down_sample(voxel)
    if own_normals and cloud.has_normals():
        return down.normalize_normals()
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * normal_radius, max_nn=30))
    if camera is not None and not cloud.has_normals():
        down.orient_normals_towards_camera_location(np.asarray(camera, dtype=float))
    return down


def pairwise_icp(source, target, init: np.ndarray, options: MultiwayOptions):
    """ICP from ``init`` (point-to-plane by default; point-to-point, or Open3D's coloured ICP
    for clouds with colours), coarse to fine correspondence distances."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    T = np.asarray(init, dtype=float)
    criteria = reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7,
                                          max_iteration=options.icp_iterations)
    colored = options.method == "colored" and source.has_colors() and target.has_colors()
    estimation = (reg.TransformationEstimationPointToPoint() if options.method == "point_to_point"
                  else reg.TransformationEstimationForColoredICP() if colored
                  else reg.TransformationEstimationPointToPlane())
    result = None
    for scale in options.scales:
        distance = options.max_correspondence * scale
        if colored:
            result = reg.registration_colored_icp(source, target, distance, T, estimation, criteria)
        else:
            result = reg.registration_icp(source, target, distance, T, estimation, criteria)
        T = result.transformation
    return result


@dataclass(frozen=True)
class IcpResult:
    transformation: np.ndarray
    fitness: float
    inlier_rmse: float
    information: np.ndarray  # point-to-plane information of the data alone (rotation, translation)


@dataclass(frozen=True)
class IcpCloud:
    """A registration cloud as the pairwise steps reuse it: points, normals and a KD-tree."""

    points: np.ndarray  # (N, 3) [m]
    normals: np.ndarray  # (N, 3) unit
    tree: cKDTree  # of points

    @classmethod
    def of(cls, cloud) -> IcpCloud:
        from scipy.spatial import cKDTree

        points = np.asarray(cloud.points)
        return cls(points, np.asarray(cloud.normals), cKDTree(points))


def regularized_icp(source: IcpCloud, target: IcpCloud, options: MultiwayOptions) -> IcpResult:
    """Point-to-plane ICP from the global alignment (identity), Gauss-Newton steps with a
    prior that keeps the correction within the global registration's uncertainty (relative
    pose of two scans: prior_sigma x sqrt(2)). Where the overlap fixes the pose the data
    dominate; where it does not (a plane slides in itself, a body of revolution turns about
    its axis), the correction stays near zero instead of drifting on noise.

    The coarser scales only bring the pair close: they use a regular subset of
    ``icp_points`` source points. The finest scale uses every point (its precision is what
    the edge carries): its first step searches all of them, the next ones only those that
    found a partner then."""
    import cv2


    sigma_t, sigma_r = options.prior_sigma
    prior = np.diag([1.0 / (2.0 * np.radians(sigma_r) ** 2)] * 3 + [1.0 / (2.0 * sigma_t**2)] * 3)
    tol_r, tol_t = options.icp_tolerance
    n_src = len(source.points)
    T = np.eye(4)
    x = np.zeros(6)  # accumulated correction (rotation vector, translation), small angles
    rmse, fitness, H_data = options.point_sigma, 0.0, np.zeros((6, 6))
    for k, scale in enumerate(options.scales):
        distance = options.max_correspondence * scale
        final = k == len(options.scales) - 1
        use = slice(None) if final else slice(None, None, max(1, -(-n_src // options.icp_points)))
        src_pts, src_n = source.points[use], source.normals[use]
        history: list[np.ndarray] = []  # the last solutions of this scale
        for it in range(options.icp_iterations):
            R = T[:3, :3]
            p = src_pts @ R.T + T[:3, 3]
            d, j = map(np.asarray, target.tree.query(p, distance_upper_bound=distance))  # (N,) each for points (N, 3)
            found = d < np.inf
            fitness = float(found.sum()) / (n_src if final else len(p))
            if final and it == 0:  # later steps move by micrometres: the others stay without a partner
                src_pts, src_n = src_pts[found], src_n[found]
            p, j, n_p = p[found], j[found], src_n if final and it == 0 else src_n[found]
            n = target.normals[j]
            # pairs whose normals disagree are not the same surface (an edge of the object,
            # the rim of what the other scan saw): they would pull the scans along the surface
            same = np.einsum("ij,ij->i", n_p @ R.T, n) > options.normal_agreement
            if same.sum() < 6:
                break
            p, n = p[same], n[same]
            r = np.einsum("ij,ij->i", p - target.points[j[same]], n)
            J = np.hstack([np.cross(p, n), n])  # d r / d (rotation, translation)
            rmse = float(np.sqrt(np.mean(r * r)))
            # neighbouring residuals are not independent (normals, resampling, noise of one
            # surface): the data count as ``effective_samples`` measurements, not one per point
            w = min(1.0, options.effective_samples / len(r)) / max(rmse, options.point_sigma) ** 2
            H_data = w * (J.T @ J)
            step = np.linalg.solve(H_data + prior, -(w * (J.T @ r) + prior @ x))
            x = x + step
            T = pose(cv2.Rodrigues(x[:3])[0], x[3:])
            # converged: a small step, or back where it was a few steps ago (the
            # correspondences cycle through a few sets, the solution lies among them)
            if any(np.linalg.norm(v[:3]) < tol_r and np.linalg.norm(v[3:]) < tol_t
                   for v in (step, *(x - h for h in history))):
                break
            history = [*history[-3:], x]
    return IcpResult(T, fitness, rmse, H_data)


def correspondence_counts(clouds: list, distance: float) -> np.ndarray:
    """counts[i, j]: points of cloud i with a neighbour in cloud j within ``distance``
    (clouds in one frame); symmetric by taking the smaller of both directions. Pairs whose
    bounding boxes are farther apart than ``distance`` are not searched."""
    from scipy.spatial import cKDTree

    points = [np.asarray(c.points) for c in clouds]
    trees = [cKDTree(p) for p in points]
    lo = np.array([p.min(axis=0) if len(p) else np.full(3, np.inf) for p in points])
    hi = np.array([p.max(axis=0) if len(p) else np.full(3, -np.inf) for p in points])
    n = len(clouds)
    counts = np.zeros((n, n), dtype=int)
    for i in range(n):
        for j in range(i + 1, n):
            if np.any(lo[i] > hi[j] + distance) or np.any(lo[j] > hi[i] + distance):
                continue
            a = int(np.isfinite(trees[j].query(points[i], distance_upper_bound=distance)[0]).sum())
            b = int(np.isfinite(trees[i].query(points[j], distance_upper_bound=distance)[0]).sum())
            counts[i, j] = counts[j, i] = min(a, b)
    return counts


def maximum_spanning_tree(weights: np.ndarray) -> list[tuple[int, int]]:
    """Edges (i < j) of a maximum spanning forest of a symmetric weight matrix (0: no edge)."""
    w = np.triu(np.asarray(weights, dtype=float), 1)
    top = w.max() + 1.0 if w.size else 1.0
    inverted = np.where(w > 0, top - w, 0.0)  # scipy: zero entries are missing edges
    from scipy.sparse.csgraph import minimum_spanning_tree

    tree = minimum_spanning_tree(inverted).tocoo()
    return sorted((int(min(i, j)), int(max(i, j))) for i, j in zip(tree.row, tree.col, strict=True))


def register_multiway(clouds: list, options: MultiwayOptions = MultiwayOptions(),  # noqa: B008
                      progress: Callable[[str, int, int], None] | None = None,
                      cameras: Sequence[npt.ArrayLike] | None = None) -> MultiwayResult:
    """Pose-graph registration of globally registered clouds (Open3D point clouds). With
    ``rounds`` > 1 the graph is built again from the optimized poses (every pairwise ICP then
    starts closer to its answer, and pruned loop closures get a second chance). ``cameras``:
    each cloud's camera position (its frame), which turns the normals of clouds without
    normals of their own (see :func:`prepare`)."""
    if cameras is not None and len(cameras) != len(clouds):
        raise ValueError(f"{len(clouds)} clouds but {len(cameras)} camera positions")
    down = [prepare(c, options.voxel, options.normal_radius, options.own_normals,
                    None if cameras is None else cameras[k]) for k, c in enumerate(clouds)]
    poses = [np.eye(4) for _ in clouds]
    result = None
    for r in range(options.rounds):
        moved = [o3d_transformed(d, T) for d, T in zip(down, poses, strict=True)]
        result = _one_round(moved, options, progress, r)
        poses = [T_new @ T for T_new, T in zip(result.poses, poses, strict=True)]
    if result is None:
        raise ValueError(f"multiway registration needs at least one round, not {options.rounds}")
    if options.anchor == "mean":
        G = mean_anchor(down, poses)
        poses = [G @ T for T in poses]
    return MultiwayResult(poses, result.edges, result.counts, result.pruned)


def o3d_transformed(cloud, T: np.ndarray):
    import open3d as o3d

    c = o3d.geometry.PointCloud(cloud)
    c.transform(T)
    return c


def _one_round(down: list, options: MultiwayOptions, progress, round_: int) -> MultiwayResult:
    import open3d as o3d

    reg = o3d.pipelines.registration
    n = len(down)
    coarse = options.max_correspondence * max(options.scales)
    sparse = [d.voxel_down_sample(options.overlap_voxel) for d in down]
    counts = correspondence_counts(sparse, coarse)
    sizes = np.array([len(d.points) for d in sparse])
    overlapping = counts >= options.min_overlap * np.minimum.outer(sizes, sizes)
    np.fill_diagonal(overlapping, False)
    tree = set(maximum_spanning_tree(np.where(overlapping, counts, 0)))
    pairs = select_pairs(overlapping, counts / np.maximum(np.minimum.outer(sizes, sizes), 1), tree,
                         options.loop_closures_per_scan)
    graph = reg.PoseGraph()
    for _ in range(n):
        graph.nodes.append(reg.PoseGraphNode(np.eye(4)))
    reference = options.reference
    if options.anchor == "prior":  # node n: the common (marker) frame, kept fixed
        graph.nodes.append(reg.PoseGraphNode(np.eye(4)))
        reference = n
        sigma_t, sigma_r = options.prior_sigma
        prior = np.diag([1.0 / np.radians(sigma_r) ** 2] * 3 + [1.0 / sigma_t**2] * 3)
        for i in range(n):
            graph.edges.append(reg.PoseGraphEdge(i, n, np.eye(4), prior, uncertain=False))
    # with the prior, point-to-plane edges come from numpy on KD-trees built once per cloud
    arrays = [IcpCloud.of(d) for d in down] if options.anchor == "prior" and options.method == "point_to_plane" \
        else None

    def measure(pair: tuple[int, int]):
        """(transformation, fitness, rmse, information or None) of one pair."""
        i, j = pair
        if pair in tree or options.loop_closure_init == "icp":
            if arrays is not None:
                r = regularized_icp(arrays[i], arrays[j], options)
                return r.transformation, r.fitness, r.inlier_rmse, r.information
            r = pairwise_icp(down[i], down[j], np.eye(4), options)
            return np.asarray(r.transformation), r.fitness, r.inlier_rmse, None
        if arrays is not None:  # the thesis' loop closure: the global alignment
            fitness, rmse, info = plane_fit(arrays[i], arrays[j], np.eye(4), options.max_correspondence)
            return np.eye(4), fitness, rmse, info / max(rmse, options.point_sigma) ** 2
        ev = reg.evaluate_registration(down[i], down[j], options.max_correspondence, np.eye(4))
        return np.eye(4), ev.fitness, ev.inlier_rmse, None

    edges = []
    label = "pairwise ICP" if options.rounds == 1 else f"pairwise ICP {round_ + 1}/{options.rounds}"
    with ThreadPoolExecutor(options.workers or os.cpu_count() or 1) as pool:
        for k, ((i, j), (T, fitness, rmse, info)) in enumerate(zip(pairs, pool.map(measure, pairs), strict=True)):
            odometry = (i, j) in tree
            rejected = not _plausible(T, np.asarray(down[i].get_center()), options)
            if not rejected:
                if info is not None:
                    pass  # point-to-plane information of the data, from the regularized ICP or plane_fit
                elif options.anchor == "prior":  # point-to-plane information, in units of the ICP residual
                    info = plane_information(down[i], down[j], T, options.max_correspondence)
                    info = info / max(rmse, options.point_sigma) ** 2
                else:
                    info = reg.get_information_matrix_from_point_clouds(down[i], down[j], options.max_correspondence,
                                                                        T)
                graph.edges.append(reg.PoseGraphEdge(i, j, T, info, uncertain=not odometry))
            edges.append(PairEdge(i, j, "odometry" if odometry else "loop_closure", int(counts[i, j]),
                                  float(fitness), float(rmse), T, rejected))
            if progress:
                progress(label, k + 1, len(pairs))
    before = len(graph.edges)
    if len(graph.edges):
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            reg.global_optimization(
                graph, reg.GlobalOptimizationLevenbergMarquardt(), reg.GlobalOptimizationConvergenceCriteria(),
                reg.GlobalOptimizationOption(max_correspondence_distance=options.max_correspondence,
                                             edge_prune_threshold=options.edge_prune_threshold,
                                             reference_node=reference))
    return MultiwayResult([np.asarray(node.pose) for node in graph.nodes[:n]], edges, counts,
                          before - len(graph.edges))


def select_pairs(overlapping: np.ndarray, share: np.ndarray, tree: set[tuple[int, int]],
                 per_scan: int) -> list[tuple[int, int]]:
    """Pairs (i < j) of the graph: the tree's and, as loop closures, the overlapping pairs,
    or with ``per_scan`` > 0 only those among the ``per_scan`` largest overlap shares of
    either of their scans."""
    n = len(overlapping)
    keep = np.array(overlapping, dtype=bool)
    if per_scan > 0:
        ranked = np.where(keep, share, -np.inf)
        best = np.zeros_like(keep)
        for i in range(n):
            top = [j for j in np.argsort(-ranked[i], kind="stable")[:per_scan] if keep[i, j]]
            best[i, top] = True
        keep &= best | best.T
    for i, j in tree:
        keep[i, j] = keep[j, i] = True
    return [(i, j) for i in range(n) for j in range(i + 1, n) if keep[i, j]]


def _plausible(T: np.ndarray, centre: np.ndarray, options: MultiwayOptions) -> bool:
    """Is an ICP correction T (from the global alignment) within the global registration's
    uncertainty? Translation measured at the source cloud's centre."""
    if options.anchor != "prior":
        limit_t, limit_r = 0.05, 5.0  # without a prior: only gross slides [m, deg]
    else:
        sigma_t, sigma_r = options.prior_sigma
        limit_t, limit_r = (options.gate * np.sqrt(2.0) * v for v in (sigma_t, sigma_r))
    turn = np.degrees(np.arccos(np.clip((np.trace(T[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
    shift = np.linalg.norm(T[:3, :3] @ centre + T[:3, 3] - centre)
    return bool(turn <= limit_r and shift <= limit_t)


def plane_fit(source: IcpCloud, target: IcpCloud, T: np.ndarray, distance: float) -> tuple[float, float, np.ndarray]:
    """Fitness (share of source points with a target point within ``distance``), RMSE of
    those distances [m] and point-to-plane information (sum of J^T J, see
    plane_information) of the clouds at T."""
    p = source.points @ T[:3, :3].T + T[:3, 3]
    d, j = map(np.asarray, target.tree.query(p, distance_upper_bound=distance))  # (N,) each for points (N, 3)
    found = np.isfinite(d)
    if not found.any():
        return 0.0, 0.0, np.zeros((6, 6))
    p, n = p[found], target.normals[j[found]]
    J = np.hstack([np.cross(p, n), n])
    return float(found.mean()), float(np.sqrt(np.mean(d[found] ** 2))), J.T @ J


def plane_information(source, target, T: np.ndarray, distance: float) -> np.ndarray:
    """Information matrix (rotation, translation) of point-to-plane residuals between the
    clouds at T: sum of J^T J with J = [p x n, n] over the correspondences. Unlike Open3D's
    point-to-point information it is (nearly) singular along directions the overlap does not
    fix (sliding along a plane, turning about an axis of symmetry), where the prior holds."""
    import open3d as o3d

    corr = np.asarray(o3d.pipelines.registration.evaluate_registration(
        source, target, distance, T).correspondence_set)
    if len(corr) == 0:
        return np.zeros((6, 6))
    p = np.asarray(source.points)[corr[:, 0]] @ T[:3, :3].T + T[:3, 3]
    n = np.asarray(target.normals)[corr[:, 1]]
    J = np.hstack([np.cross(p, n), n])
    return J.T @ J


def mean_anchor(clouds: list, poses: list[np.ndarray]) -> np.ndarray:
    """Rigid G that moves the locally registered set (poses[i] @ clouds[i]) closest, in the
    least-squares sense over all points, to where the global registration put them."""
    import open3d as o3d

    corrected, original = [], []
    for c, T in zip(clouds, poses, strict=True):
        p = np.asarray(c.points)
        corrected.append(p @ T[:3, :3].T + T[:3, 3])
        original.append(p)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.vstack(corrected)))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.vstack(original)))
    idx = np.arange(len(src.points))
    pairs = o3d.utility.Vector2iVector(np.stack([idx, idx], axis=1))
    return np.asarray(o3d.pipelines.registration.TransformationEstimationPointToPoint()
                      .compute_transformation(src, tgt, pairs))
