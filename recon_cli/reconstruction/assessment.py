"""``recon evaluate``: a reconstruction (cloud or mesh file) against a reference mesh.

Loads both files, optionally aligns the reconstruction to the reference by point-to-plane
ICP (only when asked: ``align="icp"``; the transform is reported), computes the signed
distances and coverage of ``evaluation.evaluate`` (coverage of the visible part when a scan
store gives the camera poses), writes a JSON report and a histogram PNG.

A two-sided run folder (``sides_report.json``) is evaluated as a whole: its merged cloud, and
what each side's cloud covers alone (side 2's moved by the registration of the sides, and
with the merged cloud by the alignment); without a reference, the simulated object's surface
where side 1 saw it (a simulation of a built-in or YCB object; side 1's scan store is
``side_1/scans`` of a script run or ``side_1/`` of ``recon autoscan --sides 2``). What is read
from the run folder may not leave it through a link.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.errors import FileError, InputError
from recon_cli.geometry.transforms import pose_error, transform_points
from recon_cli.inputs import files
from recon_cli.inputs.jsonschemas import check_pose
from recon_cli.inputs.meshes import CLOUD_SUFFIXES, MESH_SUFFIXES, read_cloud, read_mesh
from recon_cli.objects import BUILTIN, SceneObject, load_object, ycb_names
from recon_cli.perception.sensor import motioncam_3d_m
from recon_cli.randomness import open3d_draws
from recon_cli.reconstruction.evaluation import CameraView, Evaluation, evaluate, histogram_png, signed_distances
from recon_cli.reconstruction.options import SurfaceOptions
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.runs import evaluation as evaluation_file
from recon_cli.runs import sides as sides_file
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
    records = (store.read(i, images=False) for i in store.indices())  # the poses: no image decoded
    return [CameraView(s.world_T_camera_fk, s.intrinsics, z_min, z_max, incidence) for s in records]


def align_icp(points: np.ndarray, reference, distance: float = 0.005, seed: int = 0,
              samples: int = 200_000) -> np.ndarray:
    """Rigid transform taking the points onto the reference surface (point-to-plane ICP;
    the reference sampled at ``samples`` points with Open3D's generator seeded with ``seed``)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).voxel_down_sample(_SURFACE.voxel)
    with open3d_draws(seed):
        tgt = reference.sample_points_uniformly(number_of_points=samples)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=_SURFACE.normal_radius, max_nn=30))
    T = np.eye(4)
    for d in (distance, distance / 2, distance / 5):
        T = reg.registration_icp(src, tgt, d, T, reg.TransformationEstimationPointToPlane(),
                                 reg.ICPConvergenceCriteria(max_iteration=60)).transformation
    return np.asarray(T)


@dataclass(frozen=True)
class TwoSidedRun:
    """A run folder of an object scanned on both sides, as ``recon evaluate`` reads it."""

    folder: Path
    merged: Path  # reconstruction/cloud.ply
    sides: dict[str, np.ndarray]  # side_1, side_2: each side's points (N, 3) in the merged cloud's frame


def _inside_run(path: Path, folder: Path, what: str) -> Path:
    """``path``, refused (FileError) when it is or lies behind a link leading out of the run
    folder: what is read from a run folder lies inside it."""
    link = files.link_out_of(path, folder)
    if link is not None:
        raise FileError(files.outside_text(files.Refusal(files.OUTSIDE, path, 0, root=folder, link=link), what),
                        hint=files.OUTSIDE_HINT)
    return path


def two_sided_run(folder: Path) -> TwoSidedRun:
    """The merged cloud and both sides' points of a two-sided run folder (FileError or
    MetadataError, one line, when its sides were not merged, a file is missing or broken,
    or a file is reached through a link leading out of the folder)."""
    folder = Path(folder)
    report_path = folder / sides_file.SIDES_REPORT
    if not (report_path.exists() or report_path.is_symlink()):
        raise FileError(f"{folder} is a folder but not a two-sided run (no {sides_file.SIDES_REPORT})",
                        hint="give a cloud or mesh file, e.g. RUN/reconstruction/cloud.ply")
    report = sides_file.read(folder, root=folder)
    merged = _inside_run(folder / "reconstruction" / "cloud.ply", folder, "merged cloud")
    if report.cloud is None or not merged.is_file():
        why = f" ({report.error})" if report.error else ""
        raise FileError(f"{folder}: its two sides were not merged{why}",
                        hint="evaluate one side's cloud: side_1/reconstruction/cloud.ply or side_2/...")
    T = report.registration.get("side1_T_side2")
    check_pose(T, report_path, "sides report", "registration.side1_T_side2")
    clouds = (_inside_run(folder / "side_1" / "reconstruction" / "cloud.ply", folder, "side 1 cloud"),
              _inside_run(folder / "side_2" / "reconstruction" / "cloud.ply", folder, "side 2 cloud"))
    return TwoSidedRun(folder, merged, registered_sides(clouds, np.asarray(T, dtype=float)))


