"""A report page per run folder (``report.html``, no server needed).

    options.py      what a page shows, image sizes (light: no Open3D, no matplotlib)
    model.py        what a run folder holds, as typed values
    read.py         a run folder (recon run, autoscan, capture, register) -> RunFolder
    figures.py      charts the run has numbers but no figure for, scan thumbnails
    mesh_view.py    grey pictures of the mesh from a few directions (CPU ray casting), blank check
    markup.py       escaped HTML building blocks, relative links, the page shell (also of a
                    batch's index page, recon_cli.batch.index_page)
    sections.py     the sections of a run's page
    page.py         write_page: read, draw, render, write (report.html + report_files/)

Every command that makes a run folder writes its page at the end, also when the run ends
early (:func:`write_page_after_run`); ``recon report FOLDER`` rebuilds it. Links are
relative, so the folder can be moved, zipped and mailed.
"""

from __future__ import annotations

from recon_cli.report.options import ReportOptions
from recon_cli.report.page import PAGE, ReportPage, write_page, write_page_after_run, write_pages_after_register

__all__ = ["PAGE", "ReportOptions", "ReportPage", "write_page", "write_page_after_run", "write_pages_after_register"]
