"""Local registration of many scans (thesis 2.4.2, "Full Registration").

The clouds come globally registered (one common frame). For every pair, the number of
point correspondences within the correspondence distance measures their overlap; a
maximum spanning tree of those counts picks the odometry edges (the pairs that overlap
most, whatever the scan order), every other overlapping pair is a loop closure. Odometry
edges are initialized by pairwise point-to-plane ICP. Loop closures are initialized by
ICP too (default) or, as in the thesis, with the identity (the global alignment); they
enter the graph as uncertain edges that Open3D's Levenberg-Marquardt pose-graph
optimization may prune. The result is one correction pose per cloud.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse.csgraph import minimum_spanning_tree

from recon_cli.reconstruction.options import MultiwayOptions  # noqa: F401 (re-exported)


@dataclass(frozen=True)
class PairEdge:
    source: int
    target: int
    kind: str  # odometry | loop_closure
    correspondences: int  # at the global alignment (coarsest distance)
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


def prepare(cloud, voxel: float, normal_radius: float = 2.5):
    """Down-sampled copy with normals (for point-to-plane ICP) estimated within
    ``normal_radius`` voxels (small: normals near an object's edges stay those of their face)."""
    import open3d as o3d

    down = cloud.voxel_down_sample(voxel)
    down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * normal_radius, max_nn=30))
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


def regularized_icp(source, target, options: MultiwayOptions) -> IcpResult:
    """Point-to-plane ICP from the global alignment (identity), Gauss-Newton steps with a
    prior that keeps the correction within the global registration's uncertainty (relative
    pose of two scans: prior_sigma x sqrt(2)). Where the overlap fixes the pose the data
    dominate; where it does not (a plane slides in itself, a body of revolution turns about
    its axis), the correction stays near zero instead of drifting on noise."""
    import cv2
    import open3d as o3d

    from recon_cli.geometry.transforms import pose

    reg = o3d.pipelines.registration
    sigma_t, sigma_r = options.prior_sigma
    prior = np.diag([1.0 / (2.0 * np.radians(sigma_r) ** 2)] * 3 + [1.0 / (2.0 * sigma_t**2)] * 3)
    src_pts, src_n = np.asarray(source.points), np.asarray(source.normals)
    tgt_pts, tgt_n = np.asarray(target.points), np.asarray(target.normals)
    T = np.eye(4)
    x = np.zeros(6)  # accumulated correction (rotation vector, translation), small angles
    rmse, fitness, H_data = options.point_sigma, 0.0, np.zeros((6, 6))
    for scale in options.scales:
        distance = options.max_correspondence * scale
        for _ in range(options.icp_iterations):
            ev = reg.evaluate_registration(source, target, distance, T)
            corr = np.asarray(ev.correspondence_set)
            if len(corr) < 6:
                break
            # pairs whose normals disagree are not the same surface (an edge of the object,
            # the rim of what the other scan saw): they would pull the scans along the surface
            same = np.einsum("ij,ij->i", src_n[corr[:, 0]] @ T[:3, :3].T, tgt_n[corr[:, 1]]) > options.normal_agreement
            corr = corr[same]
            if len(corr) < 6:
                break
            p = src_pts[corr[:, 0]] @ T[:3, :3].T + T[:3, 3]
            n = tgt_n[corr[:, 1]]
            r = np.einsum("ij,ij->i", p - tgt_pts[corr[:, 1]], n)
            J = np.hstack([np.cross(p, n), n])
            # neighbouring residuals are not independent (normals, resampling, noise of one
            # surface): the data count as ``effective_samples`` measurements, not one per point
            w = min(1.0, options.effective_samples / len(r)) / max(float(np.sqrt(np.mean(r * r))),
                                                                    options.point_sigma) ** 2
            H_data = w * (J.T @ J)
            step = np.linalg.solve(H_data + prior, -(w * (J.T @ r) + prior @ x))
            x = x + step
            T = pose(cv2.Rodrigues(x[:3])[0], x[3:])
            rmse, fitness = float(np.sqrt(np.mean(r * r))), float(ev.fitness)
            if np.linalg.norm(step[:3]) < 1e-7 and np.linalg.norm(step[3:]) < 1e-8:
                break
    return IcpResult(T, fitness, rmse, H_data)


