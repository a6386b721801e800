"""The index page of a batch (``index.html`` in the batch folder): one row per job with its
verdict, wall time and expectation checks, linked to the job's own report page, its output
folder and its log."""

from __future__ import annotations

from pathlib import Path

from recon_cli.batch.result import BatchResult, JobResult, measured_text
from recon_cli.outputs import atomic_write_text
from recon_cli.report.markup import Content, Html, facts, link, note, num, page, section, status, table, tag
from recon_cli.report.page import PAGE

INDEX = "index.html"


def job_page(batch_folder: Path, name: str) -> Path:
    """Where a job's report page is (the job's recon output folder: ``jobs/NAME/output``)."""
    return Path(batch_folder) / "jobs" / name / "output" / PAGE


def _checks(result: JobResult) -> Html:
    items = [tag("li", [status("passed" if c.passed else "failed"), " ", c.describe()]) for c in result.checks]
    return tag("ul", items) if items else Html("")


def _row(result: JobResult, folder: Path) -> list[Content]:
    page_path = job_page(folder, result.name)
    job_dir = folder / "jobs" / result.name
    log = job_dir / "log.txt"
    name = link(page_path, folder, result.name) if page_path.is_file() else result.name
    verdict = tag("span", [status(result.status.value), " (resumed)" if result.resumed else None])
    files = [link(log, folder, "log") if log.is_file() else None,
             link(job_dir / "output", folder, "output") if (job_dir / "output").is_dir() else None]
    return [name, result.kind, verdict, f"{result.wall_s:.1f}", num(result.exit_code) or "-", _checks(result),
            measured_text(result), result.reason or "", Html(" ".join(f for f in files if f))]


def write_index(batch: BatchResult) -> Path:
    """``index.html`` of a :class:`~recon_cli.batch.result.BatchResult` in its folder."""
    folder = Path(batch.folder)
    c = batch.counts
    verdict = "all passed" if batch.exit_code == 0 else "failed"
    rows = [_row(r, folder) for r in batch.jobs]
    rows += [[name, "", status("not run"), "-", "-", "", "-", "the batch was interrupted", ""]
             for name in batch.pending]
    reports = [link(folder / name, folder, name) for name in ("junit.xml", "summary.json", "summary.md", "batch.json")
               if (folder / name).is_file()]
    summary = facts([("result", status("passed" if batch.exit_code == 0 else "failed")),
                     ("jobs", f"{len(batch.jobs)}: {c['passed']} passed, {c['failed']} failed, {c['timeout']} timed "
                              f"out, {c['error']} errors" + (f", {len(batch.pending)} not run" if batch.pending
                                                            else "")),
                     ("wall time", f"{batch.wall_s:.1f} s"), ("executor", batch.executor),
                     ("interrupted", f"by {batch.interrupted}" if batch.interrupted else None),
                     ("folder", str(folder.absolute())), ("reports", Html(", ".join(reports)) or None)])
    jobs = table(("job", "kind", "result", "wall time [s]", "exit code", "expectations", "measured", "reason",
                  "files"), rows, numeric=(3, 4))
    explain = note("A job's name links to its report page where its command wrote one (validations write none).")
    text = page(f"recon batch {batch.name}: {verdict}", f"batch folder {folder.absolute()}",
                [("summary", "Summary"), ("jobs", "Jobs")],
                [section("summary", "Summary", summary), section("jobs", "Jobs", jobs, explain)])
    return atomic_write_text(folder / INDEX, text)
