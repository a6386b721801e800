"""The thesis dialect's named fragments: scans and loaded clouds that the script registers,
merges, down-samples, transforms, exports and deletes by name; display commands
(show, hide, color) are recorded."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from recon_cli.errors import FileError, ReconError
from recon_cli.inputs.images import read_color, read_depth
from recon_cli.inputs.meshes import read_cloud
from recon_cli.perception.charuco import cell_board
from recon_cli.perception.rgbd import rgbd_cloud
from recon_cli.perception.sensor import cell_sensor
from recon_cli.reconstruction.global_registration import global_pose
from recon_cli.reconstruction.options import pair_voxel
from recon_cli.reconstruction.pipeline import crop_box_marker, scan_cloud
from recon_cli.reconstruction.pose_graph import MultiwayOptions, pairwise_icp, prepare, register_multiway
from recon_cli.reconstruction.surface import poisson_mesh, write_cloud, write_mesh
from recon_cli.scripts import commands as C
from recon_cli.scripts.checks import readable_file
from recon_cli.scripts.handlers import handles
from recon_cli.scripts.state import CommandReport, CommandStatus, RunState

_ICP_METHODS = {"point_to_point_icp": "point_to_point", "point_to_plane_icp": "point_to_plane",
                "colored_point_cloud_registration": "colored"}


def make_fragment(state: RunState, name: str, scan, report: CommandReport) -> None:
    """A scan as a fragment: placed by its global pose (board, else kinematics), cropped."""

    if state.fragment_box is None:
        state.fragment_box = crop_box_marker(state.config.registration, state.store.session())
    pose = global_pose(scan, cell_board(state.cell.config.cell_file), state.cell.world_T_marker)
    if pose is None:
        raise ReconError(f"scan {name}: no camera pose (neither the board nor the robot's kinematics gave one)",
                         hint="keep the board in view, or record the robot's joints with the scan")
    state.fragments[name] = scan_cloud(scan, pose, state.fragment_box, state.config.registration.surface)
    report.details.update(fragment=name, pose_source=pose.source.value,
                          fragment_points=len(state.fragments[name].points))


def _fragment(state: RunState, name: str, cmd: C.Command):
    if name not in state.fragments:
        known = ", ".join(sorted(state.fragments)) or "none yet"
        raise ReconError(f"{cmd.source}: no fragment named {name!r} (known: {known})", hint="scan or load it first")
    return state.fragments[name]


def _icp_options(method: str, threshold: float):

    return MultiwayOptions(max_correspondence=threshold, scales=(1.0,), method=_ICP_METHODS[method],
                           voxel=pair_voxel(threshold))


@handles(C.PairRegister)
def pair_register(state: RunState, cmd: C.PairRegister, report: CommandReport) -> None:

    if state.skipped_in_dry_run(report):
        return
    src, tgt = _fragment(state, cmd.source_fragment, cmd), _fragment(state, cmd.target, cmd)
    opts = _icp_options(cmd.method, cmd.threshold)
    result = pairwise_icp(prepare(src, opts.voxel), prepare(tgt, opts.voxel), np.eye(4), opts)
    src.transform(result.transformation)
    report.details.update(fitness=result.fitness, rmse_m=result.inlier_rmse)


@handles(C.Multiway)
def multiway(state: RunState, cmd: C.Multiway, report: CommandReport) -> None:

    if state.skipped_in_dry_run(report):
        return
    names = list(state.fragments)
    if len(names) < 2:
        raise ReconError(f"{cmd.source}: multiway registration needs two fragments or more ({len(names)} now)",
                         hint="scan more views first")
    opts = replace(_icp_options(cmd.method, cmd.threshold), scales=(2.0, 1.0))
    result = register_multiway([state.fragments[n] for n in names], opts)
    for n, T in zip(names, result.poses, strict=True):
        state.fragments[n].transform(T)
    report.details.update(fragments=len(names), edges=len(result.edges), pruned=result.pruned)


@handles(C.AddFragment)
def add(state: RunState, cmd: C.AddFragment, report: CommandReport) -> None:
    import open3d as o3d

    if state.skipped_in_dry_run(report):
        return
    src = _fragment(state, cmd.fragment, cmd)
    target = state.fragments.setdefault(cmd.target, o3d.geometry.PointCloud())
    target += src


@handles(C.Downsample)
def downsample(state: RunState, cmd: C.Downsample, report: CommandReport) -> None:
    if state.skipped_in_dry_run(report):
        return
    frag = _fragment(state, cmd.fragment, cmd)
    if cmd.voxel > 0:
        state.fragments[cmd.fragment] = frag.voxel_down_sample(cmd.voxel)
    report.details.update(points=len(state.fragments[cmd.fragment].points))


@handles(C.TransformFragment)
def transform(state: RunState, cmd: C.TransformFragment, report: CommandReport) -> None:
    if state.skipped_in_dry_run(report):
        return
    _fragment(state, cmd.fragment, cmd).transform(np.asarray(cmd.matrix, dtype=float))


@handles(C.DeleteFragment)
def delete(state: RunState, cmd: C.DeleteFragment, report: CommandReport) -> None:
    if state.skipped_in_dry_run(report):
        return
    _fragment(state, cmd.fragment, cmd)
    del state.fragments[cmd.fragment]


@handles(C.LoadFragment)
def load(state: RunState, cmd: C.LoadFragment, report: CommandReport) -> None:
    import cv2


    if state.skipped_in_dry_run(report):
        return
    if cmd.kind == "point_cloud":
        path = readable_file(state.script, cmd.path_point_cloud, cmd.source, "point cloud")
        cloud = _guarded(cmd, read_cloud, path, "point cloud", hint="check path_point_cloud (a PLY or PCD file)")
    else:
        color_path = readable_file(state.script, cmd.path_color, cmd.source, "colour image")
        depth_path = readable_file(state.script, cmd.path_depth, cmd.source, "depth image")
        depth = _guarded(cmd, read_depth, depth_path, "depth image", hint="check path_depth (a 16-bit PNG)")
        color = _guarded(cmd, read_color, color_path, "colour image", hint="check path_color")
        if color.shape[:2] != depth.shape:
            raise FileError(f"{cmd.source}: depth {depth_path.name} ({depth.shape[1]}x{depth.shape[0]}) and colour "
                            f"{color_path.name} ({color.shape[1]}x{color.shape[0]}) do not match",
                            hint="give a single-channel depth image of the colour image's size")
        sensor = cell_sensor(state.cell.config.cell_file)
        K = sensor.intrinsics(depth.shape[1] / sensor.width)
        cloud = rgbd_cloud(cv2.cvtColor(color, cv2.COLOR_BGR2RGB), depth.astype(np.float64) / sensor.depth_scale, K)
        report.message = f"camera frame; intrinsics and depth scale of the cell's sensor ({sensor.name})"
    state.fragments[cmd.name] = cloud
    report.details.update(points=len(cloud.points))


def _guarded(cmd, reader, path, what: str, **kw):
    """A file through its guarded reader; a refusal names the script line."""
    try:
        return reader(path, what, **kw)
    except FileError as exc:
        raise FileError(f"{cmd.source}: {exc.message}", hint=exc.hint) from None


@handles(C.ExportFragment)
def export(state: RunState, cmd: C.ExportFragment, report: CommandReport) -> None:
    import open3d as o3d


    if state.skipped_in_dry_run(report):
        return
    frag = _fragment(state, cmd.fragment, cmd)
    T = state.cell.world_T_marker if state.store is not None else None  # scans are in the marker frame
    target = state.out_path(cmd.path, cmd, report)
    if cmd.kind == "point_cloud":
        write_cloud(target, frag, T)
    else:
        cloud = o3d.geometry.PointCloud(frag)
        surface = state.config.registration.surface
        if not cloud.has_normals():
            cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=surface.normal_radius, max_nn=30))
            cloud.orient_normals_consistent_tangent_plane(20)
        mesh, _ = poisson_mesh(cloud, surface)
        write_mesh(target, mesh, T)
    state.outputs[f"export_{cmd.fragment}_{cmd.kind}"] = str(target)


@handles(C.Display)
def display(state: RunState, cmd: C.Display, report: CommandReport) -> None:
    report.status = CommandStatus.RECORDED
