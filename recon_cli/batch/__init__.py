"""Batches: many isolated ``recon`` runs with pass criteria, for CI and for clusters.

    spec.py          the batch file (YAML): typed jobs, matrix expansion, checks with file:line
    expectations.py  what a job's reports measured, checked against its bounds
    job.py           one job: its process, timeout, retries for infrastructure failures, verdict
    child.py         the job's process: recon, ended with the batch
    executors.py     a local pool, or Dask (an existing scheduler or a LocalCluster)
    runner.py        the batch folder, --resume, the executor, the reports
    reports.py       JUnit XML, JSON and Markdown summaries

docs/batch.md describes the batch file and the commands.
"""

from recon_cli.batch.runner import BatchOptions, BatchResult, run_batch
from recon_cli.batch.spec import BatchSpec, Expectations, JobKind, JobSpec, Overrides, load_batch

__all__ = ["BatchOptions", "BatchResult", "BatchSpec", "Expectations", "JobKind", "JobSpec", "Overrides",
           "load_batch", "run_batch"]
