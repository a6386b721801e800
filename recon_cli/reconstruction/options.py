"""Options of registration and surface reconstruction: board, pose graph, surface.

A light module (numpy only) so that the configuration and the command line can take their
defaults from it without loading Open3D or OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from recon_cli.perception.charuco import BoardSpec
    from recon_cli.reconstruction.crop import CropBox

#: [px] a board pose whose corners reproject worse than this is not trusted (a grazing view
#: of the board: in simulation such a pose was 2.85 mm off at 2.7 px, the good ones < 0.4 px)
MAX_REPROJECTION_PX = 1.0
MAX_BOARD_SIGMA = 0.002  # [m]


@dataclass(frozen=True)
class SurfaceOptions:
    voxel: float = 0.001  # [m] voxel of the fused cloud
    normal_radius: float = 0.004  # [m] neighbourhood of the normal estimation
    # outliers of the fused cloud: "radius" drops points with fewer than outlier_min_points
    # neighbours within outlier_radius voxels (or point spacings, where the cloud is sparser
    # than the voxel; isolated points only); "statistical" is the thesis'
    # filter (outlier_neighbors, outlier_std_ratio sigma of the mean neighbour distance), which
    # also drops whole patches of a face that lies in one layer of the voxel grid while the
    # faces around it straddle two (a box's top face: 4.7 % of the wood block)
    outlier_filter: str = "radius"
    outlier_radius: float = 3.0  # [voxels, or the median point spacing where larger]
    outlier_min_points: int = 4
    outlier_neighbors: int = 50
    outlier_std_ratio: float = 3.0
    poisson_depth: int = 9  # octree depth (thesis: 8)
    density_quantile: float = 0.02  # drop mesh vertices below this quantile of Poisson density


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
        if self.loop_closure_init not in ("icp", "global"):
            raise ValueError(f"loop_closure_init must be 'icp' or 'global', not {self.loop_closure_init!r}")
        if self.method not in ("point_to_plane", "point_to_point", "colored"):
            raise ValueError(f"method must be point_to_plane, point_to_point or colored, not {self.method!r}")
        if self.anchor not in ("prior", "mean", "reference"):
            raise ValueError(f"anchor must be 'prior', 'mean' or 'reference', not {self.anchor!r}")


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
    seed: int = 0
