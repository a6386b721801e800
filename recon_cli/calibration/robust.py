"""Hand-eye refinement that treats the robot's flange poses as measurements with errors.

A real arm's logged flange pose is off the true one by about 0.5 mm and 0.05 deg (joint zero
offsets, link lengths, elasticity, timing). A refinement that holds the logged poses exact
moves the camera mount until it absorbs those errors. Here every view i gets its own
correction twist c_i of the flange pose, with a Gaussian prior of the robot's stated accuracy
(:class:`PosePrior`), and the maximum a posteriori estimate of the mount X
(``flange_T_camera``), the board W (``world_T_marker``) and the corrections minimizes::

    sum_i | log(camera_T_marker[i]^-1 ... ) / detection std |^2 + | c_i / pose std |^2

where the board residual of view i compares the measured board pose in the camera with the
one the chain predicts, ``inv(world_T_flange[i] exp(c_i) X) W``: the marker origin's position
[m] and the rotation vector [rad] between the two, both in camera axes. The board poses'
own precision (the detection std) is estimated from the data when it is not given: variance
component estimation (Förstner), which divides the board residuals' sum of squares by their
share of the redundancy, repeated until it settles. Twists here are (translation [m],
rotation vector [rad]) applied on the right: ``X = X_est exp(xi)``, so the position part of
the mount's covariance is the camera origin's in camera axes.

:func:`estimate_joint_offsets` adds the joints' zero offsets when the joint positions and the
cell's kinematics are known: the flange poses are then forward kinematics of the measured
joints plus the offsets, and only offsets that the views determine are estimated (a
rotation of the first joint moves the whole base about the vertical, which the board's pose
absorbs; one of the last joint turns the flange about its axis, which the mount absorbs).
:func:`bootstrap_mount` gives a mount uncertainty from any solver by resampling the views.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from recon_cli.calibration.handeye import BoardObservation, HandEyeSolution
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

    def __post_init__(self) -> None:
        for name in ("translation", "rotation", "detection_translation", "detection_rotation"):
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
    """(n, 6): predicted minus measured board pose in the camera per view: the marker
    origin's position [m] and the rotation vector [rad] of predicted @ measured^-1 (camera axes)."""
    pred = _inv_many(world_T_flange @ flange_T_camera) @ world_T_marker
    dt = pred[:, :3, 3] - camera_T_marker[:, :3, 3]
    dr = _rotvec(pred[:, :3, :3] @ np.swapaxes(camera_T_marker[:, :3, :3], -1, -2))
    return np.concatenate([dt, dr], axis=1)


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

    @property
    def n(self) -> int:
        return len(self.B)

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
        X, W, c, offsets = self.unpack(x)
        F = self.flange(offsets) @ _exp(c)
        return board_residuals(F, X, W, self.B), c

    def residuals(self, x: np.ndarray) -> np.ndarray:
        board, c = self.raw(x)
        rb = board / self.detection
        if self.loss != "linear":  # per view: the square of the scaled residual is the loss
            s = np.sum(rb * rb, axis=1) / ROBUST_SCALE ** 2
            if self.loss == "soft_l1":
                rho = 2.0 * (np.sqrt(1.0 + s) - 1.0)
            else:  # huber
                rho = np.where(s <= 1.0, s, 2.0 * np.sqrt(s) - 1.0)
            scale = np.sqrt(np.where(s > 1e-12, rho / np.maximum(s, 1e-12), 1.0))
            rb = rb * scale[:, None]
        return np.concatenate([rb.ravel(), (c / self.prior).ravel()])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """Dense Jacobian of :meth:`residuals` by central differences, the corrections of all
        views perturbed at once per component (each view's rows see only its own)."""
        n, m = self.n, 12 * self.n
        J = np.zeros((m, self.size))
        steps = np.concatenate([np.full(12, 1e-6), 1e-3 * np.tile(self.prior, n), np.full(self.k, 1e-6)])
        dense = list(range(12)) + list(range(12 + 6 * n, self.size))
        for j in dense:
            e = np.zeros(self.size)
            e[j] = steps[j]
            J[:, j] = (self.residuals(x + e) - self.residuals(x - e)) / (2 * steps[j])
        for a in range(6):
            cols = 12 + 6 * np.arange(n) + a
            e = np.zeros(self.size)
            e[cols] = steps[cols]
            d = (self.residuals(x + e) - self.residuals(x - e)) / (2 * steps[cols[0]])
            for i in range(n):  # view i's board rows and its prior rows
                J[6 * i:6 * i + 6, cols[i]] = d[6 * i:6 * i + 6]
                J[6 * n + 6 * i:6 * n + 6 * i + 6, cols[i]] = d[6 * n + 6 * i:6 * n + 6 * i + 6]
        return J

    def solve(self, x0: np.ndarray, bounds: tuple[np.ndarray, np.ndarray] | None = None):
        from scipy.optimize import least_squares

        scale = np.concatenate([np.full(12, 1e-3), np.tile(self.prior, self.n), np.full(self.k, 1e-3)])
        if bounds is None:
            return least_squares(self.residuals, x0, jac=self.jacobian, method="lm", x_scale=scale,
                                 xtol=1e-12, ftol=1e-12, gtol=1e-10, max_nfev=200)
        return least_squares(self.residuals, x0, jac=self.jacobian, method="trf", tr_solver="exact",
                             x_scale=scale, bounds=bounds, xtol=1e-12, ftol=1e-12, gtol=1e-10, max_nfev=200)


    def update_detection(self, fit, per_axis: tuple[bool, bool]) -> bool:
        """Variance component estimation of the board std, per camera axis (translation x, y,
        z, rotation about x, y, z) where ``per_axis`` says so (translation, rotation), else one
        for the three: True when it changed by less than 5 %."""
        J = np.asarray(fit.jac)
        N_inv = _inverse(J.T @ J)
        h = np.einsum("ij,jk,ik->i", J, N_inv, J)  # the hat matrix' diagonal
        board, _ = self.raw(fit.x)
        red = (1.0 - h[:6 * self.n]).reshape(self.n, 6)
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
    J = np.asarray(fit.jac)
    dof = max(len(fit.fun) - problem.size, 1)
    s2 = float(fit.fun @ fit.fun) / dof
    cov = _inverse(J.T @ J)
    return np.asarray(cov[:6, :6] * s2)


