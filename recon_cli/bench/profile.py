"""Wall clock of the main job by stage (``recon bench profile``).

The main job is ``recon autoscan --dc 0.55 --n 16`` (the bottle, seed 0): the same workflow
(:class:`recon_cli.workflows.autoscan.Autoscan`) with the options the command gives it, run
in this process under :mod:`cProfile`, its outputs (scans, reconstruction, pictures, page)
in a subfolder of the benchmark's folder (:data:`SUBFOLDER`).

A stage is a set of functions (:data:`STAGES`: stage name, module, qualified name); its
time is read from the profile (:mod:`pstats`: each function's cumulative time over its
outermost calls, so recursion is counted once). The workflow code is not instrumented.

Nested stages: **the time belongs to the innermost stage on the call stack**. A stage
function called inside another stage's function (a library imported inside the first
scan's cloud, a board pose inside the registration, the motion planner made inside the
session set-up) is its own stage's time and is subtracted from the stage around it; a stage
function called inside a function of its own stage (a planning request inside the view
selection) is not counted twice. Where a stage function is called from is read from the
profile's caller edges (their cumulative times), with the profiler's usual assumption that
a function's time splits over its callers as their calls to it do; it is exact where a
function is always called from the same stage, as the stage functions here are. Calls that
close a cycle (an import inside an import) are left out, as cProfile counts a recursion
once; what the edges cannot place stays with the stage around it.

Rows of the table: ``start-up`` (from the command's start to the workflow's run, with
:func:`time.perf_counter`: the options and the workflow object), the
stages, and ``other`` (the rest of the wall clock: the workflow's own code between the
stages, its report file). The rows add up to the total wall clock; in a fresh process the
interpreter and recon's own imports before the command (about 2 s) come on top.
Times include the profiler's overhead (more for stages of many small Python calls).
"""

from __future__ import annotations

import cProfile
import importlib
import inspect
import os
import pstats
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from recon_cli.config import DEFAULTS
from recon_cli.session import resolve_object_name
from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions, AutoscanResult

#: (stage, module, qualified function name): a stage's time is that of its functions
STAGES: tuple[tuple[str, str, str], ...] = (
    ("imports (libraries loaded on first use)", "importlib._bootstrap", "_find_and_load"),
    ("session set-up", "recon_cli.session", "open_session"),
    ("session set-up", "recon_cli.session", "Session.__init__"),
    ("rendering", "recon_cli.backends.sim.camera", "render_rgbd"),
    ("sensor model", "recon_cli.perception.sensor", "SensorModel.apply"),
    ("sensor model", "recon_cli.perception.sensor", "SensorModel.apply_color"),
    ("sensor model", "recon_cli.backends.sim.camera", "SimCamera._realism_effects"),
    ("scan storage", "recon_cli.acquisition", "Acquisition.settle"),  # the wait for the writer thread
    ("board poses", "recon_cli.reconstruction.global_registration", "global_pose"),
    ("scan clouds", "recon_cli.reconstruction.pipeline", "scan_points"),
    ("ellipsoid fits", "recon_cli.viewplan.ellipsoid", "Ellipsoid.from_cloud"),
    ("view sampling (potential field, IK)", "recon_cli.workflows.autoscan", "Autoscan._default_initial"),
    ("view sampling (potential field, IK)", "recon_cli.workflows.autoscan", "Autoscan._ellipsoid_candidates"),
    ("view selection and motion planning", "recon_cli.sequence.view_selection", "select_view"),
    ("view selection and motion planning", "recon_cli.planning.planner", "MotionPlanner.__init__"),
    ("view selection and motion planning", "recon_cli.planning.planner", "MotionPlanner.plan_to_joints"),
    ("view selection and motion planning", "recon_cli.planning.planner", "MotionPlanner.plan_to_pose"),
    ("robot execution", "recon_cli.backends.sim.robot", "SimRobot.execute"),
    ("registration", "recon_cli.reconstruction.pipeline", "run_register"),
    ("ground-truth evaluation", "recon_cli.workflows.autoscan", "surface_coverage"),
    ("ground-truth evaluation", "recon_cli.reconstruction.evaluation", "signed_distances"),
    ("ground-truth evaluation", "recon_cli.reconstruction.evaluation", "histogram_png"),
    ("report page", "recon_cli.report.page", "write_page_after_run"),
    ("pictures (hand-over, final wait)", "recon_cli.viewplan.picture", "PictureWorker.draw"),
    ("pictures (hand-over, final wait)", "recon_cli.viewplan.picture", "PictureWorker.close"),
)
#: the rows measured beside the profile
START_UP = "start-up"
OTHER = "other"
#: the main job: ``recon autoscan --dc 0.55 --n 16`` (bottle, seed 0)
MAIN_DC = 0.55
MAIN_N = 16
#: ``--quick``: so many scans at this image scale
QUICK_N = 4
QUICK_RESOLUTION = 0.2
#: the autoscan's own outputs, and the raw profile (``python -m pstats FILE``), in the benchmark's folder
SUBFOLDER = "profiled_autoscan"
PSTATS_FILE = "profiled_autoscan.pstats"

