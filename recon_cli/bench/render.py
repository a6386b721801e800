"""Terminal output of the benchmarks: rich tables and summary lines (what ``recon bench ...``
prints after writing its JSON and figures)."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from rich.console import JustifyMethod
from rich.table import Table

THESIS_TABLE_4_2 = "thesis Table 4.2: 1.532 mm, 0.0853°"


def _table(title: str, columns: tuple[str, ...], justify: JustifyMethod = "right") -> Table:
    table = Table(title=title)
    for col in columns:
        table.add_column(col, justify=justify)
    return table


def ik_report(result, kind: str, solutions: int) -> Iterator:
    table = _table(f"IK benchmark, {kind} cell, {result.n_poses} poses (from {result.samples_drawn} random "
                   "configurations)", ("measure", "value"))
    rows = [
        ("success, first solution", f"{result.success_first * 100:.1f} %"),
        ("median time to first solution", f"{result.median_ms_first:.2f} ms"),
        ("p90 time to first solution", f"{result.p90_ms_first:.2f} ms"),
        (f"success, asking for {solutions}", f"{result.success_multi * 100:.1f} %"),
        ("mean distinct solutions found", f"{result.mean_solutions:.2f}"),
        ("median time per solution", f"{result.median_ms_per_solution:.2f} ms"),
        ("max position error", f"{result.max_position_error_m:.2e} m"),
        ("max rotation error", f"{result.max_rotation_error_rad:.2e} rad"),
        ("all within soft limits", str(result.all_within_soft_limits)),
        ("all collision-free", str(result.all_collision_free)),
        ("min separation of solutions", f"{result.min_pairwise_separation:.3f}"),
    ]
    for row in rows:
        table.add_row(*row)
    yield table


def sim_report(result) -> Iterator:
    table = _table(f"24 views of eq. 4.1 around the {result.object_name}: board found in {result.found} of "
                   f"{len(result.rows)}", ("view", "corners", "markers", "ChArUco pose error", "reprojection",
                                            "capture", "points"))
    for r in result.rows:
        err = f"{r.translation_error_mm:.3f} mm / {r.rotation_error_deg:.4f}°" if r.found else "not found"
        rep = f"{r.reprojection_px:.3f} px" if r.found else "-"
        table.add_row(str(r.view), str(r.corners), str(r.markers), err, rep, f"{r.capture_s:.3f} s", str(r.points))
    yield table
    found = [r for r in result.rows if r.found]
    if found:
        yield (f"mean ChArUco pose error {np.mean([r.translation_error_mm for r in found]):.3f} mm, "
               f"{np.mean([r.rotation_error_deg for r in found]):.4f}° ({THESIS_TABLE_4_2})")
    times = [r.capture_s for r in result.rows]
    yield f"capture time (render + noise, 1600 x 1200): median {np.median(times):.3f} s, max {max(times):.3f} s"
    yield f"move home -> view 1: {result.move}"


def registration_report(data: dict) -> Iterator:
    m = data["charuco_mean"]
    covered = ", ".join(map(str, data["covered_views"]))
    k = data.get("kinematics_mean")
    realism = (data.get("realism") or {}).get("name", "ideal")
    yield (f"{data['views']} views of the {data['object']} (board covered in views {covered}; realism {realism}): "
           f"ChArUco pose error mean {m['translation_mm']:.3f} mm, {m['rotation_deg']:.4f}° ({THESIS_TABLE_4_2})"
           + ("" if k is None else f"; forward kinematics {k['translation_mm']:.3f} mm, {k['rotation_deg']:.4f}°"))
    table = _table(f"fused cloud vs ground truth (noise sigma at 0.6 m: {data['noise_sigma_at_0.6m_mm']:.3f} mm)",
                   ("case", "mean", "std", "±0.5 mm", "coverage (visible)", "pose error", "relative", "time"))
    for r in data["cases"]:
        visible = "-" if r.coverage_visible is None else f"{r.coverage_visible * 100:.2f} %"
        table.add_row(r.case, f"{r.mean_mm:+.3f} mm", f"{r.std_mm:.3f} mm", f"{r.within_half_mm * 100:.1f} %", visible,
                      f"{r.pose_error_mm:.3f} mm / {r.pose_error_deg:.4f}°",
                      f"{r.relative_error_mm:.3f} mm / {r.relative_error_deg:.4f}°", f"{r.seconds:.1f} s")
    yield table


def sequence_report(summary: dict, n: int, velocity_scale: float, acceleration_scale: float) -> Iterator:
    table = _table(f"eq. 4.1 from the Table 4.1 start, {n} runs per case (velocity x{velocity_scale:g}, "
                   f"acceleration x{acceleration_scale:g})",
                   ("case", "mean t_p", "vs A", "mean n_req", "max n_req", "failed", "thesis t_p / n_req",
                    "wall / run"))
    for case, v in summary.items():
        th = v["thesis"]
        table.add_row(case, f"{v['t_p_mean']:.2f} s", "-" if v["vs_A"] is None else f"{v['vs_A'] * 100:+.2f} %",
                      f"{v['n_req_mean']:.2f}", str(v["n_req_max"]), str(v["failed"]),
                      "-" if th is None else f"{th[0]:.2f} s / {th[1]:.2f}", f"{v['wall_s_mean']:.1f} s")
    yield table


def tour_report(summary: dict, rows, velocity_scale: float, acceleration_scale: float) -> Iterator:
    """``recon bench tour``: case D's tour against the optimal one on the same planned durations."""
    table = _table(f"eq. 4.1, {summary['views']} views from the Table 4.1 start, the optimal tour on the same "
                   f"planned durations (velocity x{velocity_scale:g}, acceleration x{acceleration_scale:g})",
                   ("seed", "B (own graph)", "C", "D (ours)", "D's search, every edge planned", "optimal", "gap",
                    "gap [s]", "proven", "requests D / matrix", "solve"))
    for r in rows:
        table.add_row(str(r.seed), f"{r.case_b:.2f} s", f"{r.case_c:.2f} s", f"{r.ours:.2f} s",
                      f"{r.search_full:.2f} s", f"{r.optimal:.2f} s", f"{r.gap_pct:+.2f} %", f"{r.gap_s:.2f} s",
                      "yes" if r.proven_optimal else "no", f"{r.requests_ours} / {r.requests_matrix}",
                      f"{r.solve_seconds:.2f} s")
    yield table
    yield (f"mean over {summary['seeds']} seeds: D {summary['ours_mean']:.2f} s, "
           f"optimal {summary['optimal_mean']:.2f} s (D's local search with every edge planned: "
           f"{summary['search_full_mean']:.2f} s); closing the gap would save {summary['gap_s_mean']:.2f} s of "
           f"robot time per scan "
           f"({summary['gap_pct_mean']:.2f} %, at most {summary['gap_pct_max']:.2f} %), at the price of planning "
           f"the whole matrix: {summary['requests_matrix_mean']:.0f} requests instead of "
           f"{summary['requests_ours_mean']:.1f} ({summary['plan_seconds_mean']:.0f} s more planning here)")


