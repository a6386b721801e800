"""``recon bench ...``: the thesis' benchmarks (and ours), each writing JSON, a table and a figure.

The tables are drawn by :mod:`recon_cli.bench.render`; this module parses and calls.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path
from typing import Annotated, Literal

import typer

from recon_cli.bench import render
from recon_cli.bench.cell_planners import PEERS, run_cell_planners
from recon_cli.bench.handeye import handeye_study
from recon_cli.bench.handeye_held_out import held_out_study
from recon_cli.bench.ik import IKBenchConfig, run_ik_bench
from recon_cli.bench.inputs import MAKERS, run_campaign
from recon_cli.bench.mplib_peer import run_mplib
from recon_cli.bench.planners import DEFAULT_PLANNERS, run_planner_bench, thesis_times, write_results
from recon_cli.bench.profile import MAIN_N, PSTATS_FILE, QUICK_N, QUICK_RESOLUTION, run_profile, stage_png
from recon_cli.bench.registration import run_registration_bench
from recon_cli.bench.sequence import CASES, ecdf_png, run_sequence_bench, summarize
from recon_cli.bench.sim import run_sim_bench
from recon_cli.bench.tour import QUICK_VIEW_STEP, run_tour_bench, summarize_tours, tour_png
from recon_cli.bench.viewplan import coverage_png, run_viewplan_bench
from recon_cli.cli.app import bench_app
from recon_cli.cli.options import (
    CellOpt,
    D,
    DcOpt,
    ForceOpt,
    PlanningTimeOpt,
    RealismOpt,
    ResolutionOpt,
    SafetyOpt,
    ScansOpt,
    SeedOpt,
    SimplificationName,
    make_cell,
    name_list,
    object_metavar,
    object_names,
    object_option,
    output_folder,
    realism_profile,
    split_names,
)
from recon_cli.console import console, progress_bar, write_json
from recon_cli.errors import InputError
from recon_cli.perception.sensor import cell_sensor
from recon_cli.planning.options import PLANNERS
from recon_cli.robot.description import CellConfig, CellName
from recon_cli.viewplan.policy import Method

OutOpt = Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default "
                                                                 "runs/bench-<name>-<time>).")]
#: the cases of ``recon bench sequence`` for its help (the parser checks recon_cli.bench.sequence.CASES,
#: which loads the planner, when a command line is parsed)
SEQUENCE_CASES = ("A", "B", "C", "D", "A0")
#: the peers ``recon bench planners`` can compare with
Peer = Literal["none", "mplib", "vamp", "all"]


def _sequence_cases() -> tuple[str, ...]:

    return CASES


@bench_app.command("ik")
def bench_ik(
    n: Annotated[int, typer.Option("--poses", min=1, max=100_000, help="Number of camera poses.")] = 500,
    solutions: Annotated[int, typer.Option(min=1, max=32, help="Solutions asked per pose in the second run.")]
    = D.planner.ik_solutions,
    cell: CellOpt = D.cell.kind,
    safety: SafetyOpt = None,
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """IK success rate and time on random reachable camera poses around the table."""

    folder = output_folder(out, "bench ik", force=force).path
    c = make_cell(cell, safety)
    cfg = IKBenchConfig(n_poses=n, solutions=solutions, seed=seed)
    with progress_bar() as update:
        result = run_ik_bench(c, cfg, update)
    write_json(folder / "bench_ik.json", {"config": cfg.__dict__, "safety_distance": c.config.safety_distance,
                                          "result": result.to_dict()})
    for item in render.ik_report(result, c.config.name, solutions):
        console.print(item)
    console.print(f"results: {folder / 'bench_ik.json'}")


@bench_app.command("sim")
def bench_sim(
    object_name: Annotated[str, typer.Option("--object", metavar=object_metavar(True), callback=object_option(True),
                                             help="Object on the board.")] = "drill",
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Board detection in the 24 views of eq. 4.1, capture time, execution precision."""


    folder = output_folder(out, "bench sim", force=force).path
    with progress_bar() as update:
        result = run_sim_bench(folder, object_name, seed, update)
    write_json(folder / "bench_sim.json", {"object": result.object_name, "views": [asdict(r) for r in result.rows],
                                           "move": result.move})
    for item in render.sim_report(result):
        console.print(item)
    console.print(f"results: {folder / 'bench_sim.json'}, picture: {folder / 'eq_4_1_views.png'}")


