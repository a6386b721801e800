"""Options of registration and surface reconstruction: board, pose graph, surface.

A light module (numpy only) so that the configuration and the command line can take their
defaults from it without loading Open3D or OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from recon_cli.errors import InputError

if TYPE_CHECKING:
    from recon_cli.perception.charuco import BoardSpec
    from recon_cli.reconstruction.crop import CropBox

#: [px] a board pose whose corners reproject worse than this is not trusted (a grazing view
#: of the board: in simulation such a pose was 2.85 mm off at 2.7 px, the good ones < 0.4 px)
MAX_REPROJECTION_PX = 1.0
MAX_BOARD_SIGMA = 0.002  # [m]
#: [m] a reference sample closer than this to a reconstruction counts as covered (recon
#: evaluate, a script's <evaluate>, the ground-truth coverage of autoscan and the benchmarks)
COVERAGE_TOLERANCE = 0.001


def _one_of(what: str, value: str, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise InputError(f"{what} {value!r} is not one of {', '.join(allowed)}",
                         hint=f"choose {' or '.join(allowed)}")


def _positive(what: str, value: float, unit: str = " m") -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < float("inf"):
        raise InputError(f"{what} = {value!r}{unit} is not a positive number",
                         hint=f"give {what} in metres, e.g. 0.001")


@dataclass(frozen=True)
class SurfaceOptions:
    voxel: float = 0.001  # [m] voxel of the fused cloud
    normal_radius: float = 0.004  # [m] neighbourhood of the normal estimation
    # outliers of the fused cloud: "radius" drops points with fewer than outlier_min_points
    # neighbours within outlier_radius voxels (or point spacings, where the cloud is sparser
    # than the voxel; isolated points only); "statistical" is the thesis'
    # filter (outlier_neighbors, outlier_std_ratio sigma of the mean neighbour distance), which
    # also drops whole patches of a face that lies in one layer of the voxel grid while the
    # faces around it straddle two (a box's top face: 4.7 % of the wood block); "none" keeps them all
    outlier_filter: str = "radius"
    outlier_radius: float = 3.0  # [voxels, or the median point spacing where larger]
    outlier_min_points: int = 4
    outlier_neighbors: int = 50
    outlier_std_ratio: float = 3.0
    poisson_depth: int = 9  # octree depth (thesis: 8)
    density_quantile: float = 0.02  # drop mesh vertices below this quantile of Poisson density

    def fuses_like(self, other: SurfaceOptions) -> bool:
        """Whether fusion with these options gives what it gives with ``other`` (they differ
        at most in the Poisson surface)."""
        return replace(self, poisson_depth=other.poisson_depth, density_quantile=other.density_quantile) == other

    def __post_init__(self) -> None:
        _positive("surface voxel", self.voxel)
        _positive("surface normal_radius", self.normal_radius)
        _one_of("outlier filter", self.outlier_filter, ("radius", "statistical", "none"))
        if not 0.0 <= self.density_quantile < 1.0:
            raise InputError(f"density quantile {self.density_quantile!r} is outside 0 ... 1",
                             hint="trim a share within 0 ... 0.5, e.g. 0.02")


@dataclass(frozen=True)
class MultiwayOptions:
    voxel: float = 0.0015  # [m] down-sampling of the clouds used for registration
    # [m] finest ICP correspondence distance: larger ones let partly overlapping scans pull
    # each other along their borders (biased by tenths of a millimetre)
    max_correspondence: float = 0.0015
    scales: tuple[float, ...] = (4.0, 2.0, 1.0)  # ICP runs at these multiples of it, in order
    icp_iterations: int = 50  # per scale
    # [rad, m] a Gauss-Newton step of the pairwise ICP smaller than this (rotation and
    # translation) ends a scale (measured: the same poses as 1e-7 rad / 1e-8 m, in a third of
    # the steps)
    icp_tolerance: tuple[float, float] = (1e-5, 5e-6)
    # source points at the coarser scales (a regular subset of the down-sampled cloud; the
    # finest scale uses all: fewer there cost pose accuracy)
    icp_points: int = 1500
    workers: int = 0  # pairs registered at once (threads; 0: one per core)
    min_overlap: float = 0.3  # pair overlaps: correspondences / smaller cloud above this
    overlap_voxel: float = 0.004  # [m] sparser copies on which the overlaps are counted
    # loop closures kept per scan, those of largest overlap (0: every overlapping pair)
    loop_closures_per_scan: int = 0
    loop_closure_init: str = "icp"  # "icp" or "global" (identity, the thesis' choice)
    edge_prune_threshold: float = 0.25
    reference: int = 0  # node kept fixed during the optimization ("reference" anchor)
    # how the graph is tied to the global registration:
    # "prior": every scan keeps an edge to the common frame weighted by the global
    #   registration's uncertainty (prior_sigma); directions the scans' overlaps do not fix
    #   (a rotationally symmetric object turning about its axis) stay where the board put
    #   them, and the set as a whole averages the global poses;
    # "mean": no prior, afterwards the set is moved to agree best with the global poses on
    #   average; "reference": no prior, the reference node keeps its global pose
    anchor: str = "prior"
    prior_sigma: tuple[float, float] = (0.002, 0.1)  # [m, deg] per global pose
    point_sigma: float = 0.0002  # [m] floor of the ICP residual that weights ICP edges
    # a pairwise ICP result that moves the source farther from the global alignment than the
    # global registration's own uncertainty allows (3 sigma of the relative pose of two
    # scans, prior_sigma x sqrt(2)) slid along a symmetry of the overlap and is rejected
    gate: float = 3.0
    normal_agreement: float = 0.99  # cosine: correspondences with normals further apart are dropped
    effective_samples: int = 200  # independent measurements a pairwise overlap is worth
    normal_radius: float = 2.5  # [voxels] neighbourhood of the normals (when estimated)
    # the clouds' own normals averaged per voxel (estimated only where missing) instead of
    # normals estimated on the down-sampled copies: faster, but the per-pixel normals of the
    # noisy full-resolution scans let pairs slide along large flat faces (the wood block's
    # scans ended 1.8 mm apart from 0.16 mm at their board poses), so off by default
    own_normals: bool = False
    rounds: int = 1  # graph built and optimized this many times
    method: str = "point_to_plane"  # pairwise ICP: point_to_plane | point_to_point | colored

    def __post_init__(self) -> None:
        _one_of("loop closure initialization", self.loop_closure_init, ("icp", "global"))
        _one_of("ICP method", self.method, ("point_to_plane", "point_to_point", "colored"))
        _one_of("pose graph anchor", self.anchor, ("prior", "mean", "reference"))
        _positive("registration voxel", self.voxel)
        _positive("registration overlap_voxel", self.overlap_voxel)
        _positive("ICP max_correspondence", self.max_correspondence)
        if not self.scales or any(not 0 < x < float("inf") for x in self.scales):
            raise InputError(f"ICP scales {list(self.scales)} are not positive numbers", hint="e.g. [4, 2, 1]")


#: a script's <pair_register threshold=...>: ICP on copies down-sampled to this share of the
#: correspondence distance, but no finer than MIN_PAIR_VOXEL [m]
PAIR_VOXEL_RATIO = 0.25
MIN_PAIR_VOXEL = 5e-4


def pair_voxel(threshold: float) -> float:
    """[m] the registration voxel of a pairwise ICP with correspondence distance ``threshold``."""
    return max(threshold * PAIR_VOXEL_RATIO, MIN_PAIR_VOXEL)


@dataclass(frozen=True)
class RegisterOptions:
    box: CropBox | None = None  # in the world frame (default: the session's object box)
    box_frame: str = "world"  # frame of ``box``: world | marker
    use_board: bool = True  # False: every pose from kinematics
    min_corners: int = 6
    max_reprojection_px: float = MAX_REPROJECTION_PX  # board poses reprojecting worse: kinematics
    # [m] board poses whose corners fix the camera position worse than this (standard
    # deviation from the corners' configuration and residuals: a few bunched corners) are not
    # trusted either: the pose graph takes every board pose as good to prior_sigma (2 mm)
    max_board_sigma: float = MAX_BOARD_SIGMA
    # shift every global pose along the board normal so that the board in the scan's own
    # depth image lies at z = 0 of the marker frame (the height from metric depth): a camera
    # whose intrinsics are a little off puts its board poses millimetres off along the
    # viewing ray, its depth does not (reconstruction/global_registration.py)
    board_plane: bool = True
    # kinematic (fallback) poses corrected by the session's board poses: a constant error on
    # the world side (robot base) and on the flange side (hand-eye), fitted where both exist
    correct_kinematics: bool = True
    local: bool = True  # pose-graph local registration
    mesh: bool = True
    multiway: MultiwayOptions = field(default_factory=MultiwayOptions)
    surface: SurfaceOptions = field(default_factory=SurfaceOptions)
    board: BoardSpec | None = None
    # evaluation aid: move every global pose by this translation [m] and rotation [rad] in
    # random directions (seeded), e.g. the thesis' ChArUco errors on a simulated camera whose
    # poses are otherwise nearly exact; recorded in the report
    perturb: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        _one_of("box frame", self.box_frame, ("world", "marker"))


@dataclass(frozen=True)
class RecordingScale:
    """The scale a recording is registered at its recorded poses (``recon replay``): hand-held
    and tabletop sensors see centimetres where the cell sees tenths of a millimetre. Every
    length is a ratio of ``voxel``."""

    voxel: float = 0.02  # [m] registration voxel and finest ICP correspondence distance
    prior: tuple[float, float] = (0.05, 2.0)  # [m, deg] uncertainty of a recorded pose
    surface_ratio: float = 0.5  # the fused cloud's voxel
    normal_radius_ratio: float = 3.0  # the fused cloud's normal neighbourhood
    overlap_ratio: float = 2.0  # the sparser copies the overlaps are counted on
    point_sigma_divisor: float = 10.0  # the floor of the ICP residual is voxel / this
    residual_voxel_ratio: float = 0.5  # down-sampling of the clouds the overlap residuals are measured on
    residual_distance_ratio: float = 2.5  # overlap gate of the residuals

    def __post_init__(self) -> None:
        _positive("recording voxel", self.voxel)


RECORDING_SCALE = RecordingScale()
