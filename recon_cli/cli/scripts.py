"""``recon validate`` and ``recon run``: automation scripts."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from recon_cli.both_sides import confidence_line
from recon_cli.cli.app import app
from recon_cli.cli.options import (
    REALISM_HELP,
    ConfigOpt,
    D,
    ForceOpt,
    RecordOpt,
    SeedOpt,
    cell_metavar,
    cell_option,
    check_record,
    object_metavar,
    object_option,
    output_folder,
    realism_option,
    realism_profile,
    run_base,
)
from recon_cli.console import console, progress_bar, styled
from recon_cli.errors import InputError
from recon_cli.interrupts import stop_signals
from recon_cli.scripts.checks import check_backend, check_script
from recon_cli.scripts.loader import load_script
from recon_cli.scripts.state import RunOptions, SequenceMethod
from recon_cli.session import Backend
from recon_cli.workflows.script_run import ScriptRunner


@app.command()
def validate(
    script: Annotated[Path, typer.Argument(help="Automation script (recon or thesis dialect).")],
) -> None:
    """Expand xacro, validate against the XSD and list the commands a script would run."""

    s = load_script(script)
    check_script(s)
    dialect = "recon (schemas/recon_script.xsd)" if s.dialect == "recon" else \
        "thesis system (schemas/thesis_script.xsd)"
    console.print(f"{script}: valid, dialect {dialect}, script {s.name!r}, {len(s.commands)} commands, "
                  f"on failure: {s.on_failure}" + (", sequence optimization requested" if s.optimize else ""))
    for k, cmd in enumerate(s.commands, start=1):
        console.print(f"{k:4d}  {cmd.source}  {cmd.describe()}")


RUN_EPILOG = ("Exit codes: 0 every command done; 1 error before or outside the commands (bad script, option or "
              "file); 2 usage error; 3 some commands failed (their scans skipped; --allow-failures gives 0); "
              "4 aborted by a failed command (on_failure=\"abort\"); 130 interrupted by Ctrl-C, 143 by SIGTERM "
              "(completed scans kept, the report says what was interrupted).")


@app.command("run", epilog=RUN_EPILOG)
def run_script(
    ctx: typer.Context,
    script: Annotated[Path | None, typer.Argument(help="Automation script (recon or thesis dialect); with --config "
                                                       "the script the file names by default.")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Output folder (default runs/run-<time>).")] = None,
    backend: Annotated[Backend | None, typer.Option(help="The backend (overrides the script).")] = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="Plan every move, move nothing, scan nothing.")] = False,
    object_name: Annotated[str | None, typer.Option("--object", metavar=object_metavar(True),
                                                    callback=object_option(True),
                                                    help="Simulated object (overrides the script; default: the "
                                                         "drill if present).")] = None,
    optimize: Annotated[bool | None, typer.Option("--optimize/--no-optimize", help="Reorder independent moves "
                                                  "and scans (default: as the script says).")] = None,
    sequence_method: Annotated[SequenceMethod, typer.Option(help="'ours' (local search) or 'thesis' (Tables "
                                                                 "2.2/2.3).")] = SequenceMethod.OURS,
    seed: SeedOpt = D.seed,
    append: Annotated[bool, typer.Option("--append", help="Add this run's scans to the scan store already in "
                                                          "--out (same cell and object); without it --out must "
                                                          "be new or empty.")] = False,
    allow_failures: Annotated[bool, typer.Option("--allow-failures", help="Exit 0 even when some commands "
                                                                          "failed (default: exit 3).")] = False,
    station: Annotated[Path | None, typer.Option(help="Station file: run on the robot and camera adapters it names "
                                                      "(docs/hardware.md); default: the simulation.")] = None,
    realism: Annotated[str | None, realism_option(REALISM_HELP + " Overrides the script's <cell realism=...>.")]
    = None,
    cell: Annotated[str | None, typer.Option("--cell", metavar=cell_metavar(), callback=cell_option,
                                             help="Run the script on this cell (overrides the script's <cell "
                                                  "kind=...>, with the cell's own safety distance): a shipped "
                                                  "cell or a cell FILE.yaml (docs/cells.md).")] = None,
    record: RecordOpt = False,
    force: ForceOpt = False,
    config_file: ConfigOpt = None,
) -> None:
    """Run an automation script: moves, scans, registration, reconstruction, exports.

    Its config.yaml records the script and the options that override it; with --config FILE
    the script runs again on that configuration (the script's elements set what they set
    the first time)."""

    base = run_base(ctx, config_file, "run")
    if script is None:
        script = base.stored("script")
        if script is None:
            raise InputError("no script given", hint="give the automation script (or --config FILE of a run)")
        script = Path(script)
    backend = base.pick("backend", backend, base.stored("backend_override"))
    backend = None if backend is None else Backend(backend)
    dry_run = base.pick("dry_run", dry_run, base.stored("dry_run", dry_run))
    object_name = base.pick("object_name", object_name, base.stored("object_override"))
    cell = base.pick("cell", cell, base.stored("cell_override"))
    optimize = base.pick("optimize", optimize, base.stored("optimize"))
    sequence_method = SequenceMethod(base.pick("sequence_method", sequence_method,
                                               base.stored("sequence_method", sequence_method)))
    station = base.pick("station", station, base.stored("station"))
    station = None if station is None else Path(station)
    stored_realism = base.stored("realism_override")
    check_record(record)
    s = load_script(script)
    check_script(s, object_override=object_name, cell_override=cell, append=append)  # before the output folder
    check_backend(s, backend, station, dry_run)
    if realism is not None:
        profile = realism_profile(realism)
    elif stored_realism is not None:  # the profile the file records (it overrode the script then)
        profile = base.config.realism
    else:
        profile = None
    folder = output_folder(out, "run", append=append, force=force,
                           append_hint="--append to add this run's scans to the scan store in it",
                           inputs=(script, station, None if realism is None else Path(realism))).path
    config = base.config.with_values(base.picked(seed=("seed", seed)))
    run = {"dry_run": dry_run, "backend_override": backend, "object_override": object_name, "optimize": optimize,
           "sequence_method": sequence_method, "realism_override": realism or stored_realism, "cell_override": cell}
    options = RunOptions(folder, backend, config, dry_run, object_name, optimize, sequence_method, append, station,
                         profile, cell, record, run=run)
    with stop_signals(), progress_bar() as update:
        result = ScriptRunner(s, options, update).run()
    counts: dict[str, int] = {}
    for r in result.reports:
        counts[r.status.value] = counts.get(r.status.value, 0) + 1
    console.print(f"{s.name}: {len(result.reports)} commands (" + ", ".join(f"{v} {k}" for k, v in counts.items())
                  + f"), {result.scans} scans, {result.seconds:.1f} s")
    for r in result.reports:
        if r.status in ("failed", "skipped") and r.message != "dry run":
            console.print(styled(r.status.value, "yellow", f" {r.source} {r.command}: {r.message}"))
    for seq in result.sequences:
        console.print(f"sequence of {seq.moves} moves ({seq.method.value}): planned trajectory time "
                      f"{seq.planned_duration_s:.1f} s with {seq.planning_requests} planning requests "
                      f"({seq.seconds:.1f} s)")
    if result.sides is not None:
        console.print(confidence_line(result.sides.registration))
        if result.sides.coverage is not None:
            console.print(f"ground truth: coverage {result.sides.coverage * 100:.2f} % of the whole surface (1 mm)")
    for k, v in result.outputs.items():
        console.print(f"{k}: {v}")
    console.print(f"report: {folder / 'run_report.json'}")
    if record and not dry_run:
        console.print(f"recording: {folder / 'recording.rrd'} (recon view {folder})")
    if result.page is not None:
        console.print(f"page: {result.page}")
    if result.exit_code and not allow_failures:
        raise typer.Exit(result.exit_code)
