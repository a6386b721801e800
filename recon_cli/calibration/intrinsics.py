"""Camera calibration from images of a board: intrinsics and lens distortion.

Every image is searched for the board (recon_cli.perception.boards: a ChArUco board's
markers, then the chessboard corners interpolated between them and refined to sub-pixel; a
chessboard's corners; an asymmetric circle grid's centres), each point paired with its
position in OpenCV's board frame, and ``cv2.calibrateCameraExtended`` fits fx, fy, cx, cy
and the distortion coefficients of the chosen model to all views at once. The result says how
well the model explains each view (RMS reprojection error per view [px]) and how well the
data pins each parameter (standard deviations from the fit's covariance).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from recon_cli.calibration.camera_file import CameraCalibration
from recon_cli.errors import InputError, UnknownNameError
from recon_cli.perception.boards import Board, BoardMissing, find_points
from recon_cli.perception.camera_model import Intrinsics

#: corners a view needs to take part (fewer make a poorly conditioned homography)
MIN_CORNERS = 8
#: views a calibration needs at least (OpenCV's minimum is 1; intrinsics with distortion
#: are not determined by fewer than 3 different tilts of the board)
MIN_VIEWS = 3
PARAMETERS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


class DistortionModel(StrEnum):
    """Which of OpenCV's distortion coefficients the fit estimates (the others stay 0)."""

    FULL = "k1k2p1p2k3"  #: radial k1, k2, k3 and tangential p1, p2 (OpenCV's default)
    K1K2P = "k1k2p1p2"  #: without k3 (few views, narrow lenses)
    RADIAL = "k1k2"  #: radial only
    NONE = "none"  #: a pinhole camera

    def flags(self) -> int:
        import cv2

        fixed = {DistortionModel.FULL: 0,
                 DistortionModel.K1K2P: cv2.CALIB_FIX_K3,
                 DistortionModel.RADIAL: cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
                 DistortionModel.NONE: cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
                 | cv2.CALIB_ZERO_TANGENT_DIST}
        return int(fixed[self])

    @classmethod
    def parse(cls, name: str) -> DistortionModel:
        try:
            return cls(str(name).strip().lower())
        except ValueError:
            raise UnknownNameError("distortion model", name, [m.value for m in cls]) from None


