"""``recon register``: scan store folder -> globally and locally registered, fused cloud and
Poisson mesh, with a JSON report (thesis 2.4.2-2.4.3, 3.2).

Steps: global pose of every scan (ChArUco, else kinematics); back-projection and cropping
with the object box (removes table and board); normals toward each camera; pose-graph
local registration; fusion; Poisson with density trimming. The fused cloud of the global
registration alone is written too (``cloud_global.ply``), so the gain of the local step can
be measured. Outputs are in the world frame when the session knows the marker's world pose
(the cell's calibration), else in the marker frame; the report says which.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from recon_cli.errors import FileError, InputError, MetadataError, ReconError
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.outputs import OutputFolder
from recon_cli.perception.charuco import recorded_board
from recon_cli.randomness import DEFAULT_SEED
from recon_cli.reconstruction.crop import CropBox, box_pixels, crop_cloud
from recon_cli.reconstruction.global_registration import (
    GlobalPose,
    PoseSource,
    corrected_pose,
    global_pose,
    kinematic_correction,
)
from recon_cli.reconstruction.metadata import SessionInfo
from recon_cli.reconstruction.options import RegisterOptions
from recon_cli.reconstruction.pose_graph import MultiwayResult, register_multiway
from recon_cli.reconstruction.scan_store import ScanStore, read_scan
from recon_cli.reconstruction.surface import (
    SurfaceOptions,
    fuse,
    oriented_cloud,
    poisson_mesh,
    write_cloud,
    write_mesh,
)
from recon_cli.runs import register as reg_file
from recon_cli.runs.codec import from_json, matrix, plain

Progress = Callable[[str, int, int], None]


@dataclass
class ScanRecord:
    index: int
    pose: GlobalPose | None
    points: int = 0  # after cropping
    skipped: str = ""  # why the scan is not in the result
    charuco_error: tuple[float, float] | None = None  # [m, rad] vs simulation ground truth
    final_marker_T_camera: np.ndarray | None = None
    true_marker_T_camera: np.ndarray | None = None  # simulation only (evaluation)
    folder: str = ""  # the scan's folder name in the store

    gauge: dict[str, np.ndarray] = field(default_factory=dict)  # see _set_gauges

    @property
    def placed_pose(self) -> GlobalPose:
        """The global pose of a scan that has one (every scan that is not skipped)."""
        if self.pose is None:
            raise ValueError(f"scan {self.index} has no global pose")
        return self.pose

    def pose_errors(self) -> dict[str, tuple[float, float]]:
        """[m, rad] against the truth (simulation only) of the global and the final pose, and
        of both relative to the first registered scan ("global_relative", "final_relative":
        the scan set moved as a whole so that the first scan is exact; local registration
        keeps the first scan fixed, so this is the error it can remove)."""
        if self.true_marker_T_camera is None or self.pose is None or self.final_marker_T_camera is None:
            return {}
        out = {"global": pose_error(self.pose.marker_T_camera, self.true_marker_T_camera),
               "final": pose_error(self.final_marker_T_camera, self.true_marker_T_camera)}
        if self.gauge:
            out["global_relative"] = pose_error(self.gauge["global"] @ self.pose.marker_T_camera,
                                                self.true_marker_T_camera)
            out["final_relative"] = pose_error(self.gauge["final"] @ self.final_marker_T_camera,
                                               self.true_marker_T_camera)
        return out


    @property
    def name(self) -> str:
        return self.folder or f"scan {self.index}"

    def to_dict(self) -> dict:
        d = {"scan": self.index, "folder": self.folder or None, "points": self.points, "skipped": self.skipped or None,
             "pose": None if self.pose is None else self.pose.to_dict(),
             "final_marker_T_camera": self.final_marker_T_camera}
        if self.charuco_error is not None:
            d["charuco_error"] = {"translation_mm": self.charuco_error[0] * 1e3,
                                  "rotation_deg": float(np.degrees(self.charuco_error[1]))}
        for name, (dp, dr) in self.pose_errors().items():
            d[f"{name}_pose_error"] = {"translation_mm": dp * 1e3, "rotation_deg": float(np.degrees(dr))}
        return d


def final_camera(record: ScanRecord) -> np.ndarray:
    """Where the scan's camera was (marker frame): its final pose, else its placed one."""
    T = record.final_marker_T_camera if record.final_marker_T_camera is not None \
        else record.placed_pose.marker_T_camera
    return np.asarray(T, dtype=float)[:3, 3].copy()


