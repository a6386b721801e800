"""Whether a hand-eye calibration can be trusted: one line, from three checks.

1. **Held-out error against the detection's precision.** The board detection of a view has
   a precision of its own: the corners' reprojection RMS of the view's solvePnP, propagated
   through the projection's Jacobian to the board pose (:func:`detection_precision`; the
   origin's position [m] and the orientation [rad], 1-sigma, in camera axes). Without the
   corners (recorded scans' board poses only) the in-sample spread of the calibration's
   predictions stands in for it. A calibration is not trusted when its held-out error
   (:mod:`recon_cli.calibration.holdout`, RMS over the views) is more than
   ``DETECTION_RATIO`` times that precision (RMS over the views): the views then contradict
   each other far beyond what the images explain (a pose convention, a unit, a wrong camera
   model, a robot that had not settled), or more than ``GENERALISATION_RATIO`` times its
   in-sample error: it fits its views but does not predict others.
2. **The mount's distance.** Eye-in-hand: the camera more than ``MOUNT_TOLERANCE`` from the
   cell's camera mount (when a cell says where it is), else farther than ``MAX_MOUNT_DISTANCE``
   from the flange; eye-to-hand: the board farther than ``MAX_MOUNT_DISTANCE`` from the flange.
   A wrong calibration puts the camera where no camera can be.
3. **Rotation diversity** of the robot poses (:func:`~recon_cli.calibration.handeye.pose_diversity`):
   views whose rotations turn about nearly one axis (axis spread below 0.003) give a
   calibration that is not trusted (the translation along that axis is poorly determined);
   views rotated less than 20 deg against each other are a warning, judged by the held-out
   error; the degenerate cases (less than 1 deg, or every
   rotation within about 1 deg of one axis) are refused before any solver runs
   (:func:`check_observations`).

When a calibration is not trusted because of 1 or 2, :func:`likely_cause` tries the usual
mistakes on the data (every robot rotation transposed, every robot pose inverted) and names
the one that makes the views agree.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from recon_cli.calibration.handeye import (
    BoardObservation,
    Diversity,
    DiversityIssue,
    HandEyeMethod,
    HandEyeSolution,
    SolverFailed,
    solve_hand_eye,
)
from recon_cli.calibration.holdout import HeldOut, prediction_errors
from recon_cli.errors import InputError, ReconError
from recon_cli.geometry.transforms import invert

#: the held-out error may be at most this many times the detection's precision (RMS over views)
DETECTION_RATIO = 25.0
#: ... and at most this many times the calibration's own in-sample prediction error
GENERALISATION_RATIO = 3.0
#: [m] the camera (eye-in-hand) or the board (eye-to-hand) at most this far from the flange
MAX_MOUNT_DISTANCE = 0.3
#: [m] eye-in-hand with a cell: the camera at most this far from the cell's camera mount
MOUNT_TOLERANCE = 0.05
#: [m] a robot pose farther than this from the base looks like millimetres
MAX_REACH = 10.0
#: a likely cause is named when it makes the views' in-sample error this many times smaller
CAUSE_GAIN = 5.0


class NotTrusted(ReconError):
    """A calibration whose verdict is "not trusted"; ``verdict`` says why."""

    exit_code = 5
    label = "not trusted"

    def __init__(self, verdict: Verdict, hint: str | None = None) -> None:
        self.verdict = verdict
        super().__init__("; ".join(verdict.reasons), hint=hint)


@dataclass(frozen=True)
class Verdict:
    """The verdict and the numbers it came from ([m], [rad]; None where not known)."""

    trusted: bool
    reasons: tuple[str, ...]
    held_out_rms: tuple[float, float]
    in_sample_rms: tuple[float, float]
    precision: tuple[float, float]
    precision_source: str  # "PnP" (propagated corner RMS) or "in-sample"
    mount_distance: float
    mount_bound: float
    mount_reference: str  # what the distance is measured from
    diversity: dict = field(default_factory=dict)
    cause: str | None = None

    def line(self) -> str:
        """``trusted (...)`` or ``not trusted: reason; reason``."""
        if self.trusted:
            t, r = self.held_out_rms
            return (f"trusted (held-out error {t * 1e3:.2f} mm / {np.degrees(r):.3f}° RMS, "
                    f"{t / max(self.precision[0], 1e-12):.1f} x the detection's precision; mount "
                    f"{self.mount_distance * 1e3:.0f} mm from {self.mount_reference})")
        return "not trusted: " + "; ".join(self.reasons)

    def to_dict(self) -> dict:
        return {"trusted": self.trusted, "line": self.line(), "reasons": list(self.reasons),
                "likely_cause": self.cause,
                "held_out_rms_mm_deg": [self.held_out_rms[0] * 1e3, float(np.degrees(self.held_out_rms[1]))],
                "in_sample_rms_mm_deg": [self.in_sample_rms[0] * 1e3, float(np.degrees(self.in_sample_rms[1]))],
                "detection_precision_mm_deg": [self.precision[0] * 1e3, float(np.degrees(self.precision[1]))],
                "detection_precision_from": self.precision_source,
                "detection_ratio_bound": DETECTION_RATIO, "generalisation_ratio_bound": GENERALISATION_RATIO,
                "mount_distance_m": self.mount_distance, "mount_bound_m": self.mount_bound,
                "mount_from": self.mount_reference, "diversity": self.diversity}


# --------------------------------------------------------------------- detection precision
def pnp_precision(camera_T_marker: np.ndarray, object_points: np.ndarray, K: np.ndarray, distortion: np.ndarray,
                  rms_px: float) -> tuple[float, float]:
    """1-sigma of a board pose from solvePnP [m, rad]: the corners' reprojection RMS
    ``rms_px`` (a distance, so sqrt(2) times a coordinate's std; corrected for the six pose
    parameters) propagated through the projection's Jacobian with respect to the origin's
    position and a rotation about it, both in camera axes. Returns the norms of the
    position's and the rotation's standard deviations (sqrt of the covariance's traces)."""
    import cv2
    from scipy.spatial.transform import Rotation

    P = np.asarray(object_points, dtype=float).reshape(-1, 1, 3)
    n = len(P)
    if n < 4:
        return float("inf"), float("inf")
    dist = np.asarray(distortion, dtype=float)

    def project(d: np.ndarray) -> np.ndarray:
        R = Rotation.from_rotvec(d[3:]).as_matrix() @ camera_T_marker[:3, :3]
        uv, _ = cv2.projectPoints(P, cv2.Rodrigues(R)[0], (camera_T_marker[:3, 3] + d[:3]).reshape(3, 1), K, dist)
        return uv.ravel()

    step = 1e-6
    J = np.zeros((2 * n, 6))
    for j in range(6):
        d = np.zeros(6)
        d[j] = step
        J[:, j] = (project(d) - project(-d)) / (2 * step)
    sigma = rms_px / np.sqrt(2.0) * np.sqrt(2 * n / max(2 * n - 6, 1))
    try:
        C = sigma**2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return float("inf"), float("inf")
    return float(np.sqrt(max(np.trace(C[:3, :3]), 0.0))), float(np.sqrt(max(np.trace(C[3:, 3:]), 0.0)))


def detection_precision(views: Sequence) -> list[tuple[float, float]]:
    """:func:`pnp_precision` of every view (setups.CornerView: its board pose, corners,
    camera and PnP RMS) [m, rad]."""
    return [pnp_precision(v.camera_T_board, v.object_points, v.camera.intrinsics.matrix(),
                          v.camera.distortion_array, v.pnp_rms) for v in views]


def _rms(values: Sequence[float]) -> float:
    a = np.asarray(values, dtype=float)
    a = a[np.isfinite(a)]
    return float(np.sqrt(np.mean(a**2))) if a.size else float("nan")


# --------------------------------------------------------------------- input checks
def check_observations(observations: list[BoardObservation], diversity: Diversity, what: str) -> None:
    """Refuse, before any solver runs, inputs no calibration can come from, in one line:
    a pose that is a mirror image (determinant -1: a mirrored board or a left-handed pose),
    boards seen from behind in some views but not others (a PnP flip), robot poses farther
    than MAX_REACH from the base (millimetres read as metres), degenerate rotations."""
    for o in observations:
        for name, T in (("robot pose", o.world_T_flange), ("board pose", o.camera_T_marker)):
            if np.linalg.det(T[:3, :3]) < 0:
                raise InputError(f"{o.name}: the {name}'s rotation has determinant {np.linalg.det(T[:3, :3]):.2f}: "
                                 "a mirror image, not a rotation (a mirrored board, or a pose with one axis "
                                 "flipped)", hint="check the board's squares_x/squares_y and the pose's axes")
        if float(np.linalg.norm(o.world_T_flange[:3, 3])) > MAX_REACH:
            raise InputError(f"{o.name}: the robot pose is {np.linalg.norm(o.world_T_flange[:3, 3]):.4g} m from "
                             f"the base, more than {MAX_REACH:g} m: it looks like millimetres read as metres",
                             hint="give the poses' length unit (--length-unit mm)")
    facing = np.array([float(o.camera_T_marker[:3, 2] @ o.camera_T_marker[:3, 3]) for o in observations])
    if len(facing) >= 3:
        majority = np.sign(np.sum(np.sign(facing)))
        flipped = [o.name for o, f in zip(observations, facing, strict=True) if np.sign(f) == -majority]
        if majority != 0 and flipped:
            raise InputError(f"the board faces the camera the other way in {len(flipped)} of {len(facing)} views "
                             f"({', '.join(flipped[:3])}{', ...' if len(flipped) > 3 else ''}): a board pose "
                             "flipped by PnP or a mirrored board", hint="leave those views out or check their "
                                                                        "board detection")
    reason = diversity.degenerate
    if reason is not None:
        raise InputError(f"the {len(observations)} views of {what} cannot determine the hand-eye calibration: "
                         f"{reason}", hint="add views with the flange turned about two or more different axes, by "
                                           "20° or more (docs/calibration.md)")


# --------------------------------------------------------------------- the likely cause
def _quick_error(observations: list[BoardObservation]) -> float:
    """In-sample translation RMS [m] of the best of two closed-form methods on ``observations``."""
    best = float("inf")
    for m in (HandEyeMethod.PARK, HandEyeMethod.SHAH):
        try:
            s = solve_hand_eye(observations, m)
        except (SolverFailed, InputError):
            continue
        best = min(best, _rms([t for t, _ in prediction_errors(observations, s)]))
    return best


def likely_cause(observations: list[BoardObservation], eye_in_hand: bool = True) -> str | None:
    """The usual mistake that makes the views agree (their in-sample error CAUSE_GAIN times
    smaller), or None: every robot rotation transposed (a quaternion conjugated, a rotation
    matrix written by columns), every robot pose inverted (flange_T_base logged). The
    observations are in chain form: eye-to-hand, their poses are the robot poses' inverses,
    and the mistake is undone on the robot poses."""
    now = _quick_error(observations)
    if not np.isfinite(now):
        return None

    def transposed_robot(T: np.ndarray) -> np.ndarray:
        U = T.copy()
        U[:3, :3] = T[:3, :3].T
        return U

    def transposed(G: np.ndarray) -> np.ndarray:
        return transposed_robot(G) if eye_in_hand else invert(transposed_robot(invert(G)))

    tries = (("the robot poses' rotations look transposed (a quaternion conjugated, or a rotation matrix read by "
              "columns)", transposed),
             ("the robot poses look inverted (flange-to-base logged where base-to-flange is read)", invert))
    for text, change in tries:
        other = _quick_error([replace(o, world_T_flange=change(o.world_T_flange)) for o in observations])
        if other * CAUSE_GAIN < now:
            return f"{text}: with that change the views agree to {other * 1e3:.1f} mm instead of {now * 1e3:.0f} mm"
    return None


# --------------------------------------------------------------------- the verdict
def judge(observations: list[BoardObservation], solution: HandEyeSolution, held_out: HeldOut, diversity: Diversity,
          *, eye_in_hand: bool, precision: list[tuple[float, float]] | None = None,
          model_mount: np.ndarray | None = None) -> Verdict:
    """The verdict on ``solution`` (fitted to ``observations`` in chain form) with its
    held-out errors (see the module docstring). ``precision``: per view [m, rad]
    (:func:`detection_precision`), None: the in-sample spread; ``model_mount``: eye-in-hand,
    the cell's flange_T_camera."""
    reasons: list[str] = []
    held = held_out.rms
    in_sample = prediction_errors(observations, solution)
    ins = (_rms([t for t, _ in in_sample]), _rms([r for _, r in in_sample]))
    if precision is not None:
        prec, source = (_rms([p[0] for p in precision]), _rms([p[1] for p in precision])), "PnP"
    else:
        prec, source = ins, "in-sample"
    mis_fit = False
    if not held_out.complete:
        reasons.append(f"the calibration without {', '.join(held_out.failed[:3])} found no solution: the views "
                       "depend on single views")
        mis_fit = True
    else:
        ratio_t, ratio_r = held[0] / max(prec[0], 1e-12), held[1] / max(prec[1], 1e-12)
        if ratio_t > DETECTION_RATIO or ratio_r > DETECTION_RATIO:
            reasons.append(f"held-out error {held[0] * 1e3:.1f} mm / {np.degrees(held[1]):.2f}° RMS is "
                           f"{max(ratio_t, ratio_r):.0f} x the board detection's precision ({prec[0] * 1e3:.2f} mm / "
                           f"{np.degrees(prec[1]):.3f}°; at most {DETECTION_RATIO:g} x)")
            mis_fit = True
        gen_t, gen_r = held[0] / max(ins[0], 1e-12), held[1] / max(ins[1], 1e-12)
        if gen_t > GENERALISATION_RATIO or gen_r > GENERALISATION_RATIO:
            reasons.append(f"held-out error {max(gen_t, gen_r):.1f} x the in-sample error (at most "
                           f"{GENERALISATION_RATIO:g} x): it fits its views but does not predict others")
    if eye_in_hand and model_mount is not None:
        distance = float(np.linalg.norm(solution.flange_T_camera[:3, 3] - model_mount[:3, 3]))
        bound, reference = MOUNT_TOLERANCE, "the cell's camera mount"
    elif eye_in_hand:
        distance, bound, reference = float(np.linalg.norm(solution.flange_T_camera[:3, 3])), MAX_MOUNT_DISTANCE, \
            "the flange"
    else:
        distance, bound, reference = float(np.linalg.norm(solution.world_T_marker[:3, 3])), MAX_MOUNT_DISTANCE, \
            "the flange"
    what = "camera" if eye_in_hand else "board"
    if not distance <= bound:
        reasons.append(f"the {what} lands {distance * 1e3:.0f} mm from {reference} (at most {bound * 1e3:.0f} mm)")
        mis_fit = True
    for issue, message in diversity.issues:
        if issue is DiversityIssue.ONE_AXIS:
            reasons.append(message)
    cause = likely_cause(observations, eye_in_hand) if mis_fit else None
    if cause is not None:
        reasons.insert(0, cause)
    return Verdict(not reasons, tuple(reasons), held, ins, prec, source, distance, bound, reference,
                   diversity.to_dict(), cause)
