"""Refining a hand-eye solution together with the error of the robot's base.

OpenCV's solvers take the flange poses as exact. A real robot's flange is off its model by
an error that is, for views that keep the arm's posture (:mod:`recon_cli.calibration.goals`),
nearly one rigid transform H in the frame of the gantry carriage: the iiwa's mount, the
constant part of the joints' sag and zero offsets. Carried by the linear axes to p_i, it
acts on view i as ``T(p_i) H T(-p_i)``, which changes from view to view when the axes move.
The refinement minimizes, over flange_T_camera X, world_T_marker W and the rotation of H
(its translation is the same in every view and goes into W), the closed-chain residuals::

    E_i = W^-1 T(p_i) H T(-p_i) world_T_flange[i] X camera_T_marker[i]

(translation [m] and rotation [rad] x ``LEVER``). Without linear axes, or with the axes
still, H is not observable and only X and W are refined. Gauss-Newton by scipy's
least_squares, from an OpenCV solution.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from recon_cli.calibration.handeye import BoardObservation, HandEyeSolution
from recon_cli.geometry.transforms import invert

#: [m] a rotation residual of 1 rad counts like a translation residual of LEVER metres (the
#: board poses' typical 0.1 mm and 0.01 deg errors weigh about the same)
LEVER = 0.5
#: [m] spread of the linear axes' positions below which the base rotation is not estimated
MIN_AXIS_TRAVEL = 0.05


def _exp(xi: np.ndarray) -> np.ndarray:
    """Rigid transform of a twist (translation [m], rotation vector [rad]) (first order in
    translation is enough near the solution; the rotation is exact)."""
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(xi[3:]).as_matrix()
    T[:3, 3] = xi[:3]
    return T


def _log(T: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return np.concatenate([T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_rotvec()])


@dataclass(frozen=True)
class RefinedSolution:
    """The refined solution and the base rotation it found ((3,) rotation vector [rad] of
    H, None when not estimated)."""

    solution: HandEyeSolution
    base_rotation: np.ndarray | None
    cost_before: float
    cost_after: float


def refine_hand_eye(observations: list[BoardObservation], start: HandEyeSolution) -> RefinedSolution:
    """Refine ``start`` (see the module docstring); p_i is each view's base_position."""
    from scipy.optimize import least_squares

    X0, W0 = start.flange_T_camera, start.world_T_marker
    F = [o.world_T_flange for o in observations]
    B = [o.camera_T_marker for o in observations]
    known = all(o.base_position is not None for o in observations)
    P = np.array([o.base_position for o in observations], dtype=float) if known else None
    with_base = P is not None and float(np.max(np.ptp(P, axis=0))) >= MIN_AXIS_TRAVEL
    W0_inv = invert(W0)

    def residuals(x: np.ndarray) -> np.ndarray:
        X = X0 @ _exp(x[:6])
        W_inv = _exp(-x[6:12]) @ W0_inv  # W = W0 exp(xw)... applied on the left of the world
        out = []
        H = _exp(np.concatenate([np.zeros(3), x[12:15]])) if with_base else None
        for i, (Fi, Bi) in enumerate(zip(F, B, strict=True)):
            chain = Fi @ X @ Bi
            if H is not None and P is not None:  # both or neither (with_base)
                G = H.copy()
                G[:3, 3] = P[i] - H[:3, :3] @ P[i]
                chain = G @ chain
            e = _log(W_inv @ chain)
            out.append(np.concatenate([e[:3], e[3:] * LEVER]))
        return np.concatenate(out)

    n = 15 if with_base else 12
    x0 = np.zeros(n)
    r0 = residuals(x0)
    fit = least_squares(residuals, x0, method="lm", x_scale=np.full(n, 1e-3), xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=200 * n)
    X = X0 @ _exp(fit.x[:6])
    W = invert(_exp(-fit.x[6:12]) @ W0_inv)
    refined = HandEyeSolution(start.method, X, W)
    return RefinedSolution(refined, fit.x[12:15].copy() if with_base else None, float(r0 @ r0),
                           float(fit.fun @ fit.fun))


def corrected(observations: list[BoardObservation], refined: RefinedSolution) -> list[BoardObservation]:
    """The observations with their flange poses corrected by the refined base error (the
    residuals of a refined solution are those of the corrected chain)."""
    if refined.base_rotation is None:
        return observations

    H = _exp(np.concatenate([np.zeros(3), refined.base_rotation]))
    out = []
    for o in observations:
        G = H.copy()
        G[:3, 3] = o.base_position - H[:3, :3] @ o.base_position
        out.append(replace(o, world_T_flange=G @ o.world_T_flange))
    return out