def _set_gauges(used: list[ScanRecord]) -> None:
    ref = used[0]
    if ref.true_marker_T_camera is None or ref.final_marker_T_camera is None:
        return
    gauge = {"global": ref.true_marker_T_camera @ invert(ref.placed_pose.marker_T_camera),
             "final": ref.true_marker_T_camera @ invert(ref.final_marker_T_camera)}
    for r in used:
        r.gauge = gauge


@dataclass
class RegisterResult:
    folder: Path  # the output folder
    cloud: Path
    cloud_global: Path
    mesh: Path | None
    report: Path
    frame: str
    scans: list[ScanRecord]
    multiway: MultiwayResult | None
    timings: dict[str, float]
    clouds: list = field(default_factory=list)  # registered per-scan clouds (marker frame, no normals)
    out_T_marker: np.ndarray = field(default_factory=lambda: np.eye(4))  # marker -> output frame
    fused: Any = None  # the fused cloud of cloud.ply (marker frame)
    surface: SurfaceOptions = field(default_factory=SurfaceOptions)  # what fused it

    def fused_with(self, surface: SurfaceOptions):
        """The scans fused with ``surface``: the fused cloud at hand when those options fuse
        like the registration's own (a copy), else fused anew."""
        import open3d as o3d

        if self.fused is not None and surface.fuses_like(self.surface):
            return o3d.geometry.PointCloud(self.fused)
        return fuse(self.clouds, surface, self.cameras)

    @property
    def used(self) -> list[ScanRecord]:
        return [s for s in self.scans if not s.skipped]

    @property
    def cameras(self) -> list[np.ndarray]:
        """The camera position of each of :attr:`clouds` (marker frame, final poses)."""
        return [final_camera(r) for r in self.used]

    @property
    def pose_sources(self) -> dict[str, int]:
        """How many of the registered scans took their pose from each source."""
        return pose_source_counts(self.used)


def pose_source_counts(records: list[ScanRecord]) -> dict[str, int]:
    return {s.value: sum(1 for r in records if r.placed_pose.source is s) for s in PoseSource}


def perturbed(T: np.ndarray, translation: float, rotation: float, rng: np.random.Generator) -> np.ndarray:
    """T moved by ``translation`` [m] and turned by ``rotation`` [rad] about its origin, both
    in uniformly random directions."""
    import cv2

    axis, shift = rng.normal(size=3), rng.normal(size=3)
    out = np.array(T, dtype=float)
    out[:3, :3] = out[:3, :3] @ cv2.Rodrigues(axis / np.linalg.norm(axis) * rotation)[0]
    out[:3, 3] += shift / np.linalg.norm(shift) * translation
    return out


def _crop_box(options: RegisterOptions, session: SessionInfo, world_T_marker: np.ndarray | None) -> CropBox:
    """The crop box in the marker frame."""
    box, frame = options.box, options.box_frame
    if box is None:
        spec = session.crop_box
        if spec is None:
            raise InputError("the session has no crop box", hint="pass --crop-box cx,cy,cz,sx,sy,sz")
        T = np.eye(4)
        T[:3, 3] = spec.center
        box, frame = CropBox(T, spec.size), spec.frame
    if frame == "marker":
        return box
    if world_T_marker is None:
        raise InputError("the crop box is in the world frame but the session has no world_T_marker",
                         hint="give the box in the marker frame (--crop-frame marker)")
    return box.moved(invert(world_T_marker))