Key = tuple[str, int, str]  # pstats' (file, first line, name) of a function
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class FunctionTime:
    module: str
    function: str
    calls: int  # 0: never called (or not found: see ``found``)
    cumulative_s: float  # over its outermost calls, wherever called from [s]
    found: bool = True  # the function exists (a renamed one is reported, not guessed)


@dataclass(frozen=True)
class StageTime:
    stage: str
    seconds: float  # wall clock of the stage, innermost-stage rule [s]
    share: float  # of the total wall clock
    functions: tuple[FunctionTime, ...] = ()


@dataclass(frozen=True)
class ProfileResult:
    folder: Path  # the autoscan's outputs
    pstats_file: Path
    total_s: float  # wall clock from the command's start to the end of the workflow [s]
    workflow_s: float  # of it, the workflow's run [s]
    rows: tuple[StageTime, ...]  # start-up, the stages in STAGES' order, other
    scans: int
    settings: dict = field(default_factory=dict)
    interrupted: bool = False  # Ctrl-C ended the scanning early (the profile is of what ran)

    def to_dict(self) -> dict:
        return {"settings": self.settings, "total_s": self.total_s, "workflow_s": self.workflow_s,
                "scans": self.scans, "interrupted": self.interrupted, "autoscan_folder": str(self.folder),
                "pstats": str(self.pstats_file),
                "rule": "time belongs to the innermost stage on the call stack; rows add up to the total",
                "cpus": os.cpu_count(),
                "stages": [{"stage": r.stage, "seconds": r.seconds, "share": r.share,
                            "functions": [asdict(f) for f in r.functions]} for r in self.rows]}


def stage_names() -> tuple[str, ...]:
    """The stages in order (each once)."""
    return tuple(dict.fromkeys(s for s, _, _ in STAGES))


def main_job_options(out: Path, object_name: str = "bottle", n: int = MAIN_N, seed: int = 0,
                     resolution: float = DEFAULTS.sensor.resolution) -> AutoscanOptions:
    """What ``recon autoscan --dc 0.55 --n N --object NAME --seed S --resolution R --out
    OUT`` gives the workflow (pictures and the page on, the default cell and realism)."""
    config = DEFAULTS.with_values({"scene.object_name": resolve_object_name(object_name), "seed": seed,
                                   "viewplan.n": n, "viewplan.d_c": MAIN_DC, "sensor.resolution": resolution})
    return AutoscanOptions(out, config, None, pictures=True,
                           run={"command": "autoscan", "initial": None, "pictures": True})


def run_profile(folder: Path, object_name: str = "bottle", n: int = MAIN_N, seed: int = 0,
                resolution: float = DEFAULTS.sensor.resolution, progress: Progress | None = None) -> ProfileResult:
    """Run the main job under cProfile; its outputs go to ``folder / SUBFOLDER``, the raw
    profile to ``folder / PSTATS_FILE``."""
    t0 = time.perf_counter()
    out = folder / SUBFOLDER
    opts = main_job_options(out, object_name, n, seed, resolution)
    workflow = Autoscan(opts, progress)
    profiler = cProfile.Profile()
    t_run = time.perf_counter()
    profiler.enable()
    try:
        result: AutoscanResult = workflow.run()
    finally:
        profiler.disable()
    t_end = time.perf_counter()
    stats = pstats.Stats(profiler)
    stats.dump_stats(folder / PSTATS_FILE)
    rows = stage_rows(stats.stats, t_run - t0, t_end - t0)  # type: ignore[attr-defined]
    settings = {"command": f"recon autoscan --dc {MAIN_DC:g} --n {n}", "object": opts.config.scene.object_name,
                "n": n, "d_c": MAIN_DC, "seed": seed, "resolution": resolution,
                "cell": opts.config.cell.kind.value, "realism": opts.config.realism.name}
    return ProfileResult(out, folder / PSTATS_FILE, t_end - t0, t_end - t_run, rows, result.scans, settings,
                         result.interrupted)


# ----------------------------------------------------------------------------- the profile's arithmetic
def function_key(module: str, qualname: str) -> Key | None:
    """pstats' key of a Python function (None: no such function, or not a Python one)."""
    try:
        obj: Any = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError):
        return None
    obj = inspect.unwrap(getattr(obj, "__func__", obj))
    code = getattr(obj, "__code__", None)
    return None if code is None else (code.co_filename, code.co_firstlineno, code.co_name)


def _reach(start, step: dict) -> set:
    """Every node reached from ``start`` along ``step`` (the start nodes included)."""
    seen, todo = set(start), list(start)
    while todo:
        for nxt in step.get(todo.pop(), ()):
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return seen


