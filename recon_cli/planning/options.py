"""Options of a planning request: which OMPL planner, limits, simplification, timing scales.

A light module (no OMPL, pinocchio or MuJoCo) so that the configuration and the command
line can take their defaults from it without loading the planner.
"""

from __future__ import annotations

from dataclasses import dataclass

from recon_cli.errors import InputError, UnknownNameError

#: geometric planners of the OMPL 2.x wheel, by the names OMPL (and MoveIt) give them
PLANNERS = ("RRTConnect", "RRT", "RRTstar", "PRM", "PRMstar", "KPIECE1", "BKPIECE1", "LBKPIECE1",
            "FMT", "BFMT", "BITstar", "AORRTC", "InformedRRTstar", "SORRTstar")


#: path simplifications after the search (PlanOptions.simplify)
SIMPLIFICATIONS = ("shortcut", "reduce", "full", "none")


@dataclass(frozen=True)
class PlanOptions:
    """Options of a planning request. Optimizing planners (RRT*, PRM*, BIT*, ...) stop at
    their first exact solution: the request asks for a path, shortened afterwards.

    simplify: "shortcut" (OMPL's reduceVertices, then ``shortcut_rounds`` x
    (partialShortcutPath, reduceVertices): shortcuts between random vertex pairs, then
    per-joint shortcuts), "reduce" (reduceVertices only), "full" (OMPL's simplifySolution
    within ``simplify_time``), or "none" (docs/benchmarks.md compares them).
    range: RRT-family step length in joint space (0 lets OMPL choose).
    """

    planner: str = "RRTConnect"
    time_limit: float = 5.0  # [s] for the search
    simplify: str = "shortcut"
    shortcut_rounds: int = 1
    simplify_time: float = 1.0  # [s] budget of the "full" simplification
    range: float = 1.5
    velocity_scale: float = 0.15  # of the joint velocity limits (thesis script manager)
    acceleration_scale: float = 0.3  # of the joint acceleration limits
    max_step: float = 0.005  # [m] largest robot-point motion between checked samples
    ik_solutions: int = 4  # goal configurations tried for a pose goal

    def __post_init__(self) -> None:
        if self.planner not in PLANNERS:
            raise UnknownNameError("planner", self.planner, PLANNERS)
        if self.simplify not in SIMPLIFICATIONS:
            raise UnknownNameError("simplification", self.simplify, SIMPLIFICATIONS)
        if self.shortcut_rounds < 1:
            raise InputError(f"shortcut rounds {self.shortcut_rounds} is not a positive number",
                             hint="use 1 (default) or more")