class CloudMemo:
    """What a run has made of its scans already, kept for :func:`run_register`: each scan's
    global pose (reused when asked for with the same board, marker pose and options) and its
    cloud (:func:`scan_points`; reused when made with the very same pose and crop box).
    Anything else is made anew. The scans must hold the depth as stored (what
    :func:`read_scan` gives)."""

    def __init__(self) -> None:
        self._clouds: dict[str, tuple[np.ndarray, CropBox | None, Any]] = {}
        self._poses: dict[str, tuple[tuple, GlobalPose | None]] = {}
        self.hits = 0  # poses and clouds reused

    def pose(self, folder: str, scan, board, world_T_marker: np.ndarray | None,
             options: RegisterOptions) -> GlobalPose | None:
        """The scan's global pose (:func:`global_pose` with the options' board settings)."""
        key = _pose_key(board, world_T_marker, options)
        known = self._poses.get(folder)
        if known is not None and known[0] == key:
            self.hits += 1
            return known[1]
        pose = global_pose(scan, board, world_T_marker, options.min_corners, options.use_board,
                           options.max_reprojection_px, options.board_plane, options.max_board_sigma)
        self._poses[folder] = (key, pose)
        return pose

    def has(self, folder: str, board, world_T_marker: np.ndarray | None, options: RegisterOptions) -> bool:
        """Whether the scan's pose (with these board settings) and a cloud at that pose are
        known: then its images need not be read."""
        known = self._poses.get(folder)
        if known is None or known[0] != _pose_key(board, world_T_marker, options) or known[1] is None:
            return False
        cloud = self._clouds.get(folder)
        return cloud is not None and np.array_equal(cloud[0], known[1].marker_T_camera)

    def keep(self, scan, options: RegisterOptions, session: SessionInfo) -> None:
        """Make a scan just stored now (its images in memory, the depth as stored) what
        :func:`run_register` of its store with ``options`` will ask for: its global pose and
        its cropped cloud, so that the registration need not read its images."""
        if scan.path is None:
            return
        try:
            box = crop_box_marker(options, session)
            pose = self.pose(scan.path.name, scan, options.board or recorded_board(session.board),
                             session.world_T_marker, options)
        except ReconError:
            return  # the registration meets it again, and reports it where it belongs
        if pose is not None:
            self.put(scan.path.name, pose.marker_T_camera, box, scan_points(scan, pose, box))

    def put(self, folder: str, marker_T_camera: np.ndarray, box: CropBox | None, cloud) -> None:
        import open3d as o3d

        self._clouds[folder] = (np.array(marker_T_camera, dtype=float), box, o3d.geometry.PointCloud(cloud))

    def get(self, folder: str, marker_T_camera: np.ndarray, box: CropBox | None):
        """A copy of the scan's cloud made with these inputs, or None."""
        import open3d as o3d

        known = self._clouds.get(folder)
        if known is None or not np.array_equal(known[0], marker_T_camera) or not _same_box(known[1], box):
            return None
        self.hits += 1
        return o3d.geometry.PointCloud(known[2])


def _pose_key(board, world_T_marker: np.ndarray | None, options: RegisterOptions) -> tuple:
    return (board, None if world_T_marker is None else np.asarray(world_T_marker, float).tobytes(),
            options.min_corners, options.use_board, options.max_reprojection_px, options.board_plane,
            options.max_board_sigma)


def _same_box(a: CropBox | None, b: CropBox | None) -> bool:
    if a is None or b is None:
        return a is b
    return np.array_equal(a.frame_T_box, b.frame_T_box) and tuple(a.size) == tuple(b.size) \
        and a.support_margin == b.support_margin


def scan_points(scan, pose: GlobalPose, box: CropBox | None):
    """A scan's points (and colours) in the marker frame, placed by its global pose and
    cropped to the box (when given). No normals: :func:`fuse` estimates those on the fused
    cloud, from the scans' camera positions."""
    if box is not None:
        scan = in_box_pixels(scan, box, pose.marker_T_camera)
    cloud = scan.to_open3d_cloud(pose.marker_T_camera)
    if box is not None:
        cloud = crop_cloud(cloud, box)
    return cloud


