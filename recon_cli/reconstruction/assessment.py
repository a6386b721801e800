"""``recon evaluate``: a reconstruction (cloud or mesh file) against a reference mesh.

Loads both files, optionally aligns the reconstruction to the reference by point-to-plane
ICP (only when asked: ``align="icp"``; the transform is reported), computes the signed
distances and coverage of ``evaluation.evaluate`` (coverage of the visible part when a scan
store gives the camera poses), writes a JSON report and a histogram PNG.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from recon_cli.errors import FileError
from recon_cli.geometry.transforms import pose_error
from recon_cli.inputs.meshes import CLOUD_SUFFIXES, MESH_SUFFIXES, read_cloud, read_mesh
from recon_cli.perception.sensor import motioncam_3d_m
from recon_cli.randomness import open3d_draws
from recon_cli.reconstruction.evaluation import CameraView, Evaluation, evaluate, histogram_png, signed_distances
from recon_cli.reconstruction.options import SurfaceOptions
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.runs import evaluation as evaluation_file
from recon_cli.runs.codec import from_json, plain

_SURFACE = SurfaceOptions()  # its voxel and normal radius serve the ICP alignment to a reference


@dataclass(frozen=True)
class EvaluateResult:
    evaluation: Evaluation
    alignment: tuple[float, float] | None  # [m, rad] of the ICP alignment, when asked
    report: Path
    histogram: Path


def load_points(path: Path, samples: int = 500_000, seed: int = 0) -> np.ndarray:
    """Points of a cloud file (PLY, PCD), or uniform samples of a mesh file's surface (PLY,
    OBJ, STL; Open3D's generator seeded with ``seed``); a file of vertices only gives its
    vertices. Both through the guarded readers."""

    path = Path(path)
    if path.suffix.lower() not in (*MESH_SUFFIXES, *CLOUD_SUFFIXES):
        raise FileError(f"{path}: reconstruction has the type '{path.suffix}'", hint="give a PLY, PCD, OBJ or STL file")
    if path.suffix.lower() in CLOUD_SUFFIXES and path.suffix.lower() not in MESH_SUFFIXES:
        return np.asarray(read_cloud(path, "reconstruction").points)
    mesh = read_mesh(path, "reconstruction", triangles=False)
    if len(mesh.triangles):
        with open3d_draws(seed):
            return np.asarray(mesh.sample_points_uniformly(number_of_points=samples).points)
    return np.asarray(mesh.vertices)


def load_mesh(path: Path):
    return read_mesh(path, "reference mesh")


def camera_views(folder: Path) -> list[CameraView]:
    """Camera poses of a scan store (forward kinematics of the measured joints) with the
    sensor's depth range."""

    store = ScanStore(folder)
    if not store.indices():
        raise FileError(f"{folder} holds no scans", hint="--scan-store takes a scan store folder")
    recorded = store.session().sensor_range
    if recorded is None:  # stores without the figures: the thesis' sensor
        sensor = motioncam_3d_m()
        z_min, z_max, incidence = sensor.z_min, sensor.z_max, sensor.max_incidence
    else:
        z_min, z_max, incidence = recorded[0], recorded[1], math.radians(recorded[2])
    return [CameraView(s.world_T_camera_fk, s.intrinsics, z_min, z_max, incidence) for s in store]


def align_icp(points: np.ndarray, reference, distance: float = 0.005, seed: int = 0) -> np.ndarray:
    """Rigid transform taking the points onto the reference surface (point-to-plane ICP;
    the reference sampled with Open3D's generator seeded with ``seed``)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(_SURFACE.voxel)
    with open3d_draws(seed):
        tgt = reference.sample_points_uniformly(number_of_points=200_000)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=_SURFACE.normal_radius, max_nn=30))
    T = np.eye(4)
    for d in (distance, distance / 2, distance / 5):
        T = reg.registration_icp(src, tgt, d, T, reg.TransformationEstimationPointToPlane(),
                                 reg.ICPConvergenceCriteria(max_iteration=60)).transformation
    return np.asarray(T)


def run_evaluate(reconstruction: Path, reference: Path, tolerance: float = 0.001, views: Path | None = None,
                 align: str = "none", samples: int = 200_000, out: Path | None = None,
                 seed: int = 0) -> EvaluateResult:
    """``seed``: of every sampling (the reconstruction when it is a mesh, the reference)."""

    points = load_points(reconstruction, seed=seed)
    mesh = load_mesh(reference)
    alignment = None
    T = np.eye(4)
    if align == "icp":
        T = align_icp(points, mesh, seed=seed)
        points = points @ T[:3, :3].T + T[:3, 3]
        alignment = pose_error(T, np.eye(4))
    cams = camera_views(views) if views is not None else None
    result = evaluate(points, mesh, tolerance, samples, cams, seed=seed)
    out = Path(out or Path(reconstruction).parent)
    out.mkdir(parents=True, exist_ok=True)
    stem = Path(reconstruction).stem
    hist = out / f"{stem}_distances.png"
    histogram_png(hist, {stem: signed_distances(points, mesh)},
                  f"{Path(reconstruction).name} vs {Path(reference).name}")
    report = evaluation_file.write(out, from_json(evaluation_file.EvaluationReport, plain({
        "reconstruction": str(reconstruction), "reference": str(reference), "alignment": align,
        "alignment_transform": T if alignment else None, **result.to_dict()})))
    return EvaluateResult(result, alignment, report, hist)
