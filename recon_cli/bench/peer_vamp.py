"""Scan-move requests solved by VAMP (the Vector-Accelerated Motion Planner) for its Panda.

Runs inside VAMP's own virtual environment (VAMP is a benchmark peer, never a dependency of
recon; ``../shared/peers/vamp/build_vamp.sh VENV`` builds it); it imports nothing of recon.
Input: a JSON problem written by ``recon_cli.bench.vamp_peer`` (start/goal pairs in the
Panda's joint order, cuboid obstacles in the robot base frame, settings); output: a JSON of
per-request results on stdout's last line. Times are wall-clock around each call, one core.

    python peer_vamp.py problem.json
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main(problem_path: str) -> None:
    import vamp  # type: ignore[import-not-found]  # only in VAMP's own environment

    p = json.loads(open(problem_path).read())
    module, planner_func, plan_settings, simp_settings = vamp.configure_robot_and_planner_with_kwargs(
        p["robot"], p["planner"])
    env = vamp.Environment()
    for center, euler, half in p["cuboids"]:
        env.add_cuboid(vamp.Cuboid(list(center), list(euler), list(half)))
    if "validate" in p:  # which configurations are valid (collision-free among the cuboids)
        print(json.dumps({"valid": [bool(module.validate(np.asarray(q, dtype=float), env)) for q in p["validate"]]}))
        return
    sampler = module.halton()
    lower, upper = np.asarray(module.lower_bounds()), np.asarray(module.upper_bounds())
    rows = []
    for start, goal in p["pairs"]:
        start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
        row: dict[str, object] = {
            "start_valid": bool(module.validate(start, env)), "goal_valid": bool(module.validate(goal, env)),
            "within_bounds": bool(np.all(start >= lower) and np.all(start <= upper)
                                  and np.all(goal >= lower) and np.all(goal <= upper))}
        if row["start_valid"] and row["goal_valid"]:
            sampler.reset()
            t0 = time.perf_counter()
            result = planner_func(start, goal, env, plan_settings, sampler)
            t1 = time.perf_counter()
            solved = bool(result.solved)
            simple = module.simplify(result.path, env, simp_settings, sampler) if solved else None
            t2 = time.perf_counter()
            path = simple.path.numpy() if simple is not None else None
            row.update({"solved": solved, "plan": t1 - t0, "simplify": t2 - t1, "total": t2 - t0,
                        "vamp_ns": int(result.nanoseconds), "iterations": int(result.iterations),
                        "path_length": float(np.sum(np.abs(np.diff(path, axis=0)))) if path is not None else None})
        rows.append(row)
    print(json.dumps({"vamp": getattr(vamp, "__version__", "?"), "robot": p["robot"], "planner": p["planner"],
                      "lower": lower.tolist(), "upper": upper.tolist(), "rows": rows}))


if __name__ == "__main__":
    main(sys.argv[1])
