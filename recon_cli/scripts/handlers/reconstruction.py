"""<register>, <reconstruct>, <export>, <evaluate>: results from all scans of the run (of the
side being scanned, in a script that turns the object over)."""

from __future__ import annotations

import functools
import shutil
from dataclasses import replace
from pathlib import Path

from recon_cli.errors import ReconError
from recon_cli.inputs.meshes import read_mesh
from recon_cli.outputs import atomic_write
from recon_cli.reconstruction.assessment import run_evaluate
from recon_cli.reconstruction.pipeline import run_register
from recon_cli.reconstruction.surface import SurfaceOptions, poisson_mesh, write_cloud, write_mesh
from recon_cli.recording.results import record_registration
from recon_cli.scripts import commands as C
from recon_cli.scripts.checks import readable_file
from recon_cli.scripts.handlers import handles
from recon_cli.scripts.state import CommandReport, RunState


def _copy(source: Path, target: Path) -> None:
    shutil.copyfile(source, target)


def _need_scans(state: RunState, cmd: C.Command) -> None:
    if state.store is None or len(state.store) == 0:
        raise ReconError(f"{cmd.source}: no scans to work on yet", hint="scan before registering")


def register_scans(state: RunState, local=True, board=True, loop_closures="icp", mesh=False, surface=None):

    opts = replace(state.config.registration, local=local, use_board=board, mesh=mesh)
    opts = replace(opts, multiway=replace(opts.multiway, loop_closure_init=loop_closures))
    if surface is not None:
        opts = replace(opts, surface=surface)
    state.registered = run_register(state.store.root, state.side_out / "reconstruction", opts, seed=state.config.seed,
                                    memo=state.memo)
    if state.recorder is not None:

        record_registration(state.recorder, state.registered, state.store.root)
    state.reconstruction = {"cloud": state.registered.cloud, "cloud_global": state.registered.cloud_global}
    return state.registered


@handles(C.Register)
def register(state: RunState, cmd: C.Register, report: CommandReport) -> None:
    if state.skipped_in_dry_run(report):
        return
    _need_scans(state, cmd)
    r = register_scans(state, cmd.local, cmd.board, cmd.loop_closures)
    sources = {k: v for k, v in r.pose_sources.items() if v}
    report.details.update(pose_sources=sources, registered=len(r.used), scans=len(r.scans),
                          seconds_register=r.timings["total_s"])
    state.outputs.update(cloud=str(r.cloud), registration_report=str(r.report))


@handles(C.Reconstruct)
def reconstruct(state: RunState, cmd: C.Reconstruct, report: CommandReport) -> None:

    if state.skipped_in_dry_run(report):
        return
    _need_scans(state, cmd)
    surface = replace(state.config.registration.surface or SurfaceOptions(), voxel=cmd.voxel,
                      poisson_depth=cmd.depth, density_quantile=cmd.trim)
    r = state.registered or register_scans(state, surface=surface)
    fused = r.fused_with(surface)
    folder = state.side_out / "reconstruction"
    cloud = write_cloud(folder / "cloud.ply", fused, r.out_T_marker)
    mesh, _ = poisson_mesh(fused, surface)
    mesh_path = write_mesh(folder / "mesh.ply", mesh, r.out_T_marker)
    if state.recorder is not None:

        state.recorder.mesh("reconstruction/mesh", read_mesh(mesh_path, "reconstructed mesh", triangles=False))
    state.reconstruction.update(cloud=cloud, mesh=mesh_path)
    state.outputs.update(cloud=str(cloud), mesh=str(mesh_path))
    report.details.update(points=len(fused.points), triangles=len(mesh.triangles))


@handles(C.Export)
def export(state: RunState, cmd: C.Export, report: CommandReport) -> None:

    if state.skipped_in_dry_run(report):
        return
    for kind, name in (("cloud", cmd.cloud), ("mesh", cmd.mesh)):
        if not name:
            continue
        if kind not in state.reconstruction:
            raise ReconError(f"{cmd.source}: no {kind} to export yet",
                             hint="put <register/> and <reconstruct/> before <export>")
        source = state.reconstruction[kind]
        target = atomic_write(state.out_path(name, cmd, report), functools.partial(_copy, source))
        state.outputs[f"export_{kind}"] = str(target)


@handles(C.Evaluate)
def evaluate(state: RunState, cmd: C.Evaluate, report: CommandReport) -> None:

    if state.skipped_in_dry_run(report):
        return
    if "cloud" not in state.reconstruction:
        raise ReconError(f"{cmd.source}: nothing reconstructed to evaluate yet",
                         hint="put <register/> (and <reconstruct/>) before <evaluate>")
    if cmd.reference == "ground_truth":
        if state.scene_object is None or state.capabilities is None or not state.capabilities.ground_truth:
            raise ReconError(f"{cmd.source}: ground truth exists only in simulation",
                             hint="give reference=\"path/to/mesh.ply\"")
        reference = state.store.root / "ground_truth" / f"{state.scene_object.name}.ply"
    else:
        reference = readable_file(state.script, cmd.reference, cmd.source, "reference mesh")
    result = run_evaluate(state.reconstruction["cloud"], reference, cmd.tolerance,
                          state.store.root if state.store else None, cmd.align,
                          out=state.side_out / "reconstruction")
    e = result.evaluation
    report.details.update(mean_mm=e.mean * 1e3, std_mm=e.std * 1e3, coverage=e.coverage,
                          coverage_visible=e.coverage_visible, tolerance_mm=e.tolerance * 1e3)
    state.outputs.update(evaluation=str(result.report), histogram=str(result.histogram))
