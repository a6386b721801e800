"""Registration benchmark of thesis section 4.2 (``recon bench registration``).

The model-based scenario of eq. 4.1: 24 views around the drill (the built-in bottle when the
YCB data is absent), f = (0, 0, 0.78) m, r = 0.6 m, scanned in simulation with the board
covered in two views (kinematic fallback). Then, on the same scans:

- Table 4.2: translation and rotation error of every ChArUco camera pose;
- the fused cloud against the ground-truth mesh for global registration only and after the
  pose graph (loop closures by ICP, ours; and by the global alignment, the thesis' choice);
- the poses of forward kinematics alone (every scan, board ignored), global registration;
- with the ``ideal`` realism profile: the same with every global pose moved by the thesis'
  mean ChArUco errors (1.532 mm, 0.0853 deg) in random directions: the ideal camera has
  exact intrinsics, so its board poses are far better than the thesis' calibrated Gazebo
  camera. Other profiles (``--realism thesis``) make the errors themselves, with a camera
  that differs from the one recon is told about and a robot that differs from its model,
  and skip these cases.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
from recon_cli.geometry.transforms import pose_error
from recon_cli.inputs.meshes import read_cloud, read_mesh
from recon_cli.perception.sensor import motioncam_3d_m
from recon_cli.realism import IDEAL, RealismProfile
from recon_cli.reconstruction.assessment import run_evaluate
from recon_cli.reconstruction.evaluation import histogram_png, signed_distances
from recon_cli.reconstruction.options import COVERAGE_TOLERANCE
from recon_cli.reconstruction.pipeline import RegisterOptions, RegisterResult, run_register
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.session import resolve_object_name
from recon_cli.thesis import eq_4_1_views
from recon_cli.workflows.capture import CaptureOptions, run_capture

THESIS_CHARUCO_ERROR = (1.532e-3, np.radians(0.0853))  # Table 4.2 means [m, rad]
COVERED_VIEWS = frozenset({5, 17})


@dataclass(frozen=True)
class CaseRow:
    case: str
    perturbed: bool
    local: str  # none | icp | global (loop-closure initialization)
    mean_mm: float
    std_mm: float
    within_half_mm: float
    coverage_visible: float | None  # None without camera views
    coverage: float
    pose_error_mm: float  # mean final camera pose error vs truth
    pose_error_deg: float
    relative_error_mm: float  # relative to the first scan (what local registration fixes)
    relative_error_deg: float
    seconds: float


CASES = (  # name, perturbed, local registration
    ("global only", False, "none"), ("pose graph (ICP loop closures)", False, "icp"),
    ("pose graph (thesis: global loop closures)", False, "global"),
    ("perturbed, global only", True, "none"), ("perturbed, pose graph (ICP loop closures)", True, "icp"),
    ("perturbed, pose graph (thesis)", True, "global"),
)
KINEMATICS_CASE = "kinematics only, global only"  # every pose from forward kinematics


def run_registration_bench(out: Path, object_name: str = "auto", seed: int = DEFAULTS.seed,
                           resolution: float = DEFAULTS.sensor.resolution,
                           progress: Callable[[str, int, int], None] | None = None,
                           realism: RealismProfile = IDEAL) -> dict:
    object_name = resolve_object_name(object_name)
    scans = out / "scans"
    config = DEFAULTS.replace(scene=SceneConfig(object_name), seed=seed,
                              sensor=SensorConfig(DEFAULTS.sensor.noise, resolution), realism=realism)
    cases = [c for c in CASES if realism.is_ideal or not c[1]] + [(KINEMATICS_CASE, False, "none")]
    capture = run_capture(CaptureOptions(views=tuple(eq_4_1_views()), out=scans, config=config,
                                         cover_board=COVERED_VIEWS, run={"command": "bench registration"},
                                         page=False),
                          progress)
    reference = scans / "ground_truth" / f"{capture.scene_object.name}.ply"
    rows, results = [], {}
    for k, (name, perturbed, local) in enumerate(cases):
        base = RegisterOptions(local=local != "none", mesh=local == "icp" and not perturbed,
                               perturb=THESIS_CHARUCO_ERROR if perturbed else None,
                               use_board=name != KINEMATICS_CASE)
        opts = replace(base, multiway=replace(base.multiway, loop_closure_init=local if local != "none" else "icp"))
        result = run_register(scans, out / f"case_{k}", opts, seed=seed)
        ev = run_evaluate(result.cloud, reference, COVERAGE_TOLERANCE, scans, samples=200_000,
                          out=out / f"case_{k}").evaluation
        errors = [r.pose_errors() for r in result.used]
        rows.append(CaseRow(name, perturbed, local, ev.mean * 1e3, ev.std * 1e3, ev.within["±0.5 mm"],
                            ev.coverage_visible, ev.coverage,
                            float(np.mean([e["final"][0] for e in errors]) * 1e3),
                            float(np.degrees(np.mean([e["final"][1] for e in errors]))),
                            float(np.mean([e["final_relative"][0] for e in errors]) * 1e3),
                            float(np.degrees(np.mean([e["final_relative"][1] for e in errors]))),
                            result.timings["total_s"]))
        results[name] = result
        if progress:
            progress("registration cases", k + 1, len(cases))
    first: RegisterResult = results[CASES[0][0]]
    kinematic = _kinematic_errors(scans)
    table_4_2 = [{"scan": r.index + 1, "source": r.placed_pose.source.value, "corners": r.placed_pose.corners,
                  "translation_mm": None if r.charuco_error is None else r.charuco_error[0] * 1e3,
                  "rotation_deg": None if r.charuco_error is None else float(np.degrees(r.charuco_error[1])),
                  "kinematics_translation_mm": kinematic.get(r.index, (None, None))[0],
                  "kinematics_rotation_deg": kinematic.get(r.index, (None, None))[1]}
                 for r in first.scans]
    mesh = read_mesh(reference, "reference mesh")
    curves = {}
    for name in ("global only", "pose graph (ICP loop closures)", "perturbed, global only",
                 "perturbed, pose graph (ICP loop closures)", KINEMATICS_CASE):
        if name not in results:
            continue
        pts = np.asarray(read_cloud(results[name].cloud, "fused cloud").points)
        curves[name] = signed_distances(pts, mesh)
    histogram_png(out / "distances.png", curves, f"eq. 4.1, 24 views of the {capture.scene_object.name}: "
                  "fused cloud vs ground truth", limit=0.003)
    found = [t for t in table_4_2 if t["translation_mm"] is not None]
    return {
        "object": capture.scene_object.name, "views": len(capture.scans), "resolution": resolution,
        "realism": realism.summary(),
        "covered_views": sorted(COVERED_VIEWS), "capture_s": capture.total_seconds,
        "noise_sigma_at_0.6m_mm": float(motioncam_3d_m().sigma(np.asarray(0.6)) * 1e3),
        "table_4_2": table_4_2,
        "charuco_mean": {"translation_mm": float(np.mean([t["translation_mm"] for t in found])),
                         "rotation_deg": float(np.mean([t["rotation_deg"] for t in found]))},
        "kinematics_mean": {"translation_mm": float(np.mean([v[0] for v in kinematic.values()])),
                            "rotation_deg": float(np.mean([v[1] for v in kinematic.values()]))},
        "thesis_charuco_mean": {"translation_mm": 1.532, "rotation_deg": 0.0853},
        "cases": rows, "mesh": str(results["pose graph (ICP loop closures)"].mesh),
    }


def _kinematic_errors(scans: Path) -> dict[int, tuple[float, float]]:
    """Per scan index: camera pose from forward kinematics of the measured joints against
    the true camera pose [mm, deg] (simulation ground truth)."""
    out = {}
    for scan in ScanStore(scans):
        if scan.ground_truth:
            dp, dr = pose_error(scan.world_T_camera_fk, np.asarray(scan.ground_truth["world_T_camera"], float))
            out[scan.index] = (dp * 1e3, float(np.degrees(dr)))
    return out
