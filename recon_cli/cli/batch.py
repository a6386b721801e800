"""``recon batch``: many isolated recon runs with pass criteria, locally or on Dask."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Literal

import typer
from rich.console import JustifyMethod
from rich.table import Table

from recon_cli.batch import BatchOptions, Overrides, load_batch, run_batch
from recon_cli.batch.job import display_command
from recon_cli.batch.result import measured_text
from recon_cli.cli.app import app
from recon_cli.cli.batch_commands import AppCommands
from recon_cli.console import console, progress_bar, styled
from recon_cli.interrupts import stop_signals
from recon_cli.recording import require_rerun

BATCH_EPILOG = ("Exit codes: 0 every job passed; 1 error in the batch file or options (nothing ran); 2 usage error; "
                "3 some jobs failed, timed out or could not run; 130/143/129 interrupted by Ctrl-C/SIGTERM/SIGHUP "
                "(finished jobs kept: --resume goes on). Batch file format: docs/batch.md.")


@app.command(epilog=BATCH_EPILOG)
def batch(
    sources: Annotated[list[str], typer.Argument(
        metavar="SOURCES", help="Batch files (.yaml), scripts (.xml) or quoted globs of them ('scripts/*.xml'), "
                                "run in this order.",
        show_default=False)],
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Batch folder (default runs/batch-<time>): a folder "
                                                                 "per job, junit.xml, summary.json, summary.md, "
                                                                 "index.html.")] = None,
    workers: Annotated[int, typer.Option(min=1, max=1024, help="Jobs at once on this machine (or worker "
                                                               "processes of --cluster local).")] = 1,
    scheduler: Annotated[str | None, typer.Option(envvar="DASK_SCHEDULER_ADDRESS", help="Run the jobs on the Dask "
                                                  "cluster of this scheduler, e.g. tcp://host:8786 (env "
                                                  "DASK_SCHEDULER_ADDRESS).")] = None,
    cluster: Annotated[Literal["local"] | None, typer.Option(help="'local': start a Dask LocalCluster of --workers "
                                                                  "processes for the batch.")] = None,
    timeout: Annotated[float | None, typer.Option(min=1.0, max=604_800.0, help="Timeout per job attempt [s] for "
                                                  "jobs that set none (replaces the batch file's default; default "
                                                  "3600; at most a week).")] = None,
    retries: Annotated[int | None, typer.Option(min=0, max=10, help="Extra attempts after an infrastructure "
                                                                    "failure (killed, lost worker; default 1).")]
    = None,
    resume: Annotated[bool, typer.Option("--resume", help="Go on with the batch in --out: keep the jobs that "
                                                          "finished, run the others.")] = False,
    force: Annotated[bool, typer.Option("--force", help="Use a non-empty --out: first remove what recon wrote "
                                                        "there (links only as links; the rest stays; "
                                                        "docs/architecture.md); without it (or --resume) --out must "
                                                        "be new or empty.")] = False,
    junit: Annotated[Path | None, typer.Option(help="Also write the JUnit XML here.")] = None,
    json_out: Annotated[Path | None, typer.Option("--json", help="Also write the JSON summary here.")] = None,
    markdown: Annotated[Path | None, typer.Option(help="Also write the Markdown summary here (e.g. "
                                                       "$GITHUB_STEP_SUMMARY).")] = None,
    list_jobs: Annotated[bool, typer.Option("--list", help="Print the jobs and their commands; run nothing.")]
    = False,
    record: Annotated[bool, typer.Option("--record", help="Every job that can writes a 3D recording of its run "
                                                          "(recording.rrd in its folder; needs recon-scan[viz]).")]
    = False,
) -> None:
    """Run a batch of scans (scripts, autoscans, captures; seeds, objects) as isolated recon processes, check
    their pass criteria and write JUnit XML and summaries."""


    if cluster is not None and scheduler == os.environ.get("DASK_SCHEDULER_ADDRESS"):
        scheduler = None  # an explicit --cluster wins over the environment's scheduler
    if record:

        require_rerun()
    spec = load_batch(sources, AppCommands(), Overrides(timeout, retries, record))
    if list_jobs:
        for job in spec.jobs:
            bounds = ", ".join(f"{k} {v:g}" for k, v in job.expect.items())
            console.print(f"{job.name}: {' '.join(display_command(job))}  (timeout {job.timeout_s:g} s"
                          + (f"; expect {bounds}" if bounds else "") + ")")
        console.print(f"{len(spec.jobs)} jobs in batch {spec.name!r}")
        return

    style = {"passed": "green", "failed": "red", "timeout": "red", "error": "yellow"}

    def on_result(r, done: int, total: int) -> None:
        what = f"{r.status.value}{' (resumed)' if r.resumed else ''}"
        console.print(styled(f"[{done}/{total}] {what}", style[r.status.value],
                             f" {r.name} in {r.wall_s:.1f} s" + (f": {r.reason}" if r.reason else "")))

    options = BatchOptions(out, workers, scheduler, cluster, resume, junit, json_out, markdown, force)
    with stop_signals(hangup=True), progress_bar() as update:
        result = run_batch(spec, options, update, on_result)
    _print_table(result)
    c = result.counts
    console.print(f"{len(result.jobs)} jobs: {c['passed']} passed, {c['failed']} failed, {c['timeout']} timed out, "
                  f"{c['error']} errors" + (f", {len(result.pending)} not run" if result.pending else "")
                  + f" in {result.wall_s:.1f} s ({result.executor})")
    for key in ("junit", "json", "markdown", "index"):
        console.print(f"{key}: {result.reports[key]}")
    if result.interrupted:
        console.print(f"interrupted by {result.interrupted}; recon batch ... --out {result.folder} --resume goes on")
    if result.exit_code:
        raise typer.Exit(result.exit_code)


def _print_table(result) -> None:


    table = Table(title=f"batch {result.name}", title_justify="left")
    columns: tuple[tuple[str, JustifyMethod], ...] = (("job", "left"), ("result", "left"), ("wall [s]", "right"),
                                                      ("measured", "left"), ("reason", "left"))
    for name, justify in columns:
        table.add_column(name, justify=justify)
    for r in result.jobs:
        table.add_row(r.name, r.status.value + (" (resumed)" if r.resumed else ""), f"{r.wall_s:.1f}",
                      measured_text(r), r.reason or "-")
    for name in result.pending:
        table.add_row(name, "not run", "-", "-", "the batch was interrupted")
    console.print(table)
