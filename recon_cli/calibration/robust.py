"""Hand-eye refinement that treats the robot's flange poses as measurements with errors.

A real arm's logged flange pose is off the true one by about 0.5 mm and 0.05 deg (joint zero
offsets, link lengths, elasticity, timing). A refinement that holds the logged poses exact
moves the camera mount until it absorbs those errors. Here every view i gets its own
correction twist c_i of the flange pose, with a Gaussian prior of the robot's stated accuracy
(:class:`PosePrior`), and the maximum a posteriori estimate of the mount X
(``flange_T_camera``), the board W (``world_T_marker``) and the corrections minimizes::

    sum_i | r_i / detection std |^2 + | c_i / pose std |^2

    r_i = board(inv(world_T_flange[i] exp(c_i) X) W, camera_T_marker[i])

where ``board(P, M)`` compares the predicted board pose P in the camera with the measured M:
the marker origin's position difference [m] and the rotation vector of ``P_R M_R^T`` [rad],
both in camera axes (:func:`board_residuals`). The board poses' own precision (the detection
std, one per camera axis) is estimated from the data when it is not given: variance component
estimation (Förstner), which divides the board residuals' sum of squares by their share of
the redundancy, repeated until it settles. Twists here are (translation [m], rotation vector
[rad]) applied on the right: ``X = X_est exp(xi)``, so the position part of the mount's
covariance is the camera origin's in camera axes.

Levenberg-Marquardt (scipy's least_squares) from an OpenCV solution. The Jacobian's sparsity
(view i's rows see X, W, the offsets and c_i only) makes it cheap: central differences of X's
and W's twists and of every view's correction, one component of all views at once, in one
batch; the covariance and the redundancy numbers eliminate the corrections' 6 x 6 blocks
(Schur complement), so 50 views cost about as much linear algebra as 12 unknowns.

The eye-to-hand chain (:func:`recon_cli.calibration.setups.chain_observations`) puts the
inverse robot pose where ``world_T_flange`` stands: its correction is then in the base frame,
and a rotation error there moves the flange by the rotation times its distance from the base;
give that set-up a translation prior grown by that lever.

:func:`estimate_joint_offsets` adds the joints' zero offsets when the joint positions and the
cell's kinematics are known: the flange poses are then forward kinematics of the measured
joints plus the offsets, and only offsets that the views determine are estimated (a
rotation of the first joint moves the whole base about the vertical, which the board's pose
absorbs; one of the last joint turns the flange about its axis, which the mount absorbs).
:func:`bootstrap_mount` gives a mount uncertainty from any solver by resampling the views.

:func:`refine_corners_with_pose_errors` is the same MAP on what the images measured: the
board corners' reprojection errors [px] over their std (pooled from every view's own PnP
fit), instead of six board-pose numbers per view with one std per camera axis, which cannot
hold a PnP pose's anisotropic, correlated error (depth with tilt). Given the measured joints
and the cell, the flange errors are also correlated through the joints' zero offsets, every
offset under a Gaussian prior (``PosePrior.joint_offset``), all estimated in the same solve.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from recon_cli.calibration.handeye import BoardObservation, HandEyeSolution
from recon_cli.calibration.setups import CornerView, Setup, SetupSolution
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import invert

log = logging.getLogger(__name__)

#: smallest detection std the data may set [m, rad] (exact data would otherwise give 0)
DETECTION_FLOOR = (1e-7, 1e-7)
#: rounds of the detection std's estimate (each a full solve); it stops earlier when settled
VARIANCE_ROUNDS = 6
#: a robust loss counts a view's board residual (in detection stds, all six numbers) fully up to this size
ROBUST_SCALE = 3.0
LOSSES = ("linear", "soft_l1", "huber")


@dataclass(frozen=True)
class PosePrior:
    """How far off the logged flange poses and the board poses are (1-sigma, per axis)."""

    translation: float = 0.5e-3  # [m] std of a logged flange pose's position error
    rotation: float = float(np.radians(0.05))  # [rad] std of its orientation error
    detection_translation: float | None = None  # [m] std of a board pose's position (None: estimated from the data)
    detection_rotation: float | None = None  # [rad]
    joint_offset: float = float(np.radians(0.03))  # [rad] std of a joint's zero offset (corner level, with joints)

    def __post_init__(self) -> None:
        for name in ("translation", "rotation", "detection_translation", "detection_rotation", "joint_offset"):
            value = getattr(self, name)
            if value is not None and not (np.isfinite(value) and value > 0):
                raise ValueError(f"PosePrior.{name} must be a positive finite number, not {value!r}")


@dataclass(frozen=True)
class RobustRefinement:
    """The refined solution (the start's method label) and what the refinement found."""

    solution: HandEyeSolution
    flange_corrections: np.ndarray  # (n, 6) per-view correction twist c of world_T_flange (@ exp(c)) [m, rad]
    covariance: np.ndarray  # (6, 6) of flange_T_camera's twist [m, rad] (from the Jacobian at the optimum, scaled)
    std_mm_deg: tuple[float, float]  # 1-sigma of the mount: position [mm] (norm of the 3 stds), rotation [deg]
    converged: bool
    message: str
    detection_std: tuple[float, float] = (0.0, 0.0)  # [m, rad] the board poses' std used (RMS over the axes)
    detection_axes: np.ndarray = field(default_factory=lambda: np.zeros(6))  # (6,) per camera axis [m, m, m, rad, ...]
    pixel_std: float = 0.0  # [px] the corners' std per image coordinate (corner-level refinement only)
    joint_offsets: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (k,) [rad] (corner level, with joints)


@dataclass(frozen=True)
class JointOffsets:
    """Joint zero offsets (added to the measured joints) and the solution found with them."""

    offsets: np.ndarray  # (n_joints,) [rad] (0 where not observable)
    std: np.ndarray  # (n_joints,) [rad] 1-sigma (inf where not observable)
    solution: HandEyeSolution
    observable: np.ndarray  # (n_joints,) bool: joints whose offset the views determine
    refinement: RobustRefinement | None = field(default=None, compare=False)  # with the offsets applied


# --------------------------------------------------------------------- Lie helpers
def _rodrigues(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (m, 3, 3) of rotation vectors (m, 3) [rad]."""
    a = np.linalg.norm(w, axis=1)
    small = a < 1e-8
    safe = np.where(small, 1.0, a)
    A = np.where(small, 1.0 - a * a / 6.0, np.sin(a) / safe)  # sin(a) / a
    Bc = np.where(small, 0.5 - a * a / 24.0, (1.0 - np.cos(a)) / (safe * safe))  # (1 - cos a) / a^2
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return np.eye(3) + A[:, None, None] * K + Bc[:, None, None] * (K @ K)


def _exp(xi: np.ndarray) -> np.ndarray:
    """Rigid transforms (..., 4, 4) of twists (..., 6): translation [m], rotation vector [rad]."""
    xi = np.asarray(xi, dtype=float)
    flat = xi.reshape(-1, 6)
    T = np.zeros((len(flat), 4, 4))
    T[:, :3, :3] = _rodrigues(flat[:, 3:])
    T[:, :3, 3] = flat[:, :3]
    T[:, 3, 3] = 1.0
    return T.reshape(*xi.shape[:-1], 4, 4)


def _rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) [rad] of rotation matrices (..., 3, 3)."""
    shape = R.shape[:-2]
    Rf = R.reshape(-1, 3, 3)
    cos = np.clip((np.trace(Rf, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    a = np.arccos(cos)
    v = np.stack([Rf[:, 2, 1] - Rf[:, 1, 2], Rf[:, 0, 2] - Rf[:, 2, 0], Rf[:, 1, 0] - Rf[:, 0, 1]], axis=1)
    near_pi = a > np.pi - 1e-3
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(a < 1e-8, 0.5 + a * a / 12.0, a / (2.0 * np.sin(a)))
    out = k[:, None] * v
    if np.any(near_pi):  # the antisymmetric part vanishes: scipy's careful conversion
        from scipy.spatial.transform import Rotation

        out[near_pi] = Rotation.from_matrix(Rf[near_pi]).as_rotvec()
    return out.reshape(*shape, 3)


def _inv_many(T: np.ndarray) -> np.ndarray:
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def board_residuals(world_T_flange: np.ndarray, flange_T_camera: np.ndarray, world_T_marker: np.ndarray,
                    camera_T_marker: np.ndarray) -> np.ndarray:
    """(..., n, 6): predicted minus measured board pose in the camera per view: the marker
    origin's position [m] and the rotation vector [rad] of predicted @ measured^-1 (camera axes)."""
    pred = _inv_many(world_T_flange @ flange_T_camera) @ world_T_marker
    dt = pred[..., :3, 3] - camera_T_marker[..., :3, 3]
    dr = _rotvec(pred[..., :3, :3] @ np.swapaxes(camera_T_marker[..., :3, :3], -1, -2))
    return np.concatenate([dt, dr], axis=-1)


# --------------------------------------------------------------------- the problem
@dataclass
class _Problem:
    """The MAP problem: parameters [xi_X (6), xi_W (6), c (6n), offsets (k)]."""

    flange: Callable[[np.ndarray], np.ndarray]  # offsets (k,) -> world_T_flange (n, 4, 4)
    B: np.ndarray  # (n, 4, 4) camera_T_marker
    X0: np.ndarray
    W0: np.ndarray
    prior: np.ndarray  # (6,) pose std per twist component
    detection: np.ndarray  # (6,) board std per residual component
    k: int = 0  # number of estimated joint offsets
    loss: str = "linear"
    bound: float = np.inf  # [rad] the offsets' bound: offset = bound tanh(u / bound) of the parameter u
    _cache: tuple[bytes, np.ndarray] | None = None  # the last offsets and their flange poses

    def flange_poses(self, offsets: np.ndarray) -> np.ndarray:
        key = offsets.tobytes()
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, self.flange(offsets))
        return self._cache[1]

    @property
    def n(self) -> int:
        return len(self.B)

    def offsets(self, x: np.ndarray) -> np.ndarray:
        """The joint offsets [rad] of a parameter vector (within +-bound)."""
        u = x[12 + 6 * self.n:]
        return u if not np.isfinite(self.bound) else self.bound * np.tanh(u / self.bound)

    @property
    def size(self) -> int:
        return 12 + 6 * self.n + self.k

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        X = self.X0 @ _exp(x[:6])
        W = self.W0 @ _exp(x[6:12])
        c = x[12:12 + 6 * self.n].reshape(self.n, 6)
        return X, W, c, x[12 + 6 * self.n:]

    def raw(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unweighted board residuals (n, 6) and corrections (n, 6)."""
        board, c = self._raw_batch(x[None])
        return board[0], c[0]

    def _raw_batch(self, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`raw` of parameter vectors (b, size) that share their offsets: (b, n, 6) each."""
        n = self.n
        X = self.X0 @ _exp(xs[:, :6])  # (b, 4, 4)
        W = self.W0 @ _exp(xs[:, 6:12])
        c = xs[:, 12:12 + 6 * n].reshape(len(xs), n, 6)
        F = self.flange_poses(self.offsets(xs[0])) @ _exp(c)  # (b, n, 4, 4)
        return board_residuals(F, X[:, None], W[:, None], self.B), c

    def _weighted(self, board: np.ndarray, c: np.ndarray) -> np.ndarray:
        """(b, 12 n) weighted residuals of raw ones (b, n, 6)."""
        rb = board / self.detection
        if self.loss != "linear":  # per view: the square of the scaled residual is the loss
            s = np.sum(rb * rb, axis=-1) / ROBUST_SCALE ** 2
            if self.loss == "soft_l1":
                rho = 2.0 * (np.sqrt(1.0 + s) - 1.0)
            else:  # huber
                rho = np.where(s <= 1.0, s, 2.0 * np.sqrt(s) - 1.0)
            scale = np.sqrt(np.where(s > 1e-12, rho / np.maximum(s, 1e-12), 1.0))
            rb = rb * scale[..., None]
        b = len(board)
        return np.concatenate([rb.reshape(b, -1), (c / self.prior).reshape(b, -1)], axis=1)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self._weighted(*self._raw_batch(np.asarray(x, dtype=float)[None]))[0]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Dense Jacobian of :meth:`residuals` by central differences: the mount's and the
        board's columns and the corrections of all views at once per component (each view's
        rows see only its own) in one batch; each offset's column apart (forward kinematics)."""
        n, m, size = self.n, 12 * self.n, self.size
        J = np.zeros((m, size))
        steps = np.concatenate([np.full(12, 1e-6), 1e-3 * np.tile(self.prior, n), np.full(self.k, 1e-6)])
        E = np.zeros((18, size))
        for j in range(12):
            E[j, j] = steps[j]
        for a in range(6):
            cols = 12 + 6 * np.arange(n) + a
            E[12 + a, cols] = steps[cols]
        R = self._weighted(*self._raw_batch(np.concatenate([x + E, x - E])))
        D = (R[:18] - R[18:]) / (2.0 * np.concatenate([steps[:12], steps[12:18]]))[:, None]  # (18, m)
        J[:, :12] = D[:12].T
        rows = np.arange(n)[:, None] * 6 + np.arange(6)[None, :]  # (n, 6) view i's rows
        for a in range(6):
            cols = 12 + 6 * np.arange(n) + a
            J[rows, cols[:, None]] = D[12 + a][rows]
            J[6 * n + rows, cols[:, None]] = D[12 + a][6 * n + rows]
        for j in range(12 + 6 * n, size):
            e = np.zeros(size)
            e[j] = steps[j]
            J[:, j] = (self.residuals(x + e) - self.residuals(x - e)) / (2 * steps[j])
        return J

    def solve(self, x0: np.ndarray):
        from scipy.optimize import least_squares

        scale = np.concatenate([np.full(12, 1e-3), np.tile(self.prior, self.n), np.full(self.k, 1e-3)])
        return least_squares(self.residuals, x0, jac=self.jacobian, method="lm", x_scale=scale,
                             xtol=1e-12, ftol=1e-12, gtol=1e-10, max_nfev=200)

    def inverse_blocks(self, J: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The inverse of the normal matrix J^T J by its block structure (the corrections'
        6 x 6 blocks apart): S^-1 (p, p) of the p = 12 + k dense parameters (their covariance
        with unit weights), G = D^-1 B^T per view (n, 6, p) and D^-1 (n, 6, 6)."""
        S, G, D_inv = self.schur(J)
        return _inverse(S), G, D_inv

    def schur(self, J: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """S (p, p), the normal matrix of the dense parameters with the corrections
        eliminated, G and D^-1 (see :meth:`inverse_blocks`)."""
        n = self.n
        Jd_board = J[:6 * n, self._dense()].reshape(n, 6, -1)  # (n, 6, p); dense columns have no prior rows
        Jc = np.stack([np.concatenate([J[6 * i:6 * i + 6, 12 + 6 * i:18 + 6 * i],
                                       J[6 * n + 6 * i:6 * n + 6 * i + 6, 12 + 6 * i:18 + 6 * i]]) for i in range(n)])
        Jc_board = Jc[:, :6]
        A = np.einsum("nra,nrb->ab", Jd_board, Jd_board)
        Bm = np.einsum("nra,nrc->nac", Jd_board, Jc_board)  # (n, p, 6)
        D_inv = np.linalg.inv(np.einsum("nrc,nrd->ncd", Jc, Jc))
        G = np.einsum("ncd,nad->nca", D_inv, Bm)  # (n, 6, p)
        S = A - np.einsum("nac,ncb->ab", Bm, G)
        return S, G, D_inv

    def _dense(self) -> list[int]:
        return list(range(12)) + list(range(12 + 6 * self.n, self.size))

    def update_detection(self, fit, per_axis: tuple[bool, bool]) -> bool:
        """Variance component estimation of the board std, per camera axis (translation x, y,
        z, rotation about x, y, z) where ``per_axis`` says so (translation, rotation), else one
        for the three: True when it changed by less than 5 %."""
        J = np.asarray(fit.jac)
        n = self.n
        S_inv, G, D_inv = self.inverse_blocks(J)
        a = J[:6 * n, self._dense()].reshape(n, 6, -1)
        b = np.stack([J[6 * i:6 * i + 6, 12 + 6 * i:18 + 6 * i] for i in range(n)])  # (n, 6 rows, 6)
        u = a - np.einsum("nrc,nca->nra", b, G)
        h = np.einsum("nra,ab,nrb->nr", u, S_inv, u) + np.einsum("nrc,ncd,nrd->nr", b, D_inv, b)
        board, _ = self.raw(fit.x)
        red = 1.0 - h  # (n, 6) the board rows' redundancy numbers
        new = self.detection.copy()
        for part, floor, estimate in ((0, DETECTION_FLOOR[0], per_axis[0]), (3, DETECTION_FLOOR[1], per_axis[1])):
            groups = [[part], [part + 1], [part + 2]] if estimate else [[part, part + 1, part + 2]]
            for cols in groups:
                r = float(np.sum(red[:, cols]))
                if r > 0.5:
                    new[cols] = max(float(np.sqrt(np.sum(board[:, cols] ** 2) / r)), floor)
        settled = bool(np.all(np.abs(new / self.detection - 1.0) < 0.05))
        self.detection = new
        return settled


def _detection_start(B: np.ndarray, F: np.ndarray, start: HandEyeSolution, prior: PosePrior) -> np.ndarray:
    """The board std to start with: given, else the start solution's residual spread."""
    r = board_residuals(F, start.flange_T_camera, start.world_T_marker, B)
    rms_t = float(np.sqrt(np.mean(r[:, :3] ** 2)))
    rms_r = float(np.sqrt(np.mean(r[:, 3:] ** 2)))
    dt = prior.detection_translation or max(rms_t, DETECTION_FLOOR[0])
    dr = prior.detection_rotation or max(rms_r, DETECTION_FLOOR[1])
    return np.array([dt, dt, dt, dr, dr, dr])


def _prior_vector(prior: PosePrior) -> np.ndarray:
    return np.array([prior.translation] * 3 + [prior.rotation] * 3)


def _mount_covariance(problem: _Problem, fit) -> np.ndarray:
    """(6, 6) covariance of the mount's twist, scaled by the fit's variance factor."""
    dof = max(len(fit.fun) - problem.size, 1)
    s2 = float(fit.fun @ fit.fun) / dof
    S_inv, _, _ = problem.inverse_blocks(np.asarray(fit.jac))
    return np.asarray(S_inv[:6, :6] * s2)


def _std_mm_deg(cov: np.ndarray) -> tuple[float, float]:
    return (float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)) * 1e3),
            float(np.degrees(np.sqrt(max(np.trace(cov[3:, 3:]), 0.0)))))


def _run(problem: _Problem, estimate_detection: tuple[bool, bool], x0: np.ndarray):
    fit = problem.solve(x0)
    if any(estimate_detection):
        for _ in range(VARIANCE_ROUNDS):
            settled = problem.update_detection(fit, estimate_detection)
            fit = problem.solve(fit.x)
            if settled:
                break
    return fit


def refine_with_pose_errors(observations: list[BoardObservation], start: HandEyeSolution,
                            prior: PosePrior = PosePrior(), *,  # noqa: B008 (frozen)
                            loss: str = "linear") -> RobustRefinement:
    """MAP estimate of flange_T_camera, world_T_marker and per-view flange pose corrections
    (see the module docstring), from ``start`` (an OpenCV solution). ``loss``: ``linear``, or
    ``soft_l1`` / ``huber`` on each view's board residual (a view far off counts less)."""
    if loss not in LOSSES:
        raise ValueError(f"loss {loss!r} is not one of {', '.join(LOSSES)}")
    F = np.array([o.world_T_flange for o in observations], dtype=float)
    B = np.array([o.camera_T_marker for o in observations], dtype=float)
    problem = _Problem(lambda _: F, B, start.flange_T_camera, start.world_T_marker, _prior_vector(prior),
                       _detection_start(B, F, start, prior), loss=loss)
    estimate = (prior.detection_translation is None, prior.detection_rotation is None)
    fit = _run(problem, estimate, np.zeros(problem.size))
    return _result(problem, fit, start)


def _result(problem: _Problem, fit, start: HandEyeSolution) -> RobustRefinement:
    X, W, c, _ = problem.unpack(fit.x)
    cov = _mount_covariance(problem, fit)
    d = problem.detection
    detection = (float(np.sqrt(np.mean(d[:3] ** 2))), float(np.sqrt(np.mean(d[3:] ** 2))))
    return RobustRefinement(HandEyeSolution(start.method, X, W), c.copy(), cov, _std_mm_deg(cov),
                            bool(fit.success), str(fit.message), detection, d.copy())


# --------------------------------------------------------------------- corner level
#: smallest corner std the data may set [px] (exact data would otherwise give 0)
PIXEL_FLOOR = 1e-4


@dataclass
class _CornerProblem:
    """The corner-level MAP: parameters [xi_X (6), xi_W (6), c (6n), d (k)]; residuals: every
    corner's image coordinates (predicted minus detected) [px] / pixel std, then c / prior,
    then d / offset std. View i's chain pose is ``G_i exp(A_i d) exp(c_i)``."""

    G: np.ndarray  # (n, 4, 4) chain poses (the robot's pose, inverted for eye-to-hand)
    X0: np.ndarray
    W0: np.ndarray
    obj: np.ndarray  # (M, 3) every view's corners on the board [m]
    uv: np.ndarray  # (M, 2) where they were detected, undistorted [px]
    view: np.ndarray  # (M,) the view of each corner
    K: np.ndarray  # (M, 4) fx, fy, cx, cy of its camera [px]
    prior: np.ndarray  # (6,) pose std per twist component
    pixel: float  # [px]
    A: np.ndarray  # (n, 6, k) the chain poses' twists per joint offset [m/rad, rad/rad]
    offset_std: float = np.inf  # [rad]

    @property
    def n(self) -> int:
        return len(self.G)

    @property
    def k(self) -> int:
        return self.A.shape[2]

    @property
    def size(self) -> int:
        return 12 + 6 * self.n + self.k

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = self.n
        return self.X0 @ _exp(x[:6]), self.W0 @ _exp(x[6:12]), x[12:12 + 6 * n].reshape(n, 6), x[12 + 6 * n:]

    def _raw_batch(self, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Corner residuals (b, M, 2) [px] and corrections (b, n, 6) of parameter vectors (b, size)."""
        b, n = len(xs), self.n
        X = self.X0 @ _exp(xs[:, :6])
        W = self.W0 @ _exp(xs[:, 6:12])
        c = xs[:, 12:12 + 6 * n].reshape(b, n, 6)
        G = self.G[None] @ _exp(c)
        if self.k:
            G = self.G[None] @ _exp(np.einsum("nak,bk->bna", self.A, xs[:, 12 + 6 * n:])) @ _exp(c)
        T = _inv_many(G @ X[:, None]) @ W[:, None]  # (b, n, 4, 4) camera_T_board
        Tm = T[:, self.view]  # (b, M, 4, 4) each corner's view
        P = np.einsum("bmij,mj->bmi", Tm[..., :3, :3], self.obj) + Tm[..., :3, 3]
        z = P[..., 2]
        u = self.K[:, 0] * P[..., 0] / z + self.K[:, 2]
        v = self.K[:, 1] * P[..., 1] / z + self.K[:, 3]
        return np.stack([u, v], axis=-1) - self.uv, c

    def _weighted(self, corners: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
        b = len(corners)
        return np.concatenate([corners.reshape(b, -1) / self.pixel, (c / self.prior).reshape(b, -1),
                               d / self.offset_std], axis=1)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return self._weighted(*self._raw_batch(x[None]), x[None, 12 + 6 * self.n:])[0]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Dense Jacobian by central differences: the mount's and the board's twists, one
        component of every view's correction at once (a view's corners see only its own) and
        each offset, in one batch; the prior rows exactly."""
        n, k, size = self.n, self.k, self.size
        m = 2 * len(self.obj)
        steps = np.concatenate([np.full(12, 1e-6), 1e-3 * self.prior, np.full(k, 1e-6)])
        E = np.zeros((18 + k, size))
        E[np.arange(12), np.arange(12)] = steps[:12]
        for a in range(6):
            E[12 + a, 12 + 6 * np.arange(n) + a] = steps[12 + a]
        E[18 + np.arange(k), 12 + 6 * n + np.arange(k)] = steps[18:]
        corners, _ = self._raw_batch(np.concatenate([x + E, x - E]))
        D = (corners[:18 + k] - corners[18 + k:]).reshape(18 + k, m) / (2.0 * steps[:, None] * self.pixel)
        J = np.zeros((m + 6 * n + k, size))
        J[:m, :12] = D[:12].T
        for a in range(6):
            J[np.arange(m), 12 + 6 * np.repeat(self.view, 2) + a] = D[12 + a]
        J[:m, 12 + 6 * n:] = D[18:].T
        J[m + np.arange(6 * n), 12 + np.arange(6 * n)] = 1.0 / np.tile(self.prior, n)
        J[m + 6 * n + np.arange(k), 12 + 6 * n + np.arange(k)] = 1.0 / self.offset_std
        return J


def offset_twists(joints: np.ndarray, kin, setup: Setup, step: float = 1e-6) -> np.ndarray:
    """(n, 6, n_joints) how each view's chain pose moves per joint zero offset: the twist of
    ``inv(G(q)) G(q + step e_j)`` over ``step`` (G the flange's forward kinematics, inverted
    for eye-to-hand) [m/rad, rad/rad], by central differences."""
    fid = kin.frame_id(kin.cell.flange_link)
    Q = np.asarray(joints, dtype=float)
    nj = Q.shape[1]
    out = np.zeros((len(Q), 6, nj))
    for i, q in enumerate(Q):
        G_inv = invert(setup.chain_pose(kin.frame_pose(q, fid)))
        for j in range(nj):
            e = np.zeros(nj)
            e[j] = step
            Tp = G_inv @ setup.chain_pose(kin.frame_pose(q + e, fid))
            Tm = G_inv @ setup.chain_pose(kin.frame_pose(q - e, fid))
            tw = [np.concatenate([T[:3, 3], _rotvec(T[None, :3, :3])[0]]) for T in (Tp, Tm)]
            out[i, :, j] = (tw[0] - tw[1]) / (2.0 * step)
    return out


def _undistorted(view: CornerView) -> np.ndarray:
    """(N, 2) the detected corners without the lens distortion, in the camera's pixels."""
    dist = view.camera.distortion_array
    pts = np.asarray(view.image_points, dtype=float).reshape(-1, 2)
    if not np.any(dist):
        return pts
    import cv2

    K = view.camera.intrinsics.matrix()
    return cv2.undistortPoints(pts.reshape(-1, 1, 2), K, dist, P=K).reshape(-1, 2)


def corner_pixel_std(views: list[CornerView]) -> float:
    """The corners' std per image coordinate [px] from every view's own board pose: the sum of
    squares of its reprojection over the redundancy (2 N - 6 per view), pooled over the views."""
    ssq, dof = 0.0, 0
    for v in views:
        T = v.camera_T_board
        P = v.object_points @ T[:3, :3].T + T[:3, 3]
        K = v.camera.intrinsics
        uv = np.stack([K.fx * P[:, 0] / P[:, 2] + K.cx, K.fy * P[:, 1] / P[:, 2] + K.cy], axis=1)
        ssq += float(np.sum((uv - _undistorted(v)) ** 2))
        dof += 2 * len(P) - 6
    return max(float(np.sqrt(ssq / max(dof, 1))), PIXEL_FLOOR)


def refine_corners_with_pose_errors(views: list[CornerView], setup: Setup, start: SetupSolution | HandEyeSolution,
                                    prior: PosePrior = PosePrior(), *,  # noqa: B008 (frozen)
                                    pixel_std: float | None = None, joints: np.ndarray | None = None,
                                    kin=None) -> RobustRefinement:
    """MAP estimate of X, W (the set-up's, :class:`~recon_cli.calibration.setups.SetupSolution`)
    and per-view corrections c_i of the chain pose (the flange pose, eye-in-hand; its inverse,
    eye-to-hand) on the board corners themselves::

        sum_i sum_k | project(inv(G_i exp(c_i) X) W, p_k) - u_ik |^2 / pixel_std^2 + | c_i / pose std |^2

    A board pose from solvePnP has a strongly anisotropic, correlated error (depth and tilt
    couple); the corners carry it exactly, which the six numbers of a board pose with one std
    per axis cannot. ``pixel_std`` [px] per image coordinate: given, else pooled from every
    view's own PnP fit (:func:`corner_pixel_std`). The detected corners are undistorted once
    with the view's distortion; the residuals are in the camera's undistorted pixels.
    With ``joints`` (n, n_joints) [rad], the measured joint positions of the views, and
    ``kin`` (the cell's :class:`~recon_cli.robot.kinematics.Kinematics`), the flange errors
    are also correlated through the joints' zero offsets d (prior std
    ``prior.joint_offset`` each): view i's chain pose is ``G_i exp(A_i d) exp(c_i)``, A_i the
    chain pose's twist per offset (:func:`offset_twists`; first order in d, which is exact to
    the square of the offsets times the arm's reach). The offsets found are
    ``refinement.joint_offsets``.
    Returns the solution as a :class:`HandEyeSolution` (``flange_T_camera`` = X,
    ``world_T_marker`` = W, the start's method), the corrections, and the covariance of X's
    twist, the inverse of the normal matrix: every std in the problem is stated (the prior)
    or measured apart from the hand-eye (the pixel std), so no variance factor scales it."""
    from scipy.optimize import least_squares

    if isinstance(start, SetupSolution):
        start = HandEyeSolution(start.method, start.X, start.W)
    obj = np.concatenate([np.asarray(v.object_points, dtype=float).reshape(-1, 3) for v in views])
    uv = np.concatenate([_undistorted(v) for v in views])
    view = np.concatenate([np.full(len(v.object_points), i) for i, v in enumerate(views)])
    K = np.concatenate([np.tile([v.camera.intrinsics.fx, v.camera.intrinsics.fy, v.camera.intrinsics.cx,
                                 v.camera.intrinsics.cy], (len(v.object_points), 1)) for v in views])
    G = np.array([setup.chain_pose(v.base_T_flange) for v in views], dtype=float)
    sigma = float(pixel_std) if pixel_std is not None else corner_pixel_std(views)
    if joints is not None:
        if kin is None:
            raise ValueError("joint positions without the cell's kinematics (kin)")
        A = offset_twists(np.asarray(joints, dtype=float), kin, setup)
    else:
        A = np.zeros((len(views), 6, 0))
    problem = _CornerProblem(G, start.flange_T_camera, start.world_T_marker, obj, uv, view, K, _prior_vector(prior),
                             sigma, A, prior.joint_offset)
    x0 = np.zeros(problem.size)
    if not np.all(np.isfinite(problem.residuals(x0))):
        raise ValueError(f"the {start.method.value} solution puts some board corners behind the camera")
    scale = np.concatenate([np.full(12, 1e-3), np.tile(problem.prior, problem.n), np.full(problem.k, 1e-3)])
    fit = least_squares(problem.residuals, x0, jac=problem.jacobian, method="lm", x_scale=scale,
                        xtol=1e-12, ftol=1e-12, gtol=1e-10, max_nfev=200)
    X, W, c, d = problem.unpack(fit.x)
    J = np.asarray(fit.jac)
    cov = np.asarray(_inverse(J.T @ J)[:6, :6])
    return RobustRefinement(HandEyeSolution(start.method, X, W), c.copy(), cov, _std_mm_deg(cov),
                            bool(fit.success), str(fit.message), pixel_std=sigma, joint_offsets=d.copy())


# --------------------------------------------------------------------- joint offsets
def estimate_joint_offsets(joints: list[np.ndarray], camera_T_marker: list[np.ndarray], kin, start: HandEyeSolution,
                           prior: PosePrior = PosePrior(),  # noqa: B008 (frozen)
                           bound: float = float(np.radians(0.5))) -> JointOffsets:
    """Joint zero offsets (added to the measured ``joints``), with flange_T_camera,
    world_T_marker and the per-view corrections, from ``start``.

    ``kin``: the cell's :class:`~recon_cli.robot.kinematics.Kinematics` (its flange link is
    the cell file's ``flange``). An offset is estimated only when the views determine it: its
    std from the data (given the mount, the board, the corrections and the other estimated
    offsets) is below a third of ``bound``; estimated offsets stay within +-``bound``.
    """
    Q = np.array(joints, dtype=float)
    B = np.array(camera_T_marker, dtype=float)
    nj = Q.shape[1]
    fid = kin.frame_id(kin.cell.flange_link)

    def flange_at(offsets_all: np.ndarray) -> np.ndarray:
        return np.array([kin.frame_pose(q + offsets_all, fid) for q in Q])

    F0 = flange_at(np.zeros(nj))
    observations = [BoardObservation(str(i), F0[i], B[i]) for i in range(len(Q))]
    base = refine_with_pose_errors(observations, start, prior)
    estimate = (prior.detection_translation is None, prior.detection_rotation is None)
    pose_std = _prior_vector(prior)
    # the board poses' std found without offsets holds the offsets' effect too: choose, solve
    # (which estimates the std again), choose again until the choice stays
    X, W, c, detection = base.solution.flange_T_camera, base.solution.world_T_marker, base.flange_corrections, \
        base.detection_axes
    current = np.zeros(nj)
    chosen: list[int] = []
    result: JointOffsets | None = None
    for _ in range(3):
        def flange_near(d: np.ndarray, at: np.ndarray = current) -> np.ndarray:
            return flange_at(at + d)

        full = _Problem(flange_near, B, X, W, pose_std, detection, k=nj)
        S, _, _ = full.schur(full.jacobian(np.concatenate([np.zeros(12), c.ravel(), np.zeros(nj)])))
        choice = _observable_offsets(S, bound / 3.0)
        if result is not None and choice == chosen:
            break
        chosen = choice
        observable = np.zeros(nj, dtype=bool)
        observable[chosen] = True
        if not chosen:
            return JointOffsets(np.zeros(nj), np.full(nj, np.inf), base.solution, observable, base)

        def flange_chosen(d: np.ndarray, chosen: list[int] = chosen) -> np.ndarray:
            all_offsets = np.zeros(nj)
            all_offsets[chosen] = d
            return flange_at(all_offsets)

        problem = _Problem(flange_chosen, B, X, W, pose_std, detection, k=len(chosen), bound=bound)
        u0 = bound * np.arctanh(np.clip(current[chosen] / bound, -0.99, 0.99))
        fit = _run(problem, estimate, np.concatenate([np.zeros(12), c.ravel(), u0]))
        S_inv, _, _ = problem.inverse_blocks(np.asarray(fit.jac))
        dof = max(len(fit.fun) - problem.size, 1)
        std_u = np.sqrt(np.diag(S_inv)[12:] * float(fit.fun @ fit.fun) / dof)
        offsets = np.zeros(nj)
        std = np.full(nj, np.inf)
        offsets[chosen] = problem.offsets(fit.x)
        std[chosen] = std_u * (1.0 - (offsets[chosen] / bound) ** 2)  # d offset / d u
        refined = _result(problem, fit, start)
        result = JointOffsets(offsets, std, refined.solution, observable, refined)
        X, W, c, detection = refined.solution.flange_T_camera, refined.solution.world_T_marker, \
            refined.flange_corrections, refined.detection_axes
        current = offsets
    assert result is not None
    return result


def _observable_offsets(S: np.ndarray, threshold: float) -> list[int]:
    """The offsets (the parameters 12 ... of the normal matrix S, the corrections eliminated)
    whose std from the data, given the mount, the board and the other chosen offsets, is below
    ``threshold``. Greedy, the best determined first."""
    nj = len(S) - 12
    chosen: list[int] = []
    while len(chosen) < nj:
        stds = np.full(nj, np.inf)
        for j in set(range(nj)) - set(chosen):
            idx = list(range(12)) + [12 + m for m in (*chosen, j)]
            sub = S[np.ix_(idx, idx)]
            d = np.sqrt(np.maximum(np.diag(sub), 1e-300))
            w = np.linalg.eigvalsh(sub / np.outer(d, d))
            if w[0] > 1e-12 * w[-1]:  # else: a combination of the columns is not determined at all
                stds[j] = float(np.sqrt(max(np.linalg.inv(sub)[-1, -1], 0.0)))
        best = int(np.argmin(stds))
        if not stds[best] < threshold:
            break
        chosen.append(best)
    return sorted(chosen)


def _inverse(N: np.ndarray) -> np.ndarray:
    """Inverse of a normal matrix (symmetric, positive semi-definite), scaled by its diagonal
    for the factorization; the pseudo-inverse when it is singular."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    d = np.sqrt(np.maximum(np.diag(N), 1e-300))
    Ns = N / np.outer(d, d)
    try:
        inv = cho_solve(cho_factor(Ns), np.eye(len(N)))
    except LinAlgError:
        inv = np.linalg.pinv(Ns, hermitian=True)
    return np.asarray(inv / np.outer(d, d))


# --------------------------------------------------------------------- bootstrap
def bootstrap_mount(observations, solver, n: int = 200, seed: int = 0) -> tuple[float, float]:
    """1-sigma scatter of flange_T_camera [mm, deg] over view resamplings (with replacement;
    resamplings the solver refuses are skipped); solver: list[BoardObservation] -> HandEyeSolution."""
    rng = np.random.default_rng(seed)
    obs = list(observations)
    reference = solver(obs).flange_T_camera
    ref_inv = invert(reference)
    twists = []
    for _ in range(n):
        pick = rng.integers(0, len(obs), size=len(obs))
        if len(set(pick.tolist())) < 3:
            continue
        try:
            X = solver([obs[i] for i in pick]).flange_T_camera
        except ReconError:  # a resampling without enough distinct rotations
            continue
        D = ref_inv @ X
        twists.append(np.concatenate([D[:3, 3], _rotvec(D[None, :3, :3])[0]]))
    if len(twists) < 2:
        return float("nan"), float("nan")
    T = np.array(twists)
    sd = T.std(axis=0, ddof=1)
    return float(np.linalg.norm(sd[:3]) * 1e3), float(np.degrees(np.linalg.norm(sd[3:])))