def scan_cloud(scan, pose: GlobalPose, box: CropBox | None, surface: SurfaceOptions):
    """:func:`scan_points` with the scan's own normals, turned toward its camera (a cloud
    that stands alone: a script's fragment)."""
    return oriented_cloud(scan_points(scan, pose, box), pose.marker_T_camera[:3, 3], surface)


def in_box_pixels(scan, box: CropBox, marker_T_camera: np.ndarray):
    """The scan cut to the image rectangle where the box (marker frame) can appear: its
    pinhole images (undistorted), the principal point moved with the cut. Cropping it gives
    the same points as cropping the whole scan, from a fraction of the pixels."""
    rect = box_pixels(box, invert(marker_T_camera), scan.intrinsics)
    if rect is None or rect[2] <= rect[0] or rect[3] <= rect[1]:
        return scan
    u0, v0, u1, v1 = rect
    color, depth = scan.pinhole_images()
    K = scan.intrinsics
    return replace(scan, color=None if color is None else color[v0:v1, u0:u1], depth=depth[v0:v1, u0:u1],
                   intrinsics=replace(K, width=u1 - u0, height=v1 - v0, cx=K.cx - u0, cy=K.cy - v0),
                   distortion=None)


def read_ahead(read: Callable[[Path], Any], folders: list[Path]) -> Iterator[Callable[[], Any]]:
    """``read`` of each folder in turn, the next one read beside the caller (a PNG decodes
    without the interpreter lock) while it works on this one: yields, in order, what gives
    each result (or raises its error)."""
    if not folders:
        return
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="scan-reader") as pool:
        ahead = pool.submit(read, folders[0])
        for folder in folders[1:]:
            current, ahead = ahead, pool.submit(read, folder)
            yield current.result
        yield ahead.result


def crop_box_marker(options: RegisterOptions, session: SessionInfo) -> CropBox:
    """The crop box of a session (or of the options) in the marker frame."""
    return _crop_box(options, session, session.world_T_marker)


