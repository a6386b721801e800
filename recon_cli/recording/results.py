"""What a registration adds to a recording, and the scans of a store recorded after the fact.

:func:`record_registration` logs, after ``run_register``: the board found in each scan's
image (detected again on the stored image, the same detector the registration used), the
cropped clouds before and after local registration, the mesh and, where the scan store
holds the simulated object, the fused cloud's signed distances to it.
:func:`record_store` records a scan store that was written without a recording
(``recon register --record``): the cell of its session, the robot at each scan's joint
readings, each scan's frustum, images and cloud. :func:`record_sides` records an object's two
sides as their registration by shape put them together.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from recon_cli.errors import FileError, MetadataError
from recon_cli.inputs.meshes import read_cloud, read_mesh
from recon_cli.perception.charuco import detect, recorded_board
from recon_cli.reconstruction.assessment import registered_sides
from recon_cli.reconstruction.evaluation import signed_distances
from recon_cli.reconstruction.global_registration import PoseSource
from recon_cli.reconstruction.scan_store import ScanStore, read_scan
from recon_cli.robot.cell import Cell
from recon_cli.robot.collision import ObjectBox
from recon_cli.robot.description import CellConfig, CellName


def record_registration(recorder, result, store_root: Path,
                        distances: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Board detections, clouds before/after registration, mesh, signed distances (the
    fused cloud's points and their distances when the caller has them, else computed
    against the store's simulated object)."""

    spec = recorded_board(ScanStore(store_root).session().board)
    for rec in result.used:
        if rec.pose is None or not rec.folder:
            continue
        if rec.pose.source is PoseSource.CHARUCO:
            scan = read_scan(Path(store_root) / rec.folder)
            color, _ = scan.pinhole_images()
            if color is not None:
                found = detect(color, spec)
                px = rec.pose.reprojection_px
                recorder.board(rec.index, found.corners, found.marker_corners,
                               f"board: {found.n_corners} corners, {found.marker_count} markers"
                               + (f", pose reprojects to {px:.2f} px" if px is not None else ""))
        else:
            recorder.note(f"scan {rec.index}: pose from {rec.pose.source.value}"
                          + (f" ({rec.pose.reason})" if rec.pose.reason else ""))
    recorder.registration(result)
    if result.mesh is not None:
        recorder.mesh("reconstruction/mesh", read_mesh(result.mesh, "reconstructed mesh", triangles=False))
    if distances is not None:
        recorder.distances(*distances)
        return
    truth = _truth_mesh(Path(store_root))
    if truth is not None:

        points = np.asarray(read_cloud(result.cloud, "fused cloud", points=False).points)
        if len(points):
            recorder.distances(points, signed_distances(points, truth))


def _truth_mesh(store_root: Path):
    """The simulated object of a scan store (ground_truth/<object>.ply), or None."""
    try:
        name = ScanStore(store_root).session().object_name
    except Exception:  # noqa: BLE001 - a store without a readable session has no truth to show
        return None
    path = store_root / "ground_truth" / f"{name}.ply"
    if not name or not path.is_file():
        return None
    try:
        return read_mesh(path, "ground-truth mesh")
    except FileError:  # a broken truth file is left out, as a missing one
        return None


def record_store(recorder, store_root: Path) -> int:
    """The cell of a scan store's session and each readable scan at its joint readings;
    returns the number of scans recorded (unreadable scans are left out, as registration
    leaves them out)."""

    store = ScanStore(store_root)
    info = store.session()
    box = None if info.object_box is None else ObjectBox(info.object_box.center, info.object_box.size)
    cell = None
    if info.cell_kind is not None:  # stores replayed from other cameras have no cell
        kind, lift = CellName.parse(info.cell_kind), info.table_lift or 0.0
        cfg = CellConfig(kind=kind, table_lift=lift) if info.safety_distance is None else \
            CellConfig(kind=kind, table_lift=lift, safety_distance=info.safety_distance)
        cell = Cell(cfg, object_box=box)
        recorder.cell(cell, None, box, _truth_mesh(store_root))
    count = 0
    for _, folder in store.scan_folders():
        try:
            scan = read_scan(folder)
        except MetadataError as exc:
            recorder.note(f"{folder.name} left out: {exc.one_line()}", level="WARN")
            continue
        if cell is not None and all(name in scan.joints for name in cell.joint_names):
            recorder.configuration(np.array([scan.joints[name] for name in cell.joint_names]))
        recorder.scan(scan)
        recorder.clock += 1.0  # one second between scans on the timeline: their joint readings
        count += 1
    return count


def record_sides(recorder, clouds: tuple[Path, Path], side1_T_side2: np.ndarray, text: str) -> None:
    """Both sides' registered clouds (world frames of their sides), side 2 moved onto side 1."""
    recorder.sides(registered_sides(clouds, np.asarray(side1_T_side2, dtype=float)), text)