def profile_report(result) -> Iterator:
    """``recon bench profile``: the wall clock of the main job by stage; the rows add up to the total."""
    s = result.settings
    table = _table(f"{s['command']}, {s['object']}, seed {s['seed']}, image scale {s['resolution']:g}: wall clock "
                   "by stage (innermost stage on the call stack)", ("stage", "wall clock", "share", "calls"))
    table.columns[0].justify = "left"
    for r in result.rows:
        calls = " + ".join(str(f.calls) for f in r.functions)  # per function of the stage
        table.add_row(r.stage, f"{r.seconds:.2f} s", f"{r.share * 100:.1f} %", calls)
    table.add_row("total", f"{result.total_s:.2f} s", "100.0 %", "")
    yield table
    missing = [f"{f.module}.{f.function}" for r in result.rows for f in r.functions if not f.found]
    if missing:
        yield f"not found (their time is in the stage around them, or in 'other'): {', '.join(missing)}"
    ended = " (interrupted)" if result.interrupted else ""
    yield (f"{result.scans} scans{ended}; the workflow ran {result.workflow_s:.1f} s of the {result.total_s:.1f} s, "
           "times with the profiler's overhead")


def viewplan_report(rows, n: int, dc: float, cell: str) -> Iterator:
    table = _table(f"N = {n}, d_c = {dc} m, {cell} cell",
                   ("object", "method", "initial", "scans", "coverage", "mean", "std", "infeasible", "requests",
                    "trajectories", "wall clock"))
    for r in rows:
        table.add_row(r.object_name, r.method, r.initial, str(r.scans), f"{r.coverage * 100:.2f} %",
                      f"{r.mean_mm:+.3f} mm", f"{r.std_mm:.3f} mm", str(r.infeasible), str(r.requests),
                      f"{r.trajectory_s:.1f} s", f"{r.seconds:.1f} s")
    yield table