@dataclass(frozen=True)
class BoardView:
    """The board's corners found in one image: object_points (N, 3) on the board [m] (OpenCV's
    board frame), image_points (N, 2) [px], ids (N,) the points' indices on the board (ChArUco
    corner ids, else row by row), markers: ArUco markers found (0 for boards without)."""

    name: str
    image_size: tuple[int, int]  # (width, height) [px]
    ids: np.ndarray
    object_points: np.ndarray
    image_points: np.ndarray
    markers: int

    @property
    def corners(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class SkippedImage:
    name: str
    reason: str


def find_board(name: str, image: np.ndarray, board: Board, min_corners: int = MIN_CORNERS
               ) -> BoardView | SkippedImage:
    """The board's points in one RGB (or grey) image, or why the image cannot be used."""
    found = find_points(image, board, min_corners)
    if isinstance(found, BoardMissing):
        return SkippedImage(name, found.reason)
    h, w = image.shape[:2]
    return BoardView(name, (w, h), found.ids.copy(), found.object_points, found.image_points, found.markers)


def find_boards(images: Iterable[tuple[str, np.ndarray]], board: Board, min_corners: int = MIN_CORNERS
                ) -> tuple[list[BoardView], list[SkippedImage]]:
    views: list[BoardView] = []
    skipped: list[SkippedImage] = []
    for name, image in images:
        found = find_board(name, image, board, min_corners)
        if isinstance(found, BoardView):
            views.append(found)
        else:
            skipped.append(found)
    return views, skipped


@dataclass(frozen=True)
class ViewError:
    """Reprojection of one view with the calibrated camera: RMS [px] and the residual of
    every corner (N, 2) [px] (projected - detected)."""

    name: str
    rms: float
    residuals: np.ndarray
    camera_T_board: np.ndarray  # (4, 4) OpenCV board frame in the camera [m]

    @property
    def max(self) -> float:
        return float(np.max(np.linalg.norm(self.residuals, axis=1))) if len(self.residuals) else 0.0


@dataclass(frozen=True)
class IntrinsicsResult:
    """A camera calibration.

    camera: the calibrated intrinsics and distortion
    rms: RMS reprojection error over all corners [px]
    views: per view, in input order
    std: standard deviation of each estimated parameter (fx, fy, cx, cy [px], k1 ... k3)
    skipped: images without a usable board
    model: the distortion model fitted
    """

    camera: CameraCalibration
    rms: float
    views: tuple[ViewError, ...]
    std: dict[str, float]
    skipped: tuple[SkippedImage, ...]
    model: DistortionModel

    @property
    def corners(self) -> int:
        return int(sum(len(v.residuals) for v in self.views))

    def to_dict(self) -> dict:
        return {"camera": self.camera.to_mapping(), "model": self.model.value, "rms_px": self.rms,
                "corners": self.corners, "std": self.std,
                "views": [{"name": v.name, "rms_px": v.rms, "max_px": v.max, "corners": len(v.residuals),
                           "camera_T_board_opencv": v.camera_T_board} for v in self.views],
                "skipped": [{"name": s.name, "reason": s.reason} for s in self.skipped]}


def calibrate_intrinsics(views: list[BoardView], model: DistortionModel = DistortionModel.FULL,
                         skipped: Iterable[SkippedImage] = (), initial: Intrinsics | None = None
                         ) -> IntrinsicsResult:
    """Fit intrinsics and distortion to the board views (all of one image size).

    initial: a starting camera matrix (e.g. the nominal one); None: OpenCV's own
    initialization from the views' homographies."""
    import cv2

    skipped = tuple(skipped)
    if len(views) < MIN_VIEWS:
        why = "; ".join(f"{s.name}: {s.reason}" for s in skipped[:3])
        raise InputError(f"camera calibration needs the board in at least {MIN_VIEWS} images, found it in "
                         f"{len(views)}" + (f" ({why}{', ...' if len(skipped) > 3 else ''})" if why else ""),
                         hint="record more views of the whole board, tilted by 20-45 degrees in different directions "
                              "and placed across the image (check --board-spec for other boards)")
    sizes = {v.image_size for v in views}
    if len(sizes) > 1:
        listed = ", ".join(f"{w} x {h}" for w, h in sorted(sizes))
        raise InputError(f"the board images have different sizes ({listed})",
                         hint="calibrate each image size separately")
    (w, h), = sizes
    obj = [v.object_points.astype(np.float32).reshape(-1, 1, 3) for v in views]
    img = [v.image_points.astype(np.float32).reshape(-1, 1, 2) for v in views]
    flags = int(model.flags())
    K0 = None
    if initial is not None:
        K0 = initial.matrix()
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    # one thread: OpenCV's parallel sums make the result differ in the last digits from run to
    # run, and the same photos give the same numbers every run
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        # OpenCV takes None for "no initial camera matrix"; its stubs do not say so
        rms, K, dist, rvecs, tvecs, std_int, _, _ = cv2.calibrateCameraExtended(
            obj, img, (w, h), K0, np.zeros(5), flags=flags, criteria=criteria)  # type: ignore[arg-type]
    finally:
        cv2.setNumThreads(threads)
    dist = np.asarray(dist, dtype=np.float64).reshape(-1)[:5]
    dist = np.concatenate([dist, np.zeros(5 - len(dist))])
    camera = CameraCalibration(Intrinsics(w, h, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])),
                               tuple(float(v) for v in dist))
    per_view = []
    for v, rvec, tvec in zip(views, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(v.object_points.reshape(-1, 1, 3), rvec, tvec, K, dist)
        res = proj.reshape(-1, 2) - v.image_points
        T = np.eye(4)
        T[:3, :3] = cv2.Rodrigues(rvec)[0]
        T[:3, 3] = np.asarray(tvec).reshape(3)
        per_view.append(ViewError(v.name, float(np.sqrt(np.mean(np.sum(res**2, axis=1)))), res, T))
    std_all = np.asarray(std_int, dtype=np.float64).reshape(-1)
    std = {name: float(std_all[i]) for i, name in enumerate(PARAMETERS) if i < len(std_all)}
    return IntrinsicsResult(camera, float(rms), tuple(per_view), std, skipped, model)


def plot_reprojection(result: IntrinsicsResult, path, title: str = "") -> None:
    """A PNG: per-view RMS reprojection error (bars) and every corner's residual vector
    (scatter, one colour per view)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [1.4, 1]})
    names = [v.name for v in result.views]
    rms = [v.rms for v in result.views]
    cmap = plt.get_cmap("tab20")
    ax1.bar(range(len(rms)), rms, color=[cmap(i % 20) for i in range(len(rms))])
    ax1.axhline(result.rms, color="k", linestyle="--", linewidth=1, label=f"overall RMS {result.rms:.3f} px")
    ax1.set_xticks(range(len(names)))
    ax1.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
    ax1.set_ylabel("RMS reprojection error [px]")
    ax1.set_title("per view")
    ax1.legend(loc="upper right", fontsize=8)
    lim = 0.0
    for i, v in enumerate(result.views):
        ax2.scatter(v.residuals[:, 0], v.residuals[:, 1], s=6, color=cmap(i % 20), alpha=0.8)
        lim = max(lim, float(np.max(np.abs(v.residuals))) if len(v.residuals) else 0.0)
    lim = max(lim * 1.1, 1e-3)
    ax2.set_xlim(-lim, lim)
    ax2.set_ylim(-lim, lim)
    ax2.set_aspect("equal")
    ax2.axhline(0, color="0.7", linewidth=0.5)
    ax2.axvline(0, color="0.7", linewidth=0.5)
    ax2.set_xlabel("residual u [px]")
    ax2.set_ylabel("residual v [px]")
    ax2.set_title(f"{result.corners} corners (projected - detected)")
    K = result.camera.intrinsics
    fig.suptitle(title or f"{K.width} x {K.height}: fx {K.fx:.2f}, fy {K.fy:.2f}, cx {K.cx:.2f}, cy {K.cy:.2f} px; "
                          f"model {result.model.value}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