def _contexts(raw: dict, own: dict[Key, str]) -> dict[Key, dict[Key | None, float]]:
    """For every stage function: its seconds by the innermost stage function around its
    calls (None: none around), from the caller edges (their cumulative times). Only the
    functions between two stage functions matter; they are visited callers first. Calls that
    close a cycle (a function called again below itself, directly or through others, as
    imports within imports) are left out: cProfile counts a recursion's time once, at its
    outermost call. A function's seconds never exceed its cumulative time; what the edges
    do not place stays with the stage around it."""
    callers = {key: entry[4] for key, entry in raw.items()}
    callees: dict[Key, list[Key]] = {}
    for key, edges in callers.items():
        for caller in edges:
            callees.setdefault(caller, []).append(key)
    roots = [k for k in own if k in raw]
    between = _reach(roots, callees) & _reach(roots, callers)
    order: list[Key] = []  # post-order of a depth-first walk down the calls
    seen: set[Key] = set()
    for root in roots:
        if root in seen:
            continue
        seen.add(root)
        stack = [(root, iter(callees.get(root, ())))]
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                stack.pop()
                order.append(node)
            elif nxt in between and nxt not in seen:
                seen.add(nxt)
                stack.append((nxt, iter(callees.get(nxt, ()))))
    order.reverse()  # callers before callees, but along the calls that close a cycle
    position = {key: i for i, key in enumerate(order)}
    context: dict[Key, dict[Key | None, float]] = {}  # shares of a function's time by where it runs
    seconds: dict[Key, dict[Key | None, float]] = {}  # the same in seconds, for the stage functions
    for key in order:
        mix: dict[Key | None, float] = {}
        total = 0.0
        for caller, edge in callers[key].items():
            if position.get(caller, -1) >= position[key]:  # a call closing a cycle (or itself)
                continue
            weight = float(edge[3])
            total += weight
            around = {caller: 1.0} if caller in own else context.get(caller, {None: 1.0})
            for where, share in around.items():
                mix[where] = mix.get(where, 0.0) + weight * share
        context[key] = {k: v / total for k, v in mix.items()} if total > 0 else {None: 1.0}
        if key in own:
            ct = float(raw[key][3])
            if not callers[key]:  # at the top of the profile
                mix, total = {None: ct}, ct
            scale = min(1.0, ct / total) if total > 0 else 0.0
            seconds[key] = {k: v * scale for k, v in mix.items()}
    return seconds


def stage_times(raw: dict) -> tuple[dict[str, float], dict[str, tuple[FunctionTime, ...]]]:
    """Seconds of every stage by the innermost-stage rule, and its functions' own numbers,
    from pstats' raw table (``Stats.stats``: key -> (cc, nc, tt, ct, callers))."""
    own: dict[Key, str] = {}
    functions: dict[str, list[FunctionTime]] = {s: [] for s in stage_names()}
    for stage, module, qualname in STAGES:
        key = function_key(module, qualname)
        entry = raw.get(key) if key is not None else None
        functions[stage].append(FunctionTime(module, qualname, 0 if entry is None else int(entry[1]),
                                             0.0 if entry is None else float(entry[3]), key is not None))
        if key is not None:
            own[key] = stage
    seconds = dict.fromkeys(functions, 0.0)
    for key, by_where in _contexts(raw, own).items():
        stage = own[key]
        for where, t in by_where.items():
            if where is None:
                seconds[stage] += t
            elif own[where] != stage:  # inside another stage: moved from there to here
                seconds[stage] += t
                seconds[own[where]] -= t
            # inside its own stage (or itself): counted there already
    return seconds, {s: tuple(f) for s, f in functions.items()}


def stage_rows(raw: dict, start_up_s: float, total_s: float) -> tuple[StageTime, ...]:
    """The table's rows: start-up, the stages, other (the rest); they add up to ``total_s``."""
    seconds, functions = stage_times(raw)
    rows = [(START_UP, start_up_s, ())] + [(s, seconds[s], functions[s]) for s in stage_names()]
    rest = total_s - sum(r[1] for r in rows)
    rows.append((OTHER, rest, ()))
    return tuple(StageTime(name, t, t / total_s if total_s > 0 else 0.0, f) for name, t, f in rows)


def stage_png(path: Path, result: ProfileResult) -> None:
    """A bar per row, its seconds and share written beside it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result.rows
    fig, ax = plt.subplots(figsize=(8, 0.32 * len(rows) + 1.4))
    y = list(range(len(rows)))[::-1]
    values = [r.seconds for r in rows]
    colors = ["0.6" if r.stage in (START_UP, OTHER) else "tab:blue" for r in rows]
    ax.barh(y, values, color=colors)
    for yy, r in zip(y, rows, strict=True):
        ax.annotate(f"{r.seconds:.2f} s ({r.share * 100:.1f} %)", (max(r.seconds, 0.0), yy), xytext=(3, 0),
                    textcoords="offset points", va="center", fontsize=7)
    ax.set_yticks(y, [r.stage for r in rows], fontsize=8)
    ax.set_xlabel("wall clock [s] (innermost stage on the call stack)")
    s = result.settings
    ax.set_title(f"{s.get('command', '')}, {s.get('object', '')}, seed {s.get('seed', '')}: "
                 f"{result.total_s:.1f} s", fontsize=9)
    ax.set_xlim(0, max(values + [1e-3]) * 1.3)
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