def correspondence_counts(clouds: list, distance: float) -> np.ndarray:
    """counts[i, j]: points of cloud i with a neighbour in cloud j within ``distance``
    (clouds in one frame); symmetric by taking the smaller of both directions."""
    import open3d as o3d

    n = len(clouds)
    counts = np.zeros((n, n), dtype=int)
    for i in range(n):
        for j in range(i + 1, n):
            a = len(o3d.pipelines.registration.evaluate_registration(
                clouds[i], clouds[j], distance, np.eye(4)).correspondence_set)
            b = len(o3d.pipelines.registration.evaluate_registration(
                clouds[j], clouds[i], distance, np.eye(4)).correspondence_set)
            counts[i, j] = counts[j, i] = min(a, b)
    return counts


def maximum_spanning_tree(weights: np.ndarray) -> list[tuple[int, int]]:
    """Edges (i < j) of a maximum spanning forest of a symmetric weight matrix (0: no edge)."""
    w = np.triu(np.asarray(weights, dtype=float), 1)
    top = w.max() + 1.0 if w.size else 1.0
    inverted = np.where(w > 0, top - w, 0.0)  # scipy: zero entries are missing edges
    tree = minimum_spanning_tree(inverted).tocoo()
    return sorted((int(min(i, j)), int(max(i, j))) for i, j in zip(tree.row, tree.col, strict=True))


def register_multiway(clouds: list, options: MultiwayOptions = MultiwayOptions(),  # noqa: B008
                      progress: Callable[[str, int, int], None] | None = None) -> MultiwayResult:
    """Pose-graph registration of globally registered clouds (Open3D point clouds). With
    ``rounds`` > 1 the graph is built again from the optimized poses (every pairwise ICP then
    starts closer to its answer, and pruned loop closures get a second chance)."""
    down = [prepare(c, options.voxel, options.normal_radius) for c in clouds]
    poses = [np.eye(4) for _ in clouds]
    result = None
    for r in range(options.rounds):
        moved = [o3d_transformed(d, T) for d, T in zip(down, poses, strict=True)]
        result = _one_round(moved, options, progress, r)
        poses = [T_new @ T for T_new, T in zip(result.poses, poses, strict=True)]
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
    counts = correspondence_counts(down, coarse)
    sizes = np.array([len(d.points) for d in down])
    overlapping = counts >= options.min_overlap * np.minimum.outer(sizes, sizes)
    np.fill_diagonal(overlapping, False)
    tree = set(maximum_spanning_tree(np.where(overlapping, counts, 0)))
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if overlapping[i, j]]
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
    edges = []
    label = "pairwise ICP" if options.rounds == 1 else f"pairwise ICP {round_ + 1}/{options.rounds}"
    for k, (i, j) in enumerate(pairs):
        odometry = (i, j) in tree
        info = None
        if options.anchor == "prior" and options.method == "point_to_plane" and (
                odometry or options.loop_closure_init == "icp"):
            result = regularized_icp(down[i], down[j], options)
            T, fitness, rmse, info = result.transformation, result.fitness, result.inlier_rmse, result.information
        elif odometry or options.loop_closure_init == "icp":
            result = pairwise_icp(down[i], down[j], np.eye(4), options)
            T, fitness, rmse = result.transformation, result.fitness, result.inlier_rmse
        else:
            ev = reg.evaluate_registration(down[i], down[j], options.max_correspondence, np.eye(4))
            T, fitness, rmse = np.eye(4), ev.fitness, ev.inlier_rmse
        T = np.asarray(T)
        kind = "odometry" if odometry else "loop_closure"
        rejected = not _plausible(T, np.asarray(down[i].get_center()), options)
        if not rejected:
            if info is not None:
                pass  # the data's own information from the regularized ICP
            elif options.anchor == "prior":  # point-to-plane information, in units of the ICP residual
                info = plane_information(down[i], down[j], T, options.max_correspondence)
                info = info / max(rmse, options.point_sigma) ** 2
            else:
                info = reg.get_information_matrix_from_point_clouds(down[i], down[j], options.max_correspondence, T)
            graph.edges.append(reg.PoseGraphEdge(i, j, T, info, uncertain=not odometry))
        edges.append(PairEdge(i, j, kind, int(counts[i, j]), float(fitness), float(rmse), T, rejected))
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
