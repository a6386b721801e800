"""A replay session: a recorded RGB-D sequence re-processed by recon's registration.

The recording (a folder of colour/depth images with camera poses, or a scan store) is
imported as a scan store whose kinematic poses are the recorded ones
(``recon_cli.backends.hardware.replay.import_recording``), registered as ``recon register
--no-board`` does (global poses from the recording, pose graph, fusion), and the fused
cloud's consistency is measured: the overlap residual of consecutive frames before and
after the pose graph (``recon_cli.reconstruction.consistency``). Output folder::

    <out>/store/              the imported scan store
    <out>/reconstruction/     cloud.ply, cloud_global.ply, (mesh.ply), report.json
    <out>/consistency.json    residuals per pair and their summary, before and after
    <out>/cloud.png           the fused cloud, seen from behind the first camera and from above

The registration settings are those of ``recon register`` scaled to the recording: a room
seen by a structured-light RGB-D camera at 1-9 m has centimetre noise and point spacing, not
the tabletop scanner's tenths of a millimetre; ``voxel`` sets that scale and ``prior`` how
far the recorded poses may be off.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from recon_cli.backends.hardware.replay import ImportedRecording, ReplayConfig, import_recording
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.inputs.meshes import read_cloud
from recon_cli.outputs import atomic_write, atomic_write_text
from recon_cli.reconstruction.consistency import PairResidual, cloud_png, overlap_residuals, summary
from recon_cli.reconstruction.crop import CropBox
from recon_cli.reconstruction.options import RECORDING_SCALE, MultiwayOptions, RegisterOptions, SurfaceOptions
from recon_cli.reconstruction.pipeline import run_register

if TYPE_CHECKING:
    from recon_cli.reconstruction.pipeline import RegisterResult


@dataclass(frozen=True)
class ReplayOptions:
    """source: the recording; out: the session folder (must not hold a store yet); voxel [m]:
    the registration voxel and finest ICP correspondence distance (the fused cloud's voxel is
    half of it); prior [m, deg]: uncertainty of a recorded pose; crop_box: "auto", (centre,
    size) [m] in the recording's frame, or None (everything); local: run the pose graph;
    mesh: Poisson mesh too; residual_distance [m]: overlap gate of the residuals (default
    RecordingScale.residual_distance_ratio x voxel)."""

    source: ReplayConfig
    out: Path
    voxel: float = RECORDING_SCALE.voxel
    prior: tuple[float, float] = RECORDING_SCALE.prior
    crop_box: str | tuple | None = "auto"
    local: bool = True
    mesh: bool = False
    residual_distance: float | None = None


@dataclass(frozen=True)
class ReplayResult:
    imported: ImportedRecording
    register: RegisterResult
    before: list[PairResidual]  # consecutive frames at the recorded poses
    after: list[PairResidual]  # after the pose graph (same as before without it)
    picture: Path
    report: Path

    @property
    def summary(self) -> dict:
        return {"before": summary(self.before), "after": summary(self.after)}


def register_options(voxel: float, prior: tuple[float, float], local: bool = True, mesh: bool = False,
                     box=None) -> RegisterOptions:
    """``recon register --no-board`` settings at the scale ``voxel`` [m] (see the module
    docstring; the other lengths are RECORDING_SCALE's ratios of it)."""
    r = RECORDING_SCALE
    return RegisterOptions(
        box=box, use_board=False, board_plane=False, local=local, mesh=mesh,
        surface=SurfaceOptions(voxel=voxel * r.surface_ratio, normal_radius=voxel * r.normal_radius_ratio),
        multiway=MultiwayOptions(voxel=voxel, max_correspondence=voxel, overlap_voxel=voxel * r.overlap_ratio,
                                 prior_sigma=prior, point_sigma=voxel / r.point_sigma_divisor))


def camera_correction(record) -> dict:
    """How far the pose graph moved a scan's camera from its recorded pose [mm, deg]."""

    dp, dr = pose_error(record.final_marker_T_camera, record.pose.marker_T_camera)
    return {"scan": record.index, "translation_mm": dp * 1e3, "rotation_deg": float(np.degrees(dr))}


def run_replay(opt: ReplayOptions, progress: Callable[[str, int, int], None] | None = None) -> ReplayResult:
    """Import, register and measure a recording (see the module docstring)."""
    import open3d as o3d


    out = Path(opt.out)
    imported = import_recording(opt.source, out / "store", crop_box=opt.crop_box)
    box = None
    if imported.crop_box is None:  # no crop: a box around everything
        T = np.eye(4)
        box = CropBox(T, (1e4, 1e4, 1e4))
    options = register_options(opt.voxel, opt.prior, opt.local, opt.mesh, box)
    result = run_register(out / "store", out / "reconstruction", options, progress)
    after = result.clouds
    if result.multiway is not None:
        before = []
        for cloud, T in zip(after, result.multiway.poses, strict=True):
            c = o3d.geometry.PointCloud(cloud)
            c.transform(invert(T))
            before.append(c)
    else:
        before = after
    gate = opt.residual_distance or RECORDING_SCALE.residual_distance_ratio * opt.voxel
    residual_voxel = opt.voxel * RECORDING_SCALE.residual_voxel_ratio
    res_before = overlap_residuals(before, gate, voxel=residual_voxel)
    res_after = res_before if before is after else overlap_residuals(after, gate, voxel=residual_voxel)
    first = result.used[0].final_marker_T_camera

    fused = read_cloud(result.cloud, "fused cloud")
    title = (f"{Path(str(opt.source.source)).name}: {len(result.used)} recorded frames, "
             f"{'recorded poses + pose graph' if result.multiway else 'recorded poses'}")
    picture = atomic_write(out / "cloud.png",
                           lambda tmp: cloud_png(tmp, fused, invert(result.out_T_marker @ first), title=title))
    report = out / "consistency.json"
    data = {"source": str(opt.source.source), "frames": len(imported.scans), "voxel_m": opt.voxel,
            "prior": {"translation_m": opt.prior[0], "rotation_deg": opt.prior[1]},
            "residual_gate_m": gate, "crop_box": imported.crop_box,
            "before": {"summary": summary(res_before), "pairs": [r.to_dict() for r in res_before]},
            "after": {"summary": summary(res_after), "pairs": [r.to_dict() for r in res_after]},
            "corrections": [camera_correction(r) for r in result.used],
            "outputs": {"store": "store", "reconstruction": "reconstruction", "picture": picture.name}}
    atomic_write_text(report, json.dumps(data, indent=2) + "\n")
    return ReplayResult(imported, result, res_before, res_after, picture, report)
