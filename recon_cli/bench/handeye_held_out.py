"""Does the data-set path state its own error truly? (``recon bench handeye --unseen N``)

The simulated FR3 calibrations of :mod:`recon_cli.bench.handeye` (the same robot, mount and
detection errors), each with ``views`` views to calibrate from and ``unseen`` more the
calibration never sees. Per seed, ``recon calibrate handeye --dataset``'s choice
(:func:`recon_cli.workflows.handeye_dataset.judge_candidates`: every OpenCV method, the
refinements and the joint-offset candidate, judged by leave-one-view-out error) is made on
the calibration views; then:

- **stated**: the held-out RMS error of the candidate written, what the report tells a user;
- **true**: the RMS error with which that calibration predicts the board pose in the camera at
  the unseen views (from their logged joints, plus the offsets when the candidate has them),
  against the board's true pose there (no detection error);
- the written mount's error against the true mount, beside each OpenCV method's.

A stated error that matches the true one is what makes the report's verdict trustworthy.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from recon_cli.bench.handeye import RobotErrors, Views, fr3_views, simulate
from recon_cli.calibration.logged_joints import match_chain
from recon_cli.calibration.setups import Setup
from recon_cli.geometry.transforms import invert, pose_error
from recon_cli.workflows.handeye_dataset import LoggedJoints, judge_candidates, solve_methods

#: the stated error counts as matching the true one within this fraction
AGREEMENT = 0.25


@dataclass(frozen=True)
class HeldOutRow:
    """One seed [mm, deg]."""

    seed: int
    written: str  # the candidate the data-set path writes
    stated_mm: float
    true_mm: float
    stated_deg: float
    true_deg: float
    mount_mm: float  # the written mount's error against the truth
    closed_form_mm: dict[str, float]  # each OpenCV method's mount error on the same views
    unseen: int  # unseen views predicted

    @property
    def best_closed_form_mm(self) -> float:
        """The closed-form method closest to the truth in this seed (known only in simulation)."""
        return min(self.closed_form_mm.values())

    @property
    def ratio(self) -> float:
        """Stated over true position error."""
        return self.stated_mm / self.true_mm


@dataclass(frozen=True)
class HeldOutStudy:
    views: int
    unseen: int
    rows: list[HeldOutRow]
    seconds: float

    @property
    def median_ratio(self) -> float:
        return float(np.median([r.ratio for r in self.rows]))

    def best_opencv(self) -> tuple[str, float]:
        """The OpenCV method with the smallest median mount error over the seeds, and that median."""
        names = self.rows[0].closed_form_mm.keys()
        medians = {m: float(np.median([r.closed_form_mm.get(m, np.nan) for r in self.rows])) for m in names}
        name = min(medians, key=lambda m: medians[m])
        return name, medians[name]

    @property
    def mount_ratio(self) -> float:
        """The written mount's median error over the best OpenCV method's."""
        return float(np.median([r.mount_mm for r in self.rows])) / self.best_opencv()[1]

    @property
    def agreeing(self) -> int:
        """Seeds whose stated error is within :data:`AGREEMENT` of the true one."""
        return sum(abs(r.ratio - 1.0) <= AGREEMENT for r in self.rows)

    def table(self) -> str:
        lines = [f"{'seed':>4} {'written':<26} {'stated mm':>9} {'true mm':>8} {'stated deg':>10} {'true deg':>9} "
                 f"{'mount mm':>9} {'best CF mm':>10}"]
        for r in self.rows:
            lines.append(f"{r.seed:>4} {r.written:<26} {r.stated_mm:>9.3f} {r.true_mm:>8.3f} {r.stated_deg:>10.4f} "
                         f"{r.true_deg:>9.4f} {r.mount_mm:>9.3f} {r.best_closed_form_mm:>10.3f}")
        mount = np.median([r.mount_mm for r in self.rows])
        oracle = np.median([r.best_closed_form_mm for r in self.rows])
        name, best = self.best_opencv()
        lines.append(f"stated / true held-out error (median): {self.median_ratio:.2f}; within "
                     f"{AGREEMENT:.0%}: {self.agreeing} of {len(self.rows)} seeds")
        lines.append(f"written mount error (median): {mount:.3f} mm, {self.mount_ratio:.2f} x the best OpenCV "
                     f"method's ({name}, {best:.3f} mm); the closest closed form per seed: {oracle:.3f} mm")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {"views": self.views, "unseen": self.unseen, "seconds": self.seconds,
                "median_ratio": self.median_ratio, "agreeing": self.agreeing, "agreement": AGREEMENT,
                "mount_ratio": self.mount_ratio, "best_opencv": list(self.best_opencv()),
                "rows": [asdict(r) for r in self.rows]}


def held_out_study(seeds: int = 20, views: int = 16, unseen: int = 7, first_seed: int = 0,
                   errors: RobotErrors = RobotErrors(), cell_views: Views | None = None  # noqa: B008
                   ) -> HeldOutStudy:
    """The study of the module docstring over seeds ``first_seed`` ... ``first_seed + seeds - 1``."""
    t0 = time.perf_counter()
    cell_views = cell_views or fr3_views()
    kin = cell_views.kin
    assert kin is not None, "views without the cell's kinematics"
    rows = []
    for seed in range(first_seed, first_seed + seeds):
        sim = simulate(cell_views, views + unseen, np.random.default_rng(seed), errors)
        used = sim.corner_views[:views]
        methods, _ = solve_methods(used, Setup.EYE_IN_HAND, None)
        q = {v.name: sim.joints[i] for i, v in enumerate(used)}
        chain = match_chain(kin, list(sim.joints[:views]), [v.base_T_flange for v in used])
        if isinstance(chain, str):
            raise AssertionError(f"the simulated poses do not match the cell's kinematics: {chain}")
        judged = judge_candidates(used, Setup.EYE_IN_HAND, methods, None, True, None, LoggedJoints(chain, q))
        chosen = judged.chosen
        offsets = judged.offsets if judged.offsets is not None else np.zeros(sim.joints.shape[1])
        errs = [pose_error(invert(chain.logged(sim.joints[i] + offsets) @ chosen.solution.X) @ chosen.solution.W,
                           sim.true_camera_T_marker[i]) for i in range(views, len(sim.corner_views))]
        if not errs:
            raise AssertionError(f"seed {seed}: no unseen view left of {len(sim.corner_views)} simulated")
        true_mm = float(np.sqrt(np.mean([e[0] ** 2 for e in errs]))) * 1e3
        true_deg = math.degrees(float(np.sqrt(np.mean([e[1] ** 2 for e in errs]))))
        stated = chosen.held_out.rms
        closed = {m.value: pose_error(s.X, sim.flange_T_camera)[0] * 1e3 for m, s in methods.items()}
        rows.append(HeldOutRow(seed, chosen.name, stated[0] * 1e3, true_mm, math.degrees(stated[1]), true_deg,
                               pose_error(chosen.solution.X, sim.flange_T_camera)[0] * 1e3, closed, len(errs)))
    return HeldOutStudy(views, unseen, rows, time.perf_counter() - t0)