@bench_app.command("registration")
def bench_registration(
    object_name: Annotated[str, typer.Option("--object", metavar=object_metavar(True), callback=object_option(True),
                                             help="Object ('auto': the drill if the YCB data is here, else the "
                                                  "bottle).")] = D.scene.object_name,
    resolution: ResolutionOpt = D.sensor.resolution,
    seed: SeedOpt = D.seed,
    realism: RealismOpt = D.realism.name,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Thesis 4.2: ChArUco pose errors (Table 4.2) and global vs local registration accuracy."""

    profile = realism_profile(realism)
    folder = output_folder(out, "bench registration", force=force, inputs=(Path(realism),)).path
    with progress_bar() as update:
        data = run_registration_bench(folder, object_name, seed, resolution, update, profile)
    write_json(folder / "bench_registration.json", data)
    for item in render.registration_report(data):
        console.print(item)
    console.print(f"results: {folder / 'bench_registration.json'}, histogram: {folder / 'distances.png'}, "
                  f"mesh: {data['mesh']}")


@bench_app.command("sequence")
def bench_sequence(
    runs: Annotated[int, typer.Option("--runs", min=1, max=10_000, help="Runs per case.")] = 500,
    quick: Annotated[bool, typer.Option("--quick", help="CI mode: 3 runs per case.")] = False,
    cases: Annotated[str, typer.Option(metavar="<" + "|".join(SEQUENCE_CASES) + ">,...",
                                       callback=name_list(_sequence_cases),
                                       help="Comma-separated cases: A, B, C, D (ours), A0 (recon run's default "
                                            "order).")] = "A,B,C,D,A0",
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Thesis 4.3: total trajectory time and planning requests of the 24 views of eq. 4.1."""


    chosen = split_names(cases)
    folder = output_folder(out, "bench sequence", force=force).path
    n = 3 if quick else runs
    plan = D.planner
    with progress_bar() as update:
        rows = run_sequence_bench(n, seed, chosen, update, plan)
    summary = summarize(rows)
    write_json(folder / "bench_sequence.json", {"runs_per_case": n, "seed": seed, "planner": plan,
                                                "velocity_scale": plan.velocity_scale,
                                                "acceleration_scale": plan.acceleration_scale, "summary": summary,
                                                "runs": [asdict(r) for r in rows]})
    ecdf_png(folder / "t_p_ecdf.png", rows)
    for item in render.sequence_report(summary, n, plan.velocity_scale, plan.acceleration_scale):
        console.print(item)
    console.print(f"results: {folder / 'bench_sequence.json'}, plot: {folder / 't_p_ecdf.png'}")


@bench_app.command("tour")
def bench_tour(
    seeds: Annotated[int, typer.Option("--seeds", min=1, max=1000, help="Seeds (runs 0 ... N-1 of bench sequence "
                                                                        "--seed).")] = 5,
    quick: Annotated[bool, typer.Option("--quick", help="CI mode: 1 seed, every second view (12).")] = False,
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Sequence optimization: case D's tour against the optimal tour on the same planned durations."""

    folder = output_folder(out, "bench tour", force=force).path
    n, step = (1, QUICK_VIEW_STEP) if quick else (seeds, 1)
    plan = D.planner
    with progress_bar() as update:
        rows = run_tour_bench(n, seed, step, update, plan)
    summary = summarize_tours(rows)
    write_json(folder / "bench_tour.json", {"seeds": n, "seed": seed, "views_step": step, "planner": plan,
                                            "velocity_scale": plan.velocity_scale,
                                            "acceleration_scale": plan.acceleration_scale, "summary": summary,
                                            "runs": [asdict(r) for r in rows]})
    tour_png(folder / "tour_gap.png", rows)
    for item in render.tour_report(summary, rows, plan.velocity_scale, plan.acceleration_scale):
        console.print(item)
    console.print(f"results: {folder / 'bench_tour.json'}, plot: {folder / 'tour_gap.png'}")


@bench_app.command("inputs")
def bench_inputs(
    per_kind: Annotated[int, typer.Option("--per-kind", min=1, max=10_000, help="Cases per input kind.")] = 50,
    kinds: Annotated[str, typer.Option("--input-kinds", metavar="KIND,...",
                                       help=f"Input kinds (default all): {', '.join(MAKERS)}.")] = "",
    workers: Annotated[int, typer.Option("--workers", min=1, max=64, help="Cases at once.")] = 2,
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Careless and hostile input files through the command line, each case in its own recon
    process: refused in one line, accepted, or failed (traceback, > 20 s, > 1 GB, echo, code run)."""

    chosen = tuple(k.strip() for k in kinds.split(",") if k.strip()) or tuple(MAKERS)
    for kind in chosen:
        if kind not in MAKERS:
            raise InputError(f"--input-kinds: unknown input kind {kind!r}", hint=f"choose from: {', '.join(MAKERS)}")
    folder = output_folder(out, "bench inputs", force=force).path
    with progress_bar() as update:
        result = run_campaign(folder, per_kind, seed, workers, chosen, update)
    for item in render.inputs_report(result):
        console.print(item)
    console.print(f"results: {folder / 'bench_inputs.json'}, failing cases: {folder / 'failures'}")
    if result.failures:
        raise typer.Exit(1)


@bench_app.command("profile")
def bench_profile(
    object_name: Annotated[str, typer.Option("--object", metavar=object_metavar(True), callback=object_option(True),
                                             help="Object scanned ('auto': the drill if the YCB data is here, "
                                                  "else the bottle).")] = "bottle",
    n: ScansOpt = MAIN_N,
    quick: Annotated[bool, typer.Option("--quick", help=f"CI mode: {QUICK_N} scans at image scale "
                                                        f"{QUICK_RESOLUTION:g}.")] = False,
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Wall clock of the main job (recon autoscan --dc 0.55 --n 16) by stage, under cProfile."""

    folder = output_folder(out, "bench profile", force=force, inputs=(Path(object_name),)).path
    n, resolution = (QUICK_N, QUICK_RESOLUTION) if quick else (n, D.sensor.resolution)
    with progress_bar() as update:
        result = run_profile(folder, object_name, n, seed, resolution, update)
    write_json(folder / "bench_profile.json", {"quick": quick, **result.to_dict()})
    stage_png(folder / "stage_profile.png", result)
    for item in render.profile_report(result):
        console.print(item)
    console.print(f"results: {folder / 'bench_profile.json'}, plot: {folder / 'stage_profile.png'}, "
                  f"profile: {folder / PSTATS_FILE}, autoscan: {result.folder}")


@bench_app.command("viewplan")
def bench_viewplan(
    objects: Annotated[str, typer.Option(metavar=object_metavar(False)[:-1] + ">,...",
                                         callback=name_list(lambda: object_names(False), files=True),
                                         help="Comma-separated objects: names or mesh files (default: the "
                                              "built-ins).")]
    = "wood_block,toy_blocks,bottle,mug",
    methods: Annotated[str, typer.Option(metavar="<" + "|".join(m.value for m in Method) + ">,...",
                                         callback=name_list(lambda: [m.value for m in Method]),
                                         help="Comma-separated view planning methods.")] = "ellipsoid,sphere,random",
    n: ScansOpt = D.viewplan.n,
    dc: DcOpt = None,
    cell: CellOpt = D.cell.kind,
    resolution: ResolutionOpt = D.sensor.resolution,
    seed: SeedOpt = D.seed,
    realism: RealismOpt = D.realism.name,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Thesis 4.4: ellipsoid view planner vs evenly spread and random views, every object."""


    chosen = split_names(methods)
    cell_cfg = CellConfig(kind=CellName.parse(cell))
    dc = cell_sensor(cell_cfg.cell_file).default_distance if dc is None else dc
    profile = realism_profile(realism)
    folder = output_folder(out, "bench viewplan", force=force, inputs=(Path(realism),)).path
    with progress_bar() as update:
        rows = run_viewplan_bench(folder, split_names(objects), chosen, n, dc, seed,
                                  resolution, cell_cfg, update, profile)
    write_json(folder / "bench_viewplan.json", {"n": n, "d_c": dc, "cell": cell, "realism": profile.summary(),
                                                "resolution": resolution, "rows": [asdict(r) for r in rows]})
    coverage_png(folder / "coverage.png", rows)
    for item in render.viewplan_report(rows, n, dc, cell):
        console.print(item)
    console.print(f"results: {folder / 'bench_viewplan.json'}, plot: {folder / 'coverage.png'}")


@bench_app.command("planners")
def bench_planners(
    n: Annotated[int, typer.Option("--requests", min=1, max=100_000, help="Requests per planner.")] = 1000,
    planners: Annotated[str, typer.Option(metavar="<" + "|".join(PLANNERS) + ">,...|default",
                                          callback=name_list(lambda: PLANNERS, keyword="default"),
                                          help="Comma-separated OMPL planners, or 'default' (those of the "
                                               "table in docs/benchmarks.md).")] = "default",
    time_limit: PlanningTimeOpt = D.planner.time_limit,
    quick: Annotated[bool, typer.Option("--quick", help="CI mode: 10 requests of RRTConnect and RRT.")] = False,
    peer: Annotated[Peer, typer.Option(help="Also run a peer on the same requests: 'mplib', 'vamp' (Franka cells; "
                                            "RECON_VAMP_VENV names its environment), 'all' or 'none'.")]
    = "none",
    cell: CellOpt = D.cell.kind,
    view_distance: Annotated[float | None, typer.Option(min=0.05, max=2.0, help="Camera distance of the scan "
                                                       "moves' views on a cell other than the gantry [m] "
                                                       "(default: the cell camera's scan distance).")] = None,
    peer_n: Annotated[int, typer.Option("--peer-requests", min=1, max=10_000,
                                        help="Requests for the peer (per RRT range tried).")] = 200,
    simplify: Annotated[SimplificationName, typer.Option(help="Path simplification.")] = D.planner.simplify,
    shortcut_rounds: Annotated[int, typer.Option(min=1, max=100, help="Rounds of per-joint shortcuts (shortcut).")]
    = D.planner.shortcut_rounds,
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Planning benchmark: the Table 4.1 problem on the thesis' gantry cell (thesis 4.1), the
    moves of a scan on any other cell; success, plan times, path lengths, peers side by side."""

    options = replace(D.planner, simplify=simplify, shortcut_rounds=shortcut_rounds)
    names = list(DEFAULT_PLANNERS) if planners.strip() == "default" else split_names(planners)
    if quick:
        names, n = ["RRTConnect", "RRT"], min(n, 10)
    config = CellConfig(kind=CellName.parse(cell))
    if config.name != "gantry":
        peers = PEERS if peer == "all" else (() if peer == "none" else (peer,))
        folder = output_folder(out, "bench planners", force=force).path
        with progress_bar() as update:
            result = run_cell_planners(folder, config, names, n, time_limit, seed, peers, options, update,
                                       status=lambda text: console.print(text), distance=view_distance)
        for item in render.cell_planners_report(result):
            console.print(item)
        console.print(f"results: {folder / 'bench_planners.json'}, {folder / 'requests.csv'}, "
                      f"profile: {folder / 'profile.txt'}, plot: {folder / 'plan_times.png'}")
        return
    if peer in ("vamp", "all"):
        raise InputError("VAMP plans for its compiled Panda, not the thesis' gantry cell",
                         hint="use --peer mplib here, or --cell fr3 --peer vamp")
    folder = output_folder(out, "bench planners", force=force).path
    with progress_bar() as update:
        rows = run_planner_bench(names, n, time_limit, seed, update, options)
    peer_summary = None
    if peer == "mplib":

        with console.status("mplib 0.2.1 on the same problem ..."):
            peer_summary = run_mplib(folder, peer_n, time_limit)
    meta = {"n": n, "time_limit": time_limit, "seed": seed, "planners": names, "problem": "Table 4.1",
            "simplify": simplify, "shortcut_rounds": shortcut_rounds,
            "plan_time": "search + simplification, one core"}
    summary = write_results(folder, rows, meta, peer_summary)
    for item in render.planners_report(summary, n, time_limit, thesis_times(), peer_summary):
        console.print(item)
    console.print(f"results: {folder / 'bench_planners.json'}, {folder / 'requests.csv'}, "
                  f"plot: {folder / 'plan_times.png'}")


@bench_app.command("handeye")
def bench_handeye(
    seeds: Annotated[int, typer.Option("--seeds", min=1, max=1000, help="Simulated calibrations (seeds "
                                                                        "--seed ... --seed + N - 1).")] = 20,
    views: Annotated[int, typer.Option("--board-views", min=5, max=28, help="Board views per calibration, drawn "
                                                                           "from the FR3 cell's reachable ones.")]
    = 16,
    joints: Annotated[bool, typer.Option("--joints/--no-joints", help="Also estimate the joint zero offsets "
                                                                      "(row recon+joints).")] = True,
    unseen: Annotated[int, typer.Option("--unseen", min=0, max=12, help="Also run the data-set path "
                                                                        "(calibrate handeye --dataset) per seed and "
                                                                        "compare its stated held-out error with its "
                                                                        "true error on N views it never saw (0: "
                                                                        "not).")] = 0,
    seed: SeedOpt = D.seed,
    out: OutOpt = None,
    force: ForceOpt = False,
) -> None:
    """Hand-eye calibration with imperfect robot poses on the FR3 cell (simulation with a known truth): OpenCV's
    methods against recon's refinement with flange pose errors, the mount error over the seeds."""
    folder = output_folder(out, "bench handeye", force=force).path
    with console.status(f"{seeds} simulated calibrations of {views} views"):
        study = handeye_study(seeds=seeds, views=views, first_seed=seed, joints=joints)
    write_json(folder / "bench_handeye.json", study.to_dict())
    console.print(study.table())
    console.print(f"{study.seconds:.1f} s; results: {folder / 'bench_handeye.json'}")
    if unseen:
        with console.status(f"the data-set path on {seeds} calibrations, {unseen} unseen views each"):
            held = held_out_study(seeds=seeds, views=views, unseen=unseen, first_seed=seed)
        write_json(folder / "bench_handeye_held_out.json", held.to_dict())
        console.print(held.table())
        console.print(f"{held.seconds:.1f} s; results: {folder / 'bench_handeye_held_out.json'}")
