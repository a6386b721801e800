"""Writing a run folder's page: read the folder, draw what it lacks, render the mesh, write
``report.html`` with its pictures in ``report_files/`` beside it.

The pictures are made in a temporary folder that replaces ``report_files/`` when complete,
and the page is written last under a temporary name and renamed, so a reader sees the old
page or the new one. Pictures already in the folder (distance histograms, the autoscan's
iteration pictures) are linked where they are.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, replace
from pathlib import Path

from recon_cli.config import DEFAULTS
from recon_cli.console import err_console
from recon_cli.errors import FileError, ReconError
from recon_cli.inputs.files import link_out_of
from recon_cli.outputs import atomic_write_text, inside
from recon_cli.report import figures
from recon_cli.report.markup import GENERATOR, page
from recon_cli.report.mesh_view import MeshView, render_mesh
from recon_cli.report.model import RunFolder, RunKind
from recon_cli.report.options import ReportOptions
from recon_cli.report.read import PAGE_FILES, read_run_folder
from recon_cli.report.sections import Assets, Picture, body

PAGE = "report.html"
MARKER = ".recon-report"  # inside report_files/: the folder is the page's own (and may be replaced)


@dataclass(frozen=True)
class ReportPage:
    path: Path  # report.html
    kind: RunKind
    status: str  # of the run
    mesh_views: tuple[MeshView, ...]  # rendered pictures of the mesh
    pictures: tuple[Path, ...]  # every picture the page shows
    notes: tuple[str, ...]  # what the page could not show, and why


def mesh_file(run: RunFolder) -> Path | None:
    """The mesh a run made: the registration's, else a mesh.ply beside its report; never one
    that is (or lies behind) a link leading out of the run folder."""
    candidates = []
    if run.registration is not None:
        candidates += [run.registration.mesh, run.registration.report.parent / "mesh.ply"]
    candidates += [run.folder / "reconstruction" / "mesh.ply", run.folder / "mesh.ply"]
    return next((p for p in candidates if p is not None and p.is_file() and link_out_of(p, run.folder) is None),
                None)


def _draw(run: RunFolder, options: ReportOptions, out: Path) -> Assets:
    """Every picture of the page in ``out`` (paths inside ``out``)."""

    mesh = mesh_file(run)
    views: tuple[MeshView, ...] = ()
    why = None
    if mesh is None:
        why = "no mesh in this folder (it is made by registration with a surface: recon register, <reconstruct/>)"
    elif not options.render:
        why = "the mesh was not rendered (--no-render)"
    else:
        try:
            seed = next((s.seed for s in (run.session, run.script_run, run.autoscan)
                         if s is not None and s.seed is not None), DEFAULTS.seed)
            views = render_mesh(mesh, out, options.views, options.image_width, seed=seed)
        except FileError as exc:
            why = f"the mesh cannot be shown: {exc.one_line()}"
    pictures: list[Picture] = []
    if any(m.plan_s is not None or m.trajectory_s is not None for m in run.moves):
        pictures.append(Picture(figures.plan_times_png(out / "plan_times.png", run.moves),
                                "planning time and trajectory duration of every move"))
    if run.evaluations:
        pictures.append(Picture(figures.coverage_png(out / "coverage.png", run.evaluations),
                                "accuracy bands and coverage of the reference surface"))
    pictures += [Picture(e.histogram, f"signed distances of {e.name} to {e.reference}")
                 for e in run.evaluations if e.histogram is not None]
    if run.registration is not None and run.registration.edges:
        pictures.append(Picture(figures.icp_png(out / "icp_residuals.png", run.registration.edges),
                                "fitness and inlier RMSE of every pairwise ICP result"))
    if run.two_sides is not None:
        drawn = figures.sides_png(out / "sides.png", run.two_sides)
        if drawn is not None:
            pictures.insert(0, Picture(drawn, "the two sides as registered onto each other by their shape"))
    thumbs = {}
    scans = [(s.folder, s) for s in run.scans]
    if run.two_sides is not None:  # keyed side_k/scan_NNNN
        scans += [(f"{side.name}/{s.folder}", s) for side in run.two_sides.sides for s in side.scans]
    for key, s in scans:
        path = figures.thumbnail(out / "scans" / f"{key}.jpg", s, options.thumbnail_width)
        if path is not None:
            thumbs[key] = path
    return Assets(mesh, views, why, tuple(pictures), thumbs)


def _moved(assets: Assets, tmp: Path, final: Path) -> Assets:
    def move(p: Path) -> Path:
        return final / p.relative_to(tmp) if p.is_relative_to(tmp) else p

    return replace(assets, mesh_views=tuple(replace(v, path=move(v.path)) for v in assets.mesh_views),
                   figures=tuple(replace(p, path=move(p.path)) for p in assets.figures),
                   thumbnails={k: move(v) for k, v in assets.thumbnails.items()})


def _refuse_foreign(folder: Path, final: Path) -> None:
    """Never replace a report.html or report_files/ that recon did not write (a script may
    export files under any name)."""

    page = folder / PAGE
    if page.is_file() and f'content="{GENERATOR}"' not in page.read_text(encoding="utf-8", errors="replace")[:2000]:
        raise FileError(f"{page} is not a page recon wrote; it is left as it is",
                        hint="move it away to let recon write the run's page")
    if final.exists() and not (final / MARKER).is_file():
        raise FileError(f"{final} is not the pictures folder of a recon page; it is left as it is",
                        hint="move it away to let recon write the run's page")


def write_page(folder: Path, options: ReportOptions = ReportOptions()) -> ReportPage:  # noqa: B008
    """(Re)write the page of a run folder; a FileError when it is no run folder or cannot be
    written."""

    folder = Path(folder)
    run = read_run_folder(folder)
    final = inside(folder, PAGE_FILES, "report pictures folder")
    _refuse_foreign(folder, final)
    tmp = folder / f".{PAGE_FILES}.tmp-{os.getpid()}"
    try:
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        (tmp / MARKER).write_text("the pictures of report.html, replaced whenever the page is written\n")
        assets = _draw(run, options, tmp)
        if final.exists():
            shutil.rmtree(final)
        tmp.rename(final)
        assets = _moved(assets, tmp, final)
        nav, sections = body(run, assets)
        subtitle = f"{run.kind.label} in {folder.absolute()}; status {run.status}"
        path = atomic_write_text(folder / PAGE, page(run.title, subtitle, nav, sections))
    except OSError as exc:
        raise FileError(f"cannot write the report page in {folder} ({exc.strerror or exc})",
                        hint="check free space and permissions of the run folder") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    notes = run.notes + ((assets.mesh_note,) if assets.mesh_note else ())
    shown = (*(v.path for v in assets.mesh_views), *(p.path for p in assets.figures), *assets.thumbnails.values(),
             *run.pictures)
    return ReportPage(path, run.kind, run.status, assets.mesh_views, shown, notes)


def write_pages_after_register(out: Path) -> ReportPage | None:
    """The page of ``recon register``'s output folder; when that is the ``reconstruction``
    folder of a run or scan store with a page, that page is written again too, so that it
    shows the registration and the mesh."""
    out = Path(out)
    page = write_page_after_run(out)
    if out.name == "reconstruction" and (out.parent / PAGE).is_file():
        write_page_after_run(out.parent)
    return page


def write_page_after_run(folder: Path, options: ReportOptions = ReportOptions()) -> ReportPage | None:  # noqa: B008
    """The page at the end of a run, however it ended. The run's own results are written by
    now: a page that cannot be made is a warning (``recon report FOLDER`` tries again), not
    a failed run."""
    try:
        return write_page(folder, options)
    except Exception as exc:  # noqa: BLE001 (the run's results stand without their page)

        why = exc.one_line() if isinstance(exc, ReconError) else f"{type(exc).__name__}: {exc}"
        err_console.print(f"warning: no report page for {folder} ({why}); 'recon report {folder}' tries again",
                          markup=False, soft_wrap=True)
        return None
