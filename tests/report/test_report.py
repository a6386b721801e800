"""Report pages: a run writes its page, the page is valid HTML whose every picture and link
exists, the mesh pictures are not blank, `recon report` rebuilds the page of every kind of
run folder, and a batch's index page links every job's page.

One smoke run (three views at a quarter of the image size) feeds every test; the autoscan
and batch folders are put together from its files.
"""

from __future__ import annotations

import json
import shutil
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import cv2
import numpy as np
import pytest

from recon_cli.cli import main
from recon_cli.errors import FileError
from recon_cli.paths import SCRIPTS_DIR
from recon_cli.report.mesh_view import image_stats, render_mesh

VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}


class _Strict(HTMLParser):
    """html.parser with the checks a browser does not make: every element closed in order,
    no end tag for a void element, unique ids; collects ids and links."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.stack: list[str] = []
        self.errors: list[str] = []
        self.ids: list[str] = []
        self.links: list[tuple[str, str]] = []  # (tag, src or href)
        self.doctype: str | None = None
        self.tags: list[str] = []

    def handle_decl(self, decl: str) -> None:
        self.doctype = decl

    def handle_starttag(self, tag: str, attrs) -> None:
        a = dict(attrs)
        self.tags.append(tag)
        if "id" in a:
            self.ids.append(a["id"])
        for key in ("src", "href"):
            if a.get(key) is not None:
                self.links.append((tag, a[key]))
        if tag not in VOID:
            self.stack.append(tag)

    def handle_startendtag(self, tag: str, attrs) -> None:
        if tag not in VOID:
            self.errors.append(f"<{tag}/> is not a void element")
        self.handle_starttag(tag, attrs)

    def handle_endtag(self, tag: str) -> None:
        if tag in VOID:
            self.errors.append(f"end tag of the void element <{tag}>")
        elif not self.stack or self.stack[-1] != tag:
            self.errors.append(f"</{tag}> closes <{self.stack[-1] if self.stack else 'nothing'}>")
        else:
            self.stack.pop()


def check_page(page: Path) -> _Strict:
    """The page is well-formed HTML5 and every relative link and picture exists."""
    text = page.read_text(encoding="utf-8")
    parser = _Strict()
    parser.feed(text)
    parser.close()
    assert parser.doctype is not None and parser.doctype.lower() == "doctype html"
    assert not parser.errors, parser.errors[:5]
    assert not parser.stack, f"unclosed: {parser.stack}"
    assert parser.tags[:2] == ["html", "head"] and "body" in parser.tags and "title" in parser.tags
    assert len(parser.ids) == len(set(parser.ids)), "duplicate ids"
    import lxml.html

    root = lxml.html.fromstring(text.encode())
    assert root.tag == "html" and len(root.findall(".//h1")) == 1
    missing = []
    for tag, link in parser.links:
        parts = urlsplit(link)
        assert not parts.scheme and not parts.netloc, f"{link}: the page fetches nothing from elsewhere"
        if not parts.path:
            assert parts.fragment in parser.ids, f"#{parts.fragment} points nowhere"
            continue
        if not (page.parent / unquote(parts.path)).exists():
            missing.append(f"<{tag}> {link}")
    assert not missing, missing
    return parser


def pictures(parser: _Strict, page: Path, prefix: str) -> list[Path]:
    return [page.parent / unquote(link) for tag, link in parser.links if tag == "img" and link.startswith(prefix)]


def not_blank(path: Path) -> bool:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    stats = image_stats(image)
    return stats.std > 10 and stats.foreground > 0.05 and not stats.blank()


def table_rows(page: Path, section: str) -> list:
    import lxml.html

    root = lxml.html.fromstring(page.read_bytes())
    return root.xpath(f'//section[@id="{section}"]//table[thead]/tbody/tr')


@pytest.fixture(scope="module")
def smoke(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("report") / "smoke"
    assert main(["run", str(SCRIPTS_DIR / "smoke.xml"), "--out", str(out)]) == 0
    return out


# ----------------------------------------------------------------------------- a script run's page
def test_a_run_writes_its_page(smoke, capsys):
    page = smoke / "report.html"
    parser = check_page(page)
    text = page.read_text()
    assert "recon run: smoke" in text and "status done" in text
    # the mesh from four directions, each picture showing the mesh
    mesh = pictures(parser, page, "report_files/mesh_")
    assert [p.name for p in mesh] == ["mesh_front.png", "mesh_side.png", "mesh_top.png", "mesh_oblique.png"]
    assert all(not_blank(p) for p in mesh)
    # the figures: plan times, coverage, the evaluation's histogram, the pose graph's ICP results
    shown = {p.name for p in pictures(parser, page, "")}
    assert {"plan_times.png", "coverage.png", "cloud_distances.png", "icp_residuals.png"} <= shown
    # every command, every scan with its pose source and ICP residuals
    report = json.loads((smoke / "run_report.json").read_text())
    assert len(table_rows(page, "commands")) == len(report["commands"])
    scans = table_rows(page, "scans")
    assert len(scans) == 3
    cells = [[c.text_content() for c in row.findall("td")] for row in scans]
    assert all(c[4] in ("charuco", "kinematics") for c in cells)  # the pose source
    assert sum("fitness" in c[8] and "RMSE" in c[8] for c in cells) >= 2  # ICP of the scans in the pose graph
    assert all(row.find(".//img") is not None for row in scans)  # the thumbnails
    # a link to every PLY file of the run
    plys = {p.relative_to(smoke).as_posix() for p in smoke.rglob("*.ply")}
    linked = {unquote(link) for tag, link in parser.links if tag == "a" and link.endswith(".ply")}
    assert plys == linked and {"bottle_mesh.ply", "reconstruction/mesh.ply"} <= plys


def test_recon_report_rebuilds_every_kind_of_folder(smoke, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(smoke, run)
    shutil.rmtree(run / "report_files")
    (run / "report.html").unlink()
    assert main(["report", str(run), "--no-render"]) == 0
    out = capsys.readouterr().out
    assert f"page: {run / 'report.html'}" in out and "not rendered" in out
    check_page(run / "report.html")
    assert not (run / "report_files" / "mesh_front.png").exists()
    # the registration's own folder (as recon register writes it): scans found in the store beside it
    assert main(["report", str(run / "reconstruction"), "--width", "200"]) == 0
    page = run / "reconstruction" / "report.html"
    parser = check_page(page)
    assert "recon register" in page.read_text() and len(table_rows(page, "scans")) == 3
    mesh = pictures(parser, page, "report_files/mesh_")
    assert len(mesh) == 4 and all(not_blank(p) for p in mesh)
    assert cv2.imread(str(mesh[0])).shape[:2] == (150, 200)
    # a scan store (as recon capture writes it)
    assert main(["report", str(run / "scans")]) == 0
    page = run / "scans" / "report.html"
    check_page(page)
    assert "scan store" in page.read_text() and len(table_rows(page, "scans")) == 3


def test_recon_register_writes_its_page_and_updates_the_store_page(smoke, tmp_path, capsys):
    store = tmp_path / "store"
    shutil.copytree(smoke / "scans", store)
    assert main(["report", str(store), "--no-render"]) == 0
    assert "registered" not in (store / "report.html").read_text()
    assert main(["register", str(store), "--depth", "6", "--global-only"]) == 0
    assert f"page: {store / 'reconstruction' / 'report.html'}" in capsys.readouterr().out
    parser = check_page(store / "reconstruction" / "report.html")
    assert len(pictures(parser, store / "reconstruction" / "report.html", "report_files/mesh_")) == 4
    page = store / "report.html"  # the store's page now shows the registration and its mesh
    parser = check_page(page)
    assert "3 of 3 scans" in page.read_text() and len(pictures(parser, page, "report_files/mesh_")) == 4


def test_an_autoscan_folder(smoke, tmp_path, capsys):
    auto = tmp_path / "auto"
    shutil.copytree(smoke / "scans", auto)
    shutil.copytree(smoke / "reconstruction", auto / "reconstruction")
    (auto / "iterations").mkdir()
    for k in (1, 2):
        shutil.copyfile(smoke / "reconstruction" / "cloud_distances.png",
                        auto / "iterations" / f"iteration_{k:02d}.png")
    views = [{"status": s, "iteration": i} for s, i in (("completed", 0), ("infeasible", 1), ("completed", 1),
                                                         ("completed", 2))]
    (auto / "autoscan_report.json").write_text(json.dumps({
        "method": "ellipsoid", "object": "bottle", "cell": "gantry", "n": 3, "d_c": 0.55, "seed": 0, "scans": 3,
        "interrupted": False, "error": None, "infeasible_views": 1, "planning_requests": 4, "trajectory_s": 20.0,
        "coverage_1mm": 0.8123, "accuracy": {"mean_mm": -0.1, "std_mm": 0.2, "points": 1000},
        "seconds_total": 10.0, "views": views}))
    assert main(["report", str(auto)]) == 0
    page = auto / "report.html"
    parser = check_page(page)
    text = page.read_text()
    assert "recon autoscan: bottle" in text and "81.23 %" in text
    assert [p.name for p in pictures(parser, page, "iterations/")] == ["iteration_01.png", "iteration_02.png"]
    rows = [[c.text_content() for c in r.findall("td")] for r in table_rows(page, "iterations")]
    assert rows == [["0", "1", "0"], ["1", "1", "1"], ["2", "1", "0"]]


def test_text_from_the_run_is_escaped(smoke, tmp_path, capsys):
    run = tmp_path / "evil"
    run.mkdir()
    report = json.loads((smoke / "run_report.json").read_text())
    report.update(name="<script>alert(1)</script>", status="aborted", aborted="a & b <i>")
    (run / "run_report.json").write_text(json.dumps(report))
    assert main(["report", str(run)]) == 0
    text = (run / "report.html").read_text()
    assert "<script>" not in text and "&lt;script&gt;alert(1)&lt;/script&gt;" in text
    assert "a &amp; b &lt;i&gt;" in text and "no scans in this folder" in text and "no mesh in this folder" in text
    check_page(run / "report.html")


def test_files_recon_did_not_write_are_left_alone(smoke, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(smoke, run)
    (run / "report_files" / ".recon-report").unlink()  # as if a script had exported into report_files/
    assert main(["report", str(run)]) == 1
    assert "is not the pictures folder of a recon page" in capsys.readouterr().err
    assert (run / "report_files" / "mesh_front.png").is_file()
    shutil.rmtree(run / "report_files")
    (run / "report.html").write_text("<p>mine</p>")
    assert main(["report", str(run)]) == 1
    assert "is not a page recon wrote" in capsys.readouterr().err
    assert (run / "report.html").read_text() == "<p>mine</p>"


def test_a_folder_that_is_no_run_is_a_one_line_error(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("x")
    for target, needle in ((tmp_path / "missing", "does not exist"), (tmp_path / "empty", "is not a run folder"),
                           (tmp_path / "file", "is not a folder")):
        assert main(["report", str(target)]) == 1
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "empty" / "report.html").exists()


# ----------------------------------------------------------------------------- mesh pictures
def test_blank_pictures_are_recognized(tmp_path):
    import open3d as o3d

    assert image_stats(np.full((30, 40), 255, np.uint8)).blank()
    assert image_stats(np.full((30, 40, 3), 128, np.uint8)).blank()  # uniform, whatever its grey
    sphere = o3d.geometry.TriangleMesh.create_sphere(0.05)
    sphere.translate((0.3, -0.2, 0.8))
    o3d.io.write_triangle_mesh(str(tmp_path / "sphere.ply"), sphere)
    views = render_mesh(tmp_path / "sphere.ply", tmp_path / "out", width=160, seed=0)
    for v in views:  # the sphere fills the middle of every view, shaded
        image = cv2.imread(str(v.path), cv2.IMREAD_UNCHANGED)
        assert image.shape == (120, 160) and not v.stats.blank() and 0.2 < v.stats.foreground < 0.8
        assert image[60, 80] < 250 and image[2, 2] == 255
    o3d.io.write_triangle_mesh(str(tmp_path / "empty.ply"), o3d.geometry.TriangleMesh())
    with pytest.raises(FileError, match="no triangles"):
        render_mesh(tmp_path / "empty.ply", tmp_path / "out", seed=0)


def test_many_icp_results_are_one_matrix(tmp_path):
    from recon_cli.report.figures import icp_png
    from recon_cli.report.model import Edge

    names = [f"scan_{k:04d}" for k in range(12)]
    edges = tuple(Edge(a, b, "odometry" if j == i + 1 else "loop_closure", 100, 0.5, 0.1, rejected=(i, j) == (0, 5))
                  for i, a in enumerate(names) for j, b in enumerate(names) if j > i)
    assert len(edges) == 66
    image = cv2.imread(str(icp_png(tmp_path / "icp.png", edges)))
    assert image.shape[1] <= 1200 and not image_stats(image).blank()


# ----------------------------------------------------------------------------- batches
def test_the_batch_index_links_every_job_page(smoke, tmp_path):
    from recon_cli.batch.expectations import Measured, judge
    from recon_cli.batch.reports import write_reports
    from recon_cli.batch.result import Attempt, BatchResult, JobResult, JobStatus
    from recon_cli.batch.spec import Expectations

    folder = tmp_path / "batch"
    for name in ("first", "second"):
        shutil.copytree(smoke, folder / "jobs" / name / "output")
        (folder / "jobs" / name / "log.txt").write_text("$ recon run smoke.xml\n")
    (folder / "jobs" / "check").mkdir(parents=True)  # a validation: no output folder, no page

    def result(name, status, checks=()):
        return JobResult(name, "run", status, "" if status is JobStatus.PASSED else "coverage 42 % < 60 %", 0, 12.5,
                         (Attempt(0, 12.5),), Measured(coverage=42.0), checks, str(folder / "jobs" / name),
                         ("recon", "run", "smoke.xml"), "", "host", 0.0)

    checks = judge(Expectations(min_coverage_pct=60, max_wall_time_s=100), Measured(coverage=42.0, wall_time=12.5))
    batch = BatchResult("b<1>", folder, (result("first", JobStatus.PASSED), result("second", JobStatus.FAILED, checks),
                                         result("check", JobStatus.PASSED)), ("later",), 30.0, "local pool, 1 worker",
                        1, 0.0)
    reports = write_reports(batch, {})
    index = reports["index"]
    assert index == folder / "index.html"
    parser = check_page(index)
    pages = {unquote(link) for tag, link in parser.links if link.endswith("report.html")}
    assert pages == {"jobs/first/output/report.html", "jobs/second/output/report.html"}
    text = index.read_text()
    assert "recon batch b&lt;1&gt;: failed" in text and "coverage 42 % &lt; 60 %" in text
    assert "wall time 12.5 s &lt;= 100 s" in text and "later" in text and "not run" in text
    rows = table_rows(index, "jobs")
    assert [r.findall("td")[0].text_content() for r in rows] == ["first", "second", "check", "later"]