def run_register(folder: Path, out: Path | OutputFolder, options: RegisterOptions = RegisterOptions(),  # noqa: B008
                 progress: Progress | None = None, *, seed: int = DEFAULT_SEED,
                 memo: CloudMemo | None = None) -> RegisterResult:
    """Register the scan store ``folder`` into ``out`` (a folder, or one a command claimed:
    it is made, and what ``--force`` removes is removed, only when there is something to
    write). Scans that cannot be read, or that are links out of the store, are skipped with
    their reason. ``seed``: the run's seed (Config.seed), of the ``perturb`` directions.
    ``memo``: clouds the caller made of these scans already (see :class:`CloudMemo`)."""

    t0 = time.perf_counter()
    step = progress or (lambda *a: None)
    folder = Path(folder)
    if not folder.is_dir():
        raise FileError(f"{folder} is not a folder", hint="point to a scan store (a folder of scan_NNNN)")
    store = ScanStore(folder)
    scan_folders = store.scan_folders()
    if not scan_folders:
        raise FileError(f"{folder} holds no scans (no scan_NNNN folder)",
                        hint="record scans first, e.g. recon capture --views eq-4.1")
    store.check_inside(folder / "session.json")
    session = store.session()
    world_T_marker = session.world_T_marker
    box = _crop_box(options, session, world_T_marker)
    board = options.board or recorded_board(session.board)
    rng = np.random.default_rng(seed)

    # 1. global registration and cropping (per scan)
    records: list[ScanRecord] = []
    cloud_of: dict[int, Any] = {}  # record position -> its cropped cloud

    def add_cloud(pos: int, rec: ScanRecord, scan) -> None:
        known = None if memo is None else memo.get(rec.folder, rec.placed_pose.marker_T_camera, box)
        if known is None and scan.depth.size == 0:  # read without its images: the memo's cloud was for other inputs
            scan = read_scan(folder / rec.folder)
        cloud = known if known is not None else scan_points(scan, rec.placed_pose, box)
        rec.points = len(cloud.points)
        if rec.points < 100:
            rec.skipped = f"{rec.points} points inside the crop box"
        else:
            cloud_of[pos] = cloud

    # kinematic poses wait for the board poses of the session, which correct them
    correct = options.correct_kinematics and options.use_board and options.perturb is None \
        and world_T_marker is not None
    fk: dict[int, np.ndarray] = {}  # record position -> forward-kinematics pose (marker frame)
    deferred: list[tuple[int, Path]] = []
    def read(scan_folder: Path):
        store.check_inside(scan_folder)
        # the images only when the memo does not know the scan's pose and cloud already
        return read_scan(scan_folder, images=memo is None or options.perturb is not None
                         or not memo.has(scan_folder.name, board, world_T_marker, options))

    reads = read_ahead(read, [f for _, f in scan_folders])
    for k, (index, scan_folder) in enumerate(scan_folders):
        try:
            scan = next(reads)()
        except MetadataError as exc:  # a bad scan is skipped with its reason, the others go on
            records.append(ScanRecord(index, None, skipped=exc.one_line(), folder=scan_folder.name))
            step("global registration", k + 1, len(scan_folders))
            continue
        pose = global_pose(scan, board, world_T_marker, options.min_corners, options.use_board,
                           options.max_reprojection_px, options.board_plane, options.max_board_sigma) \
            if memo is None else memo.pose(scan_folder.name, scan, board, world_T_marker, options)
        if pose is not None and options.perturb is not None:
            pose = replace(pose, marker_T_camera=perturbed(pose.marker_T_camera, *options.perturb, rng))
        rec = ScanRecord(index, pose, folder=scan_folder.name)
        records.append(rec)
        if pose is None:
            rec.skipped = "board not found and no world_T_marker for the kinematic fallback"
        else:
            if scan.ground_truth and world_T_marker is not None:
                truth = invert(world_T_marker) @ np.asarray(scan.ground_truth["world_T_camera"], dtype=float)
                rec.true_marker_T_camera = truth
                if pose.source is PoseSource.CHARUCO:  # the board's own pose (thesis Table 4.2)
                    rec.charuco_error = pose_error(pose.source_pose, truth)
            if correct and world_T_marker is not None:
                fk[len(records) - 1] = invert(world_T_marker) @ scan.world_T_camera_fk
            if correct and pose.source is PoseSource.KINEMATICS:
                deferred.append((len(records) - 1, scan_folder))
            else:
                add_cloud(len(records) - 1, rec, scan)
        step("global registration", k + 1, len(scan_folders))
    correction = None
    if deferred:
        pairs = [(records[i].placed_pose.source_pose, fk[i]) for i in fk
                 if records[i].placed_pose.source is PoseSource.CHARUCO and not records[i].skipped]
        correction = kinematic_correction([b for b, _ in pairs], [f for _, f in pairs])
        again = read_ahead(read_scan, [f for _, f in deferred])
        for i, _ in deferred:
            rec, scan = records[i], next(again)()
            if correction is not None:
                rec.pose = corrected_pose(scan, rec.placed_pose, correction.apply(fk[i]), board, options.board_plane)
            add_cloud(i, rec, scan)
    clouds = [cloud_of[i] for i, r in enumerate(records) if not r.skipped]
    used = [r for r in records if not r.skipped]
    if not used:
        reasons = sorted({r.skipped for r in records})
        shown = "; ".join(reasons[:3]) + (f"; and {len(reasons) - 3} more" if len(reasons) > 3 else "")
        raise InputError(f"none of the {len(records)} scans of {folder} can be used ({shown})",
                         hint="check the crop box (--crop-box), the scan files and that the board or joint data "
                              "is recorded")
    t_global = time.perf_counter()

    out = out.make() if isinstance(out, OutputFolder) else Path(out)
    out.mkdir(parents=True, exist_ok=True)
    frame = "world" if world_T_marker is not None else "marker"
    to_out = world_T_marker if world_T_marker is not None else np.eye(4)

    placed = [final_camera(r) for r in used]  # the cameras where the global poses put them
    cloud_global = write_cloud(out / "cloud_global.ply", fuse(clouds, options.surface, placed), to_out)
    step("fuse (global)", 1, 1)

    # 2. local registration
    multiway = None
    if options.local and len(clouds) >= 2:
        if options.multiway.own_normals:  # the pose graph asks for the scans' own normals
            clouds = [oriented_cloud(c, p, options.surface) for c, p in zip(clouds, placed, strict=True)]
        multiway = register_multiway(clouds, options.multiway, progress, placed)
        for c, T in zip(clouds, multiway.poses, strict=True):
            c.transform(T)
        for rec, T in zip(used, multiway.poses, strict=True):
            rec.final_marker_T_camera = T @ rec.placed_pose.marker_T_camera
    else:
        for rec in used:
            rec.final_marker_T_camera = rec.placed_pose.marker_T_camera
    _set_gauges(used)
    t_local = time.perf_counter()

    # 3. surface
    fused = fuse(clouds, options.surface, [final_camera(r) for r in used])  # the final poses
    cloud_path = write_cloud(out / "cloud.ply", fused, to_out)
    mesh_path = None
    if options.mesh:
        mesh, _ = poisson_mesh(fused, options.surface)
        mesh_path = write_mesh(out / "mesh.ply", mesh, to_out)
    step("surface", 1, 1)
    t_end = time.perf_counter()
    timings = {"global_s": t_global - t0, "local_s": t_local - t_global, "surface_s": t_end - t_local,
               "total_s": t_end - t0}
    errors = [r.charuco_error for r in records if r.charuco_error is not None]
    truth = [r.pose_errors() for r in used if r.pose_errors()]

    def mean_error(pairs: list[tuple[float, float]]) -> reg_file.PoseError:
        return reg_file.PoseError(float(np.mean([p[0] for p in pairs]) * 1e3),
                                  float(np.degrees(np.mean([p[1] for p in pairs]))))

    report = reg_file.write(out, reg_file.RegisterReport(
        scan_store=str(folder), frame=frame, world_T_marker=matrix(world_T_marker),
        scans_registered=len(used), scans_skipped=len(records) - len(used),
        crop_box_marker=reg_file.CropBoxRecord(matrix(box.frame_T_box), tuple(map(float, box.size)),
                                               box.support_margin),
        scans=tuple(from_json(reg_file.ScanRegistration, plain(r.to_dict())) for r in records),
        pose_sources=pose_source_counts(used),
        kinematic_correction=None if correction is None else from_json(reg_file.KinematicCorrection,
                                                                         plain(correction.to_dict())),
        charuco_error_mean=mean_error(errors) if errors else None,
        pose_error_mean=None if not truth else from_json(reg_file.PoseErrorMean, {
            name: plain(mean_error([t[name] for t in truth])) for name in truth[0]}),
        pose_graph=None if multiway is None else reg_file.PoseGraph(
            edges=tuple(from_json(reg_file.PairEdge, plain(e.to_dict())) for e in multiway.edges),
            pruned_loop_closures=multiway.pruned,
            odometry_edges=sum(e.kind == "odometry" for e in multiway.edges),
            loop_closures=sum(e.kind == "loop_closure" for e in multiway.edges),
            rejected_edges=sum(e.rejected for e in multiway.edges)),
        points=reg_file.PointCounts(len(fused.points)),
        options=plain({"use_board": options.use_board, "board_plane": options.board_plane,
                       "correct_kinematics": options.correct_kinematics, "local": options.local,
                       "perturb": options.perturb, "multiway": options.multiway, "surface": options.surface}),
        timings=timings,
        outputs=reg_file.RegisterOutputs(cloud_path.name, cloud_global.name,
                                         None if mesh_path is None else mesh_path.name)))
    return RegisterResult(out, cloud_path, cloud_global, mesh_path, report, frame, records, multiway, timings,
                          clouds, to_out, fused, options.surface)
