"""``recon register``: the registration pipeline on a scan store, recorded when asked.

The pipeline itself is :func:`recon_cli.reconstruction.pipeline.run_register`; with
``record`` the scans of the store (cell, joint readings, frustums, images, clouds) and
what registration made of them go into ``<out>/recording.rrd``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from recon_cli.config import Config, write_config
from recon_cli.outputs import OutputFolder
from recon_cli.reconstruction.pipeline import RegisterResult, run_register
from recon_cli.recording import closing, open_recorder
from recon_cli.recording.results import record_registration, record_store


def register_folder(folder: Path, out: Path | OutputFolder, config: Config, record: bool = False,
                    progress: Callable[[str, int, int], None] | None = None) -> RegisterResult:
    """Register the scan store ``folder`` into ``out`` with ``config.registration`` and
    ``config.seed`` (and record it into ``out/recording.rrd`` with ``record``); a claimed
    output folder is made when the pipeline writes, or first with ``record``. The folder
    gets config.yaml (its run: section names the store)."""
    result = _register(Path(folder), out, config, record, progress)
    write_config(result.folder, config, command="register", store=str(folder))
    return result


def _register(folder: Path, out: Path | OutputFolder, config: Config, record: bool,
              progress: Callable[[str, int, int], None] | None) -> RegisterResult:
    options, seed = config.registration, config.seed
    if not record or not folder.is_dir():  # without a folder: the pipeline's one-line error
        return run_register(folder, out, options, progress, seed=seed)

    if isinstance(out, OutputFolder):
        out = out.make()
    recorder = open_recorder(out, f"recon register {folder.name}")
    with closing(recorder):
        record_store(recorder, folder)
        result = run_register(folder, out, options, progress, seed=seed)
        record_registration(recorder, result, folder)
    return result