def registered_sides(clouds: tuple[Path, Path], side1_T_side2: np.ndarray) -> dict[str, np.ndarray]:
    """Both sides' points (side_1, side_2) from their registered clouds (each in the world
    frame of its side), side 2's moved onto side 1 by the registration of the sides."""
    points = [np.asarray(read_cloud(c, f"side {k + 1} cloud",
                                    hint=f"the run's side_{k + 1}/ is incomplete: run the scan again").points)
              for k, c in enumerate(clouds)]
    return {"side_1": points[0], "side_2": transform_points(side1_T_side2, points[1])}


def side_store(folder: Path, side: int) -> Path | None:
    """The scan store of one side of a two-sided run folder: ``side_k/scans`` of a script
    run, ``side_k`` itself of ``recon autoscan --sides 2`` (each side an autoscan folder,
    which is its own scan store); None when neither holds a session.json."""
    base = Path(folder) / f"side_{side}"
    for store in (base / "scans", base):
        if (store / "session.json").exists() or (store / "session.json").is_symlink():
            return store
    return None


def simulated_object(folder: Path) -> SceneObject | None:
    """The simulated object where side 1 of a two-sided simulation run saw it (the object
    its session names, at the pose it records, as one-sided runs know theirs); None when the
    run was not a simulation of a built-in or YCB object."""
    store = side_store(folder, 1)
    if store is None:
        return None
    _inside_run(store / "session.json", Path(folder), "side 1 session.json")
    session = ScanStore(store).session()
    if (session.backend != "sim" or session.world_T_object is None
            or session.object_name not in (*BUILTIN, *ycb_names())):
        return None
    return replace(load_object(session.object_name), world_T_object=np.asarray(session.world_T_object, dtype=float))


def run_evaluate(reconstruction: Path, reference: Path | None, tolerance: float = 0.001, views: Path | None = None,
                 align: str = "none", samples: int = 200_000, out: Path | None = None,
                 seed: int = 0) -> EvaluateResult:
    """``reconstruction``: a cloud or mesh file, or a two-sided run folder (then ``reference``
    may be None in a simulation: the simulated object). ``seed``: of every sampling (the
    reconstruction when it is a mesh, the reference)."""
    run = two_sided_run(reconstruction) if Path(reconstruction).is_dir() else None
    if run is not None and views is not None:
        raise InputError("--scan-store does not apply to a two-sided run folder: its sides saw the object lying "
                         "two ways", hint="evaluate the coverage of the whole surface (leave out --scan-store)")
    source = run.merged if run is not None else Path(reconstruction)
    points = load_points(source, seed=seed)
    parts = dict(run.sides) if run is not None else {}
    surface = None
    if reference is not None:
        mesh, reference_name = load_mesh(reference), str(reference)
    elif run is not None and (obj := simulated_object(run.folder)) is not None:
        # the whole true surface: the resting faces too, not the faces hidden inside a union of primitives
        mesh, reference_name = obj.mesh_world(), f"the simulated {obj.name}"
        surface = obj.surface_points(samples, np.random.default_rng(seed), exclude_base=-np.inf)
    else:
        raise FileError(f"{reconstruction}: no reference to evaluate against",
                        hint="give --reference MESH (the truth; a simulation run of a built-in or YCB object "
                             "has its own)")
    alignment = None
    T = np.eye(4)
    if align == "icp":
        T = align_icp(points, mesh, seed=seed)
        points = transform_points(T, points)
        parts = {name: transform_points(T, p) for name, p in parts.items()}
        alignment = pose_error(T, np.eye(4))
    cams = camera_views(views) if views is not None else None
    result = evaluate(points, mesh, tolerance, samples, cams, seed=seed, parts=parts, surface=surface)
    out = Path(out or source.parent)
    out.mkdir(parents=True, exist_ok=True)
    stem = source.stem
    hist = out / f"{stem}_distances.png"
    histogram_png(hist, {"both sides" if run is not None else stem: signed_distances(points, mesh),
                         **{name.replace("_", " "): signed_distances(p, mesh) for name, p in parts.items()}},
                  f"{source.name} vs {Path(reference_name).name}")
    report = evaluation_file.write(out, from_json(evaluation_file.EvaluationReport, plain({
        "reconstruction": str(source), "reference": reference_name, "alignment": align,
        "alignment_transform": T if alignment else None, **result.to_dict()})))
    return EvaluateResult(result, alignment, report, hist)
