"""Judging a hand-eye calibration on views it did not use (leave one view out).

In-sample residuals cannot tell a better calibration from a worse one: a refinement that
holds the robot's logged flange poses exact moves the mount until it absorbs their errors,
and its residuals shrink while the mount moves away from the truth. A view the calibration
did not see can: calibrate without view i, predict view i's board pose in the camera from
its robot pose, compare with the pose the image itself gives (solvePnP).

Both set-ups are one chain ``G[i] @ X @ camera_T_marker[i] = W``
(:mod:`recon_cli.calibration.setups`; G is the robot pose eye-in-hand, its inverse
eye-to-hand), so the prediction is the same formula for both::

    camera_T_marker[i] = X^-1 @ G[i]^-1 @ W

eye-in-hand: the board where the camera on the flange sees it; eye-to-hand: the board on the
flange where the fixed camera sees it. The error of a view is the predicted board origin
against the observed one [m] and the angle between the two board orientations [rad].

A solver is any callable ``list[BoardObservation] -> HandEyeSolution`` (an OpenCV method, a
refinement from one). Candidates are ranked by one number, the **held-out score**::

    score = sqrt(mean_i(t_i^2 + (LEVER * r_i)^2))   [m]

the RMS over the held-out views of the translation error and the rotation error turned into
the displacement it causes at LEVER (0.1 m) from the board origin, a board corner's
distance for a board of A4 to A3 size: 1 mm and 0.57 deg count alike.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from recon_cli.calibration.handeye import BoardObservation, HandEyeSolution
from recon_cli.errors import ReconError
from recon_cli.geometry.transforms import invert, pose_error

Solver = Callable[[list[BoardObservation]], HandEyeSolution]

#: [m] a held-out rotation error of 1 rad counts like a translation error of LEVER metres
LEVER = 0.1


@dataclass(frozen=True)
class HeldOutView:
    """View ``name`` predicted by the calibration of the other views: translation [m] and
    rotation [rad] of its board pose in the camera against the observed one; ``failed``:
    why the other views gave no calibration (the errors are then NaN)."""

    name: str
    translation: float
    rotation: float
    failed: str | None = None


@dataclass(frozen=True)
class HeldOut:
    """Leave-one-view-out errors of one candidate (a solver)."""

    candidate: str
    views: tuple[HeldOutView, ...]

    def _values(self) -> tuple[np.ndarray, np.ndarray]:
        ok = [v for v in self.views if v.failed is None]
        return np.array([v.translation for v in ok]), np.array([v.rotation for v in ok])

    @property
    def failed(self) -> list[str]:
        return [v.name for v in self.views if v.failed is not None]

    @property
    def complete(self) -> bool:
        """Every view was predicted (no calibration without one of them failed)."""
        return not self.failed and bool(self.views)

    @property
    def median(self) -> tuple[float, float]:
        t, r = self._values()
        return (float(np.median(t)), float(np.median(r))) if t.size else (np.inf, np.inf)

    @property
    def rms(self) -> tuple[float, float]:
        t, r = self._values()
        return (float(np.sqrt(np.mean(t**2))), float(np.sqrt(np.mean(r**2)))) if t.size else (np.inf, np.inf)

    @property
    def max(self) -> tuple[float, float]:
        t, r = self._values()
        return (float(t.max()), float(r.max())) if t.size else (np.inf, np.inf)

    @property
    def score(self) -> float:
        """RMS of sqrt(t^2 + (LEVER r)^2) over the views [m] (inf when a view failed)."""
        if not self.complete:
            return float("inf")
        t, r = self._values()
        return float(np.sqrt(np.mean(t**2 + (LEVER * r) ** 2)))

    def to_dict(self) -> dict:
        (mt, mr), (qt, qr), (xt, xr) = self.median, self.rms, self.max
        return {"candidate": self.candidate, "score_mm": _finite(self.score * 1e3),
                "median_mm": _finite(mt * 1e3), "median_deg": _finite(np.degrees(mr)),
                "rms_mm": _finite(qt * 1e3), "rms_deg": _finite(np.degrees(qr)),
                "max_mm": _finite(xt * 1e3), "max_deg": _finite(np.degrees(xr)),
                "views": [{"name": v.name, "translation_mm": _finite(v.translation * 1e3),
                           "rotation_deg": _finite(np.degrees(v.rotation)), "failed": v.failed}
                          for v in self.views]}


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def predicted_board(solution: HandEyeSolution, chain_pose: np.ndarray) -> np.ndarray:
    """The board in the camera for a view whose chain pose G is ``chain_pose``:
    X^-1 @ G^-1 @ W (4, 4) [m]."""
    return invert(solution.flange_T_camera) @ invert(chain_pose) @ solution.world_T_marker


def prediction_errors(observations: list[BoardObservation], solution: HandEyeSolution) -> list[tuple[float, float]]:
    """Per view: the solution's predicted board pose against the observed one (in-sample
    when the solution used the view) [m, rad]."""
    return [pose_error(predicted_board(solution, o.world_T_flange), o.camera_T_marker) for o in observations]


def leave_one_out(observations: list[BoardObservation], solver: Callable[[list[BoardObservation]], Any],
                  candidate: str, predict: Callable[[Any, BoardObservation], np.ndarray] | None = None) -> HeldOut:
    """Calibrate without each view in turn and predict it (see the module docstring). A
    calibration of the others that the solver refuses (a :class:`ReconError`, e.g. too few
    views or OpenCV finding no solution) marks that view failed. ``predict``: the held-out
    view's board pose in the camera from what the solver returned (default: the solver
    returns a HandEyeSolution, :func:`predicted_board`); a solver whose model corrects the
    robot poses (a base error) predicts through its correction."""
    out = []
    for i, o in enumerate(observations):
        rest = observations[:i] + observations[i + 1:]
        try:
            s = solver(rest)
        except ReconError as exc:
            out.append(HeldOutView(o.name, float("nan"), float("nan"), exc.one_line()))
            continue
        P = predict(s, o) if predict is not None else predicted_board(s, o.world_T_flange)
        t, r = pose_error(P, o.camera_T_marker)
        out.append(HeldOutView(o.name, t, r) if np.isfinite(t) and np.isfinite(r)
                   else HeldOutView(o.name, float("nan"), float("nan"), "no finite prediction"))
    return HeldOut(candidate, tuple(out))


def best(results: list[HeldOut]) -> HeldOut:
    """The candidate with the smallest held-out score (the first of equals)."""
    if not results:
        raise ValueError("no candidates")
    return min(results, key=lambda h: h.score)


def within_noise(candidate: HeldOut, reference: HeldOut) -> bool:
    """Whether ``candidate``'s held-out score exceeds ``reference``'s by no more than one
    standard error of their difference: the mean over the views of the per-view difference
    of squared errors ``t^2 + (LEVER r)^2`` (both predict the same views) against that
    difference's standard error. With 10-20 views, scores of good candidates differ by
    less than that; the smallest is then a draw of the views, not a better calibration."""
    if not (candidate.complete and reference.complete) or [v.name for v in candidate.views] != \
            [v.name for v in reference.views]:
        return False
    t, r = candidate._values()
    t0, r0 = reference._values()
    d = (t**2 + (LEVER * r) ** 2) - (t0**2 + (LEVER * r0) ** 2)
    if d.size < 3:
        return bool(d.mean() <= 0.0)
    return bool(d.mean() <= d.std(ddof=1) / np.sqrt(d.size))


def preferred(results: list[HeldOut], order: list[str]) -> HeldOut:
    """The candidate written: the first of ``order`` (the candidates that model more of the
    robot's and the detection's errors, most first) whose held-out score is within noise of
    the smallest (:func:`within_noise`), else the one with the smallest score. Held-out
    error decides; where it cannot tell, the better model of the errors does (the
    one-standard-error rule of model selection)."""
    smallest = best(results)
    by_name = {h.candidate: h for h in results}
    for name in order:
        h = by_name.get(name)
        if h is not None and (h is smallest or within_noise(h, smallest)):
            return h
    return smallest
