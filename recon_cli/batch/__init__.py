"""Batches: many isolated ``recon`` runs with pass criteria, for CI and for clusters.

    spec.py          the batch file (YAML): typed jobs, matrix expansion, checks with file:line
    expectations.py  what a job's reports measured, checked against its bounds
    result.py        what a batch produced: each job's attempts and verdict, counts, exit code
    job.py           one job: its process, timeout, retries for infrastructure failures, verdict
    child.py         the job's process: recon's entry module, ended with the batch
    executors.py     a local pool, or Dask (an existing scheduler or a LocalCluster)
    runner.py        the batch folder, --resume, the executor, the reports
    reports.py       JUnit XML, JSON and Markdown summaries
    index_page.py    index.html: every job's verdict, linked to its report page

docs/batch.md describes the batch file and the commands.
"""

from recon_cli.batch.result import BatchResult
from recon_cli.batch.runner import BatchOptions, run_batch
from recon_cli.batch.spec import BatchSpec, Commands, Expectations, JobKind, JobSpec, Overrides, load_batch

__all__ = ["BatchOptions", "BatchResult", "BatchSpec", "Commands", "Expectations", "JobKind", "JobSpec", "Overrides",
           "load_batch", "run_batch"]