def _std_mm_deg(cov: np.ndarray) -> tuple[float, float]:
    return (float(np.sqrt(max(np.trace(cov[:3, :3]), 0.0)) * 1e3),
            float(np.degrees(np.sqrt(max(np.trace(cov[3:, 3:]), 0.0)))))


def _run(problem: _Problem, estimate_detection: tuple[bool, bool], x0: np.ndarray,
         bounds: tuple[np.ndarray, np.ndarray] | None = None):
    fit = problem.solve(x0, bounds)
    if any(estimate_detection):
        for _ in range(VARIANCE_ROUNDS):
            settled = problem.update_detection(fit, estimate_detection)
            fit = problem.solve(fit.x, bounds)
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
    detection = base.detection_axes

    # the data's information on every offset, at the refined solution
    full = _Problem(flange_at, B, base.solution.flange_T_camera, base.solution.world_T_marker,
                    _prior_vector(prior), detection)
    full_k = _Problem(lambda d: flange_at(d), B, full.X0, full.W0, full.prior, detection, k=nj)
    x0 = np.concatenate([np.zeros(12), base.flange_corrections.ravel(), np.zeros(nj)])
    J = _numeric_jacobian(full_k.residuals, x0)
    core = list(range(12 + 6 * len(Q)))
    chosen: list[int] = []
    threshold = bound / 3.0
    while True:
        best, best_std = -1, np.inf
        for j in range(nj):
            if j in chosen:
                continue
            cols = core + [12 + 6 * len(Q) + m for m in [*chosen, j]]
            Js = J[:, cols]
            cov = _inverse(Js.T @ Js)
            sd = np.inf if _rank_deficient(Js) else float(np.sqrt(max(cov[-1, -1], 0.0)))
            if sd < best_std:
                best, best_std = j, sd
        if best < 0 or best_std >= threshold:
            break
        chosen.append(best)
    chosen.sort()
    observable = np.zeros(nj, dtype=bool)
    observable[chosen] = True
    offsets: np.ndarray = np.zeros(nj)
    std: np.ndarray = np.full(nj, np.inf)
    if not chosen:
        return JointOffsets(offsets, std, base.solution, observable, base)

    def flange_chosen(d: np.ndarray) -> np.ndarray:
        all_offsets = np.zeros(nj)
        all_offsets[chosen] = d
        return flange_at(all_offsets)

    problem = _Problem(flange_chosen, B, full.X0, full.W0, full.prior, detection, k=len(chosen))
    lo = np.concatenate([np.full(12 + 6 * len(Q), -np.inf), np.full(len(chosen), -bound)])
    fit = _run(problem, (False, False), np.concatenate([np.zeros(12), base.flange_corrections.ravel(),
                                               np.zeros(len(chosen))]), (lo, -lo))
    J_fit = np.asarray(fit.jac)
    dof = max(len(fit.fun) - problem.size, 1)
    cov_all = _inverse(J_fit.T @ J_fit) * float(fit.fun @ fit.fun) / dof
    offsets[chosen] = fit.x[-len(chosen):]
    std[chosen] = np.sqrt(np.diag(cov_all)[-len(chosen):])
    refined = _result(problem, fit, start)
    return JointOffsets(offsets, std, refined.solution, observable, refined)


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


def _rank_deficient(J: np.ndarray) -> bool:
    """True when the columns of J (scaled to unit length) are nearly dependent."""
    norms = np.linalg.norm(J, axis=0)
    if np.any(norms == 0):
        return True
    s = np.linalg.svd(J / norms, compute_uv=False)
    return bool(s[-1] < 1e-6 * s[0])


def _numeric_jacobian(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, step: float = 1e-7) -> np.ndarray:
    """Central differences; fine for the information estimate (the fit uses scipy's own)."""
    cols = []
    for j in range(len(x)):
        e = np.zeros_like(x)
        e[j] = step
        cols.append((f(x + e) - f(x - e)) / (2 * step))
    return np.stack(cols, axis=1)


# --------------------------------------------------------------------- bootstrap
def bootstrap_mount(observations, solver, n: int = 200, seed: int = 0) -> tuple[float, float]:
    """1-sigma scatter of flange_T_camera [mm, deg] over view resamplings (with replacement;
    resamplings the solver refuses are skipped); solver: list[BoardObservation] -> HandEyeSolution."""
    from recon_cli.errors import ReconError

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