def planners_report(summary: dict, n: int, time_limit: float, thesis: dict, peer: dict | None) -> Iterator:
    table = _table(f"Table 4.1 problem, {n} requests per planner, {time_limit:g} s each",
                   ("planner", "solved", "min", "median", "p90", "max", "path length", "trajectory"))
    for name, sm in summary.items():
        table.add_row(name, f"{sm['success_rate'] * 100:.1f} %", f"{sm['time_min']:.3f} s",
                      f"{sm['time_median']:.3f} s", f"{sm['time_p90']:.3f} s", f"{sm['time_max']:.3f} s",
                      f"{sm['path_length_median']:.2f}", f"{sm['trajectory_duration_median']:.2f} s")
    for name, t in thesis.items():
        table.add_row(f"{name} (thesis)", "", f"{t.min():.3f} s", f"{float(np.median(t)):.3f} s",
                      f"{np.percentile(t, 90):.3f} s", f"{t.max():.3f} s", "", "")
    if peer:
        table.add_row(f"RRTConnect (mplib, range {peer['range']:g})", f"{peer['success_rate'] * 100:.1f} %",
                      "", f"{peer['time_median']:.3f} s", "", "", f"{peer['path_length_median']:.2f}", "")
    yield table
    if peer and "RRTConnect" in summary:
        ours = summary["RRTConnect"]["time_median"]
        yield (f"RRTConnect median: recon {ours:.3f} s, mplib {peer['time_median']:.3f} s, "
               f"ratio recon/mplib {ours / peer['time_median']:.2f}")


def cell_planners_report(result: dict) -> Iterator:
    """``recon bench planners --cell NAME``: recon's planners and the peers on the same scan moves."""
    meta = result["meta"]
    table = _table(f"{meta['cell']} cell: {meta['requests']} scan moves at {meta['camera_distance']:g} m, "
                   f"{meta['time_limit']:g} s each", ("planner", "solved", "median", "p90", "path length"))
    for name, sm in result["summary"].items():
        table.add_row(f"{name} (recon)", f"{sm['success_rate'] * 100:.1f} %", f"{sm['time_median'] * 1e3:.2f} ms",
                      f"{sm['time_p90'] * 1e3:.2f} ms", f"{sm['path_length_median']:.2f}")
    for peer in result["peers"]:
        asked = peer.get("asked", peer.get("requests"))
        table.add_row(f"RRTConnect ({peer['name']})", f"{peer['success_rate'] * 100:.1f} % of {asked}",
                      f"{peer['time_median'] * 1e3:.2f} ms", "", f"{peer['path_length_median']:.2f}")
    yield table
    for name, r in result["ratios"].items():
        yield (f"RRTConnect on the {r['requests']} requests both solved: recon {r['recon_median'] * 1e3:.2f} ms, "
               f"{name} {r['peer_median'] * 1e3:.2f} ms (median); recon / {name} = {r['ratio']:.1f}")
    for peer in result["peers"]:
        if peer.get("invalid_start_or_goal"):
            yield (f"{peer['name']}: {peer['invalid_start_or_goal']} of {peer['requests']} requests left out (start "
                   "or goal invalid in its own robot model)")
    if result["profile"]:
        yield "where recon's planning time goes (cProfile, cumulative):"
        yield from result["profile"]


def inputs_report(result) -> Iterator:
    """The hostile-input campaign: cases, refused, accepted and failed per input kind."""
    table = _table("hostile and careless inputs, each in its own recon process",
                   ("input", "cases", "refused", "accepted", "failed", "slowest [s]", "peak [MB]"))
    for kind, c in result.counts.items():
        table.add_row(kind, str(c.cases), str(c.refused), str(c.accepted), str(c.failed), f"{c.slowest_s:.1f}",
                      f"{c.peak_mb:.0f}")
    yield table
    for f in result.failures:
        yield f"failed: {f.kind} #{f.index}: {f.reason} ({f.last_line[:160]})"
