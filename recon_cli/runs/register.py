"""``report.json`` of ``recon register`` (schemas/register_report.schema.json), also inside
the ``reconstruction/`` folder of a script run or an autoscan: the scan store and output
frame, one row per scan (its global pose and where it came from, its points, why it was
skipped, its errors against the truth in simulation), the kinematic correction, the pose
graph's edges, the options, timings and output files."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.errors import MetadataError
from recon_cli.inputs.jsonfile import load_json
from recon_cli.runs.codec import OMIT_NONE, JsonValue, Matrix, key
from recon_cli.runs.files import read_model, target, write_model

REGISTER_REPORT = "report.json"
SCHEMA = "register_report.schema.json"


@dataclass(frozen=True)
class PoseError:
    """A pose against the truth (or the board's against the truth)."""

    translation_mm: float
    rotation_deg: float


@dataclass(frozen=True)
class GlobalPose:
    """The global registration of one scan: from the ChArUco board, else kinematics."""

    scan: int
    source: str  # charuco | kinematics
    corners: int | None = None  # ChArUco corners found
    reprojection_px: float | None = None
    reason: str = ""  # why the board was not used
    marker_T_camera: Matrix | None = None
    unrefined_marker_T_camera: Matrix | None = None  # before the board-plane refinement
    board_plane_points: int | None = None


@dataclass(frozen=True)
class ScanRegistration:
    """One scan's row (``scans``)."""

    scan: int
    folder: str | None = None  # scan_NNNN
    points: int = 0  # after cropping
    skipped: str | None = None  # why the scan is not in the result
    pose: GlobalPose | None = None
    final_marker_T_camera: Matrix | None = None
    charuco_error: PoseError | None = field(default=None, metadata=OMIT_NONE)  # the board's pose vs the truth
    global_pose_error: PoseError | None = field(default=None, metadata=OMIT_NONE)  # global pose vs the truth
    final_pose_error: PoseError | None = field(default=None, metadata=OMIT_NONE)  # registered pose vs the truth
    # both relative to the first registered scan (the scan set moved so that it is exact)
    global_relative_pose_error: PoseError | None = field(default=None, metadata=OMIT_NONE)
    final_relative_pose_error: PoseError | None = field(default=None, metadata=OMIT_NONE)

    @property
    def name(self) -> str:
        return self.folder or f"scan_{self.scan:04d}"


@dataclass(frozen=True)
class CropBoxRecord:
    marker_T_box: Matrix
    size: tuple[float, ...]  # [m]
    support_margin: float | None = None  # [m]


@dataclass(frozen=True)
class KinematicCorrection:
    """The correction of forward-kinematics poses fitted to the board poses."""

    marker_T_model: Matrix
    camera_T_model: Matrix
    scans: int
    board_vs_kinematics_mm: float
    board_vs_corrected_mm: float


@dataclass(frozen=True)
class PoseErrorMean:
    """Mean pose errors against the truth of the registered scans (simulation)."""

    global_: PoseError | None = field(default=None, metadata={**key("global"), **OMIT_NONE})
    final: PoseError | None = field(default=None, metadata=OMIT_NONE)
    global_relative: PoseError | None = field(default=None, metadata=OMIT_NONE)
    final_relative: PoseError | None = field(default=None, metadata=OMIT_NONE)


@dataclass(frozen=True)
class PairEdge:
    """One pairwise ICP result of the pose graph; ``source``/``target`` index the registered
    scans in their order."""

    source: int
    target: int
    kind: str  # odometry | loop_closure
    rejected: bool = False
    correspondences: int | None = None
    fitness: float | None = None  # share of source points with a correspondence
    rmse_m: float | None = None  # inlier RMSE [m]
    transformation: Matrix | None = None  # source -> target


@dataclass(frozen=True)
class PoseGraph:
    edges: tuple[PairEdge, ...] = ()
    pruned_loop_closures: int | None = None
    odometry_edges: int | None = None
    loop_closures: int | None = None
    rejected_edges: int | None = None


@dataclass(frozen=True)
class PointCounts:
    fused: int | None = None


@dataclass(frozen=True)
class RegisterOutputs:
    """File names beside the report."""

    cloud: str | None = None
    cloud_global: str | None = None
    mesh: str | None = None


@dataclass(frozen=True)
class RegisterReport:
    """``report.json`` of a registration."""

    scan_store: str | None = None  # as given on the command line
    frame: str = ""  # world | marker
    world_T_marker: Matrix | None = None
    scans_registered: int | None = None
    scans_skipped: int | None = None
    crop_box_marker: CropBoxRecord | None = None
    scans: tuple[ScanRegistration, ...] = ()
    pose_sources: Mapping[str, int] = field(default_factory=dict)  # charuco, kinematics -> scans
    kinematic_correction: KinematicCorrection | None = None
    charuco_error_mean: PoseError | None = None
    pose_error_mean: PoseErrorMean | None = None
    pose_graph: PoseGraph | None = None
    points: PointCounts | None = None
    options: Mapping[str, JsonValue] = field(default_factory=dict)  # the registration options
    timings: Mapping[str, float] = field(default_factory=dict)  # global_s, local_s, surface_s, total_s
    outputs: RegisterOutputs | None = None

    @property
    def registered(self) -> tuple[ScanRegistration, ...]:
        """The scans in the result, in the order the pose graph's edges index them."""
        return tuple(s for s in self.scans if not s.skipped)


def write(folder: Path, report: RegisterReport) -> Path:
    """``folder/report.json``."""
    return write_model(Path(folder) / REGISTER_REPORT, report)


def read(folder_or_path: Path, root: Path | None = None) -> RegisterReport:
    """The registration report of a folder (or the file); a MetadataError when it cannot be
    read or does not match its schema.
    ``root``: the run folder it belongs to (default: the folder that holds it), which it
    may not leave through a link."""
    path = target(folder_or_path, REGISTER_REPORT)
    return read_model(path, RegisterReport, SCHEMA, path.name, root)


def is_registration(path: Path) -> bool:
    """Whether ``path`` is a registration's report.json (it lists its scans); a file that
    cannot be read counts, so that its folder's page can say why."""

    path = Path(path)
    try:
        data = load_json(path, path.name, root=path.parent)
    except MetadataError:
        return path.is_file()
    return isinstance(data, dict) and isinstance(data.get("scans"), list)
