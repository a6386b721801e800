"""The Table 4.1 problem solved by mplib 0.2.1 (SAPIEN's C++ OMPL + FCL planner).

Runs inside its own virtual environment (mplib pins numpy < 2, so it never enters recon's
dependencies); it imports nothing of recon. Input: a JSON problem written by
``recon_cli.bench.mplib_peer`` (URDF, SRDF, start, goal, object box, time limit, number of
requests); output: a JSON of per-request times on stdout's last line.

    python peer_mplib.py problem.json
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def main(problem_path: str) -> None:
    import mplib
    from mplib.collision_detection.fcl import Box, CollisionObject, FCLObject

    p = json.loads(open(problem_path).read())
    box = FCLObject("object_box", mplib.Pose(p["box_center"], [1, 0, 0, 0]),
                    [CollisionObject(Box(np.array(p["box_size"], dtype=float)))], [mplib.Pose()])
    planner = mplib.Planner(p["urdf"], move_group=p["move_group"], srdf=p["srdf"],
                            joint_vel_limits=np.array(p["velocity"]) * p["velocity_scale"],
                            joint_acc_limits=np.array(p["acceleration"]) * p["acceleration_scale"],
                            objects=[box])
    acm = planner.planning_world.get_allowed_collision_matrix()
    for link in p["environment_links"]:  # the box stands on the table and the board
        acm.set_entry("object_box", link, True)
    # one problem asked n times (Table 4.1), or a list of start/goal pairs once each
    if "pairs" in p:
        requests = [(np.array(a, dtype=float), np.array(b, dtype=float)) for a, b in p["pairs"]]
    else:
        requests = [(np.array(p["start"], dtype=float), np.array(p["goal"], dtype=float))] * p["n"]
    start, goal = requests[0]
    idx = planner.move_group_joint_indices
    results = {}
    for rrt_range in p["ranges"]:
        planning, total, ok, lengths = [], [], [], []
        for start, goal in requests:
            # the OMPL part alone: RRTConnect search + simplification (as recon's plan time)
            t0 = time.perf_counter()
            status, path = planner.planner.plan(start[idx], [goal[idx]], time=p["time_limit"],
                                                range=rrt_range, fixed_joints=set(), simplify=True)
            planning.append(time.perf_counter() - t0)
            ok.append(status == "Exact solution")
            if ok[-1]:
                lengths.append(float(np.sum(np.abs(np.diff(np.asarray(path), axis=0)))))
            # the whole request including mplib's TOPP time parameterization
            t0 = time.perf_counter()
            planner.plan_qpos([goal], start, time_step=0.01, rrt_range=rrt_range,
                              planning_time=p["time_limit"], simplify=True)
            total.append(time.perf_counter() - t0)
        results[str(rrt_range)] = {"planning": planning, "total": total, "solved": ok, "path_lengths": lengths}
    collisions = []
    for q in requests[0]:
        planner.robot.set_qpos(planner.pad_move_group_qpos(q), True)
        collisions.append([f"{c.link_name1}/{c.link_name2}" for c in planner.planning_world.check_collision()])
    print(json.dumps({"mplib": "0.2.1", "results": results,
                      "start_collisions": collisions[0], "goal_collisions": collisions[1]}))


if __name__ == "__main__":
    main(sys.argv[1])
