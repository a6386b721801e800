"""The sections of a run's page, from a :class:`RunFolder` and the pictures made for it."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from recon_cli.report.markup import (
    Content,
    Html,
    facts,
    figure,
    href,
    image,
    link,
    note,
    num,
    pct,
    section,
    size,
    status,
    table,
    tag,
)
from recon_cli.report.mesh_view import MeshView
from recon_cli.report.model import Edge, Registration, RunFolder, RunKind, Scan, Side, TwoSides
from recon_cli.runs.register import PoseError
from recon_cli.runs.script_run import ScriptRunReport


@dataclass(frozen=True)
class Picture:
    path: Path
    caption: str


@dataclass(frozen=True)
class Assets:
    """What was drawn for the page."""

    mesh: Path | None = None  # the rendered mesh file
    mesh_views: tuple[MeshView, ...] = ()
    mesh_note: str | None = None  # why there are no mesh pictures
    figures: tuple[Picture, ...] = ()
    thumbnails: dict[str, Path] = field(default_factory=dict)  # scan folder -> its thumbnail


def _error(e: PoseError | None) -> str | None:
    return None if e is None else f"{e.translation_mm:.3f} mm / {e.rotation_deg:.3f}°"


def _when(stamp: float | None) -> str | None:
    return None if not stamp else time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(stamp))


# ----------------------------------------------------------------------------- summary
def summary(run: RunFolder) -> Html:
    rows: list[tuple[str, Content]] = [("kind", run.kind.label), ("status", status(run.status)),
                                       ("folder", str(run.folder.absolute()))]
    s, r, a, c = run.session, run.script_run, run.autoscan, run.capture
    if r is not None:
        rows += [("script", f"{r.script} ({r.dialect} dialect)"), ("on failure", r.on_failure),
                 ("dry run", "yes" if r.dry_run else None), ("stopped", r.stopped), ("exit code", num(r.exit_code)),
                 ("commands", str(len(r.commands))), ("scans", num(r.scans)), ("wall time", num(r.seconds, ".1f", "s"))]
    if a is not None:
        rows += [("method", a.method), ("scans", f"{a.scans} of N = {a.n}" if a.n else str(a.scans)),
                 ("camera distance d_c", num(a.d_c, ".3g", "m")),
                 ("stopped", "interrupted" if a.interrupted else None),
                 ("error", a.error), ("infeasible views sampled", num(a.infeasible_views)),
                 ("planning requests", num(a.planning_requests)),
                 ("trajectories", num(a.trajectory_s, ".1f", "s")),
                 ("wall time", num(a.seconds_total, ".1f", "s"))]  # coverage and accuracy: the evaluation
    if c is not None:
        rows += [("views", f"{c.scans} of {c.views} scanned"),
                 ("views skipped", num(len(c.failures)) if c.failures else None),
                 ("error", c.error), ("wall time", num(c.seconds, ".1f", "s"))]
    if s is not None:
        rows += [("object", s.object_name), ("cell", s.cell_kind), ("backend", s.backend),
                 ("sensor", None if s.sensor is None else s.sensor + ("" if s.noise is None else
                                                                     f" (noise {'on' if s.noise else 'off'})")),
                 ("realism", (s.realism or {}).get("name")), ("seed", num(s.seed)),
                 ("session started", _when(s.created))]
    g = run.registration
    if g is not None:
        sources = ", ".join(f"{k} {v}" for k, v in g.pose_sources.items() if v)
        rows += [("registered", f"{g.registered} of {g.registered + g.skipped} scans"
                  + (f" (pose sources: {sources})" if sources else "")), ("output frame", g.frame),
                 ("ChArUco pose error (mean)", _error(g.charuco_error_mean)),
                 ("final pose error (mean)", _error(g.final_error_mean)),
                 ("registration time", num(g.timings_s.get("total"), ".1f", "s"))]
    for e in run.evaluations:
        rows.append((f"{e.name} vs {e.reference}",
                     f"mean {e.mean_mm:+.3f} mm, std {e.std_mm:.3f} mm; coverage {pct(e.coverage, 2)}"
                     if e.mean_mm is not None and e.std_mm is not None else "incomplete evaluation"))
    body: list[Content] = [facts(rows)]
    body += [note(n) for n in run.notes]
    return section("summary", "Summary", *body)


# ----------------------------------------------------------------------------- pictures
def mesh(run: RunFolder, assets: Assets) -> Html:
    if not assets.mesh_views:
        return section("mesh", "Mesh", note(assets.mesh_note or "no mesh in this folder"))
    pictures = [figure(v.path, run.folder, f"{v.name} (azimuth {v.azimuth_deg:g}°, elevation {v.elevation_deg:g}°)")
                for v in assets.mesh_views]
    return section("mesh", "Mesh", tag("p", ["rendered from ", link(assets.mesh, run.folder,
                                                                   str(assets.mesh.relative_to(run.folder)))
                                             if assets.mesh and assets.mesh.is_relative_to(run.folder) else
                                             str(assets.mesh)]),
                   tag("div", pictures, class_="gallery"))


def figures(run: RunFolder, assets: Assets) -> Html:
    if not assets.figures:
        return section("figures", "Figures", note("no figures: this run has no moves, registration or evaluation "
                                                  "to plot"))
    return section("figures", "Figures",
                   tag("div", [figure(p.path, run.folder, p.caption) for p in assets.figures], class_="gallery"))


# ----------------------------------------------------------------------------- tables
def commands(script_run: ScriptRunReport) -> Html:
    rows = [(c.source, c.command, status(c.status), f"{c.seconds:.2f}", c.message) for c in script_run.commands]
    return section("commands", "Commands",
                   table(("source", "command", "status", "time [s]", "message"), rows, numeric=(3,)))


def _icp(edges: tuple[Edge, ...]) -> str | None:
    good = [(e.fitness, e.rmse_mm) for e in edges if not e.rejected and e.fitness is not None and e.rmse_mm is not None]
    if not edges:
        return None
    text = f"{len(edges)} edge" + ("s" if len(edges) != 1 else "")
    if good:
        fitness, rmse_mm = [f for f, _ in good], [r for _, r in good]
        text += (f": fitness {min(fitness):.2f}...{max(fitness):.2f}, "
                 f"RMSE ≤ {max(rmse_mm):.3f} mm")
    rejected = sum(e.rejected for e in edges)
    return text + (f", {rejected} rejected" if rejected else "")


def _scan_row(run: RunFolder, s: Scan, assets: Assets, g: Registration | None, key: str) -> list[Content]:
    """One scan's row; ``g``: the registration it belongs to, ``key``: of its thumbnail."""
    pose = None if g is None else g.pose_of(s.folder)
    thumb = assets.thumbnails.get(key)
    picture = None if thumb is None else tag("a", image(thumb, run.folder, f"{s.folder} colour image"),
                                             href=None if s.color is None else href(s.color, run.folder))
    move = s.move
    notes = [x for x in (s.problem, None if pose is None else pose.skipped,
                         None if pose is None or pose.source != "kinematics" else pose.reason) if x]
    return [tag("span", [s.folder, Html("<br>") if s.name else None, s.name]), picture,
            None if s.width is None else f"{s.width} x {s.height}",
            None if move is None else f"{move.planner or '-'}: {num(move.plan_s, '.2f', 's')} planning, "
                                      f"{num(move.trajectory_s, '.2f', 's')} trajectory",
            None if pose is None else pose.source, None if pose is None else num(pose.corners),
            None if pose is None else num(pose.reprojection_px, ".3f"), None if pose is None else num(pose.points),
            None if g is None else _icp(g.edges_of(s.folder)), None if pose is None else _error(pose.final_error),
            "; ".join(notes)]


_SCAN_HEAD = ("scan", "colour", "size [px]", "move", "pose source", "corners", "reprojection [px]", "points in box",
              "ICP (pose graph)", "pose error vs truth", "note")
_SCAN_NOTE = ("Pose source: the ChArUco board in the colour image, else the robot's kinematics. ICP: the scan's "
              "pairwise registrations in the pose graph (fitness: share of points with a correspondence; RMSE of "
              "the inliers). Pose error: simulation only.")


def scans(run: RunFolder, assets: Assets) -> Html:
    parts: list[Content] = []
    sides = run.two_sides.sides if run.two_sides is not None else ()
    count = len(run.scans) + sum(len(side.scans) for side in sides)
    if run.scans:
        parts.append(table(_SCAN_HEAD, [_scan_row(run, s, assets, run.registration, s.folder) for s in run.scans],
                           numeric=(5, 6, 7)))
    for side in sides:  # each side its own scans and registration
        parts.append(tag("h3", f"{side.label.capitalize()} ({len(side.scans)} scans)"))
        parts.append(table(_SCAN_HEAD, [_scan_row(run, s, assets, side.registration, f"{side.name}/{s.folder}")
                                        for s in side.scans], numeric=(5, 6, 7)) if side.scans
                     else note(f"no scans of {side.label} in {side.folder}"))
    if count:
        parts.append(tag("p", _SCAN_NOTE, class_="meta"))
    else:
        parts.append(note("no scans in this folder"))
    if run.capture is not None and run.capture.failures:
        parts += [tag("h3", "Skipped views"),
                  table(("view", "why"), [(str(f.view), f.message) for f in run.capture.failures], numeric=(0,))]
    return section("scans", f"Scans ({count})", *parts)


def registration(run: RunFolder) -> Html:
    g = run.registration
    if g is None:
        return section("registration", "Registration", note("no registration report in this folder"))
    timing = ", ".join(f"{k} {v:.2f} s" for k, v in g.timings_s.items())
    parts: list[Content] = [facts([("report", link(g.report, run.folder, str(g.report.relative_to(run.folder)))
                                     if g.report.is_relative_to(run.folder) else str(g.report)),
                                    ("scan store", None if g.scan_store is None else str(g.scan_store.absolute())),
                                    ("timings", timing or None), ("fused points", num(g.fused_points)),
                                    ("pruned loop closures", num(g.pruned_loop_closures))])]
    if g.edges:
        rows = [(e.source, e.target, e.kind.replace("_", " "), num(e.correspondences), num(e.fitness, ".3f"),
                 num(e.rmse_mm, ".3f"), status("rejected") if e.rejected else "") for e in g.edges]
        parts.append(table(("source", "target", "kind", "correspondences", "fitness", "RMSE [mm]", ""), rows,
                           numeric=(3, 4, 5)))
    else:
        parts.append(note("no pose graph: global registration only (or a single scan)"))
    return section("registration", "Registration and pose graph", *parts)


def _side_row(run: RunFolder, side: Side) -> list[Content]:
    g = side.registration
    return [side.label, num(len(side.scans)), num(side.seconds, ".1f", "s"),
            None if g is None else f"{g.registered} of {g.registered + g.skipped}",
            None if g is None or g.final_error_mean is None else _error(g.final_error_mean),
            pct(side.coverage, 2),
            None if side.cloud is None else link(side.cloud, run.folder, str(side.cloud.relative_to(run.folder))
                                                 if side.cloud.is_relative_to(run.folder) else str(side.cloud))]


def two_sides(run: RunFolder, sides: TwoSides) -> Html:
    """How the object was turned over, each side, the registration of the sides by shape and
    its confidence, the merged model."""
    r, reg = sides.report, sides.report.registration
    turn = dict(r.turn)
    numbers = {k: v for k, v in turn.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
    how = (f"by physics: tipped {num(numbers.get('tilt_deg'), '.1f', '°')}, settled in "
           f"{num(numbers.get('settle_s'), '.2f', 's')}" if turn.get("by") == "physics" else
           f"by the operator (pause {num(numbers.get('pause_s'), '.1f', 's')})" if turn.get("by") == "operator"
           else "not recorded")
    face = turn.get("face") if isinstance(turn.get("face"), dict) else None
    if turn.get("by") == "physics" and face is not None:
        how += f", onto a face of its hull that tips at {num(face.get('tipping_deg'), '.1f', '°')}"
        if face.get("missed_in_view") is not None:
            how += (f" and shows {pct(face.get('missed_in_view'))} of the surface (side 1 missed "
                    f"{pct(face.get('missed_by_side_1'))})")
    truth = reg.get("truth") if isinstance(reg.get("truth"), dict) else None
    confidence = ("not trusted: " + str(reg["reason"]) if reg.get("reason") else
                  "ambiguous in pose and in shape" if reg.get("shape_ambiguous") else
                  "ambiguous in pose, not in shape (the merged shape is right)" if reg.get("ambiguous") else "unique")
    rows: list[tuple[str, Content]] = [
        ("turned over", how),
        ("registration of the sides", f"fitness {num(reg.get('fitness'), '.3f')} (side 2 onto side 1) / "
                                      f"{num(reg.get('fitness_reverse'), '.3f')} (side 1 onto side 2), RMSE "
                                      f"{num(None if reg.get('rmse_m') is None else reg['rmse_m'] * 1e3, '.3f', 'mm')},"
                                      f" overlap {pct(reg.get('overlap'))}, {num(reg.get('candidates'))} poses tried"),
        ("confidence", confidence),
        ("error vs the true turn", None if truth is None else
         f"{num(truth.get('rotation_deg'), '.4f', '°')}, {num(truth.get('translation_mm'), '.3f', 'mm')}"),
        ("whole surface covered", pct(r.coverage_whole, 2)),
        ("not merged", r.error),
        ("wall time", num(r.seconds, ".1f", "s")),
        ("merged cloud", None if sides.cloud is None else link(sides.cloud, run.folder,
                                                                str(sides.cloud.relative_to(run.folder))
                                                                if sides.cloud.is_relative_to(run.folder)
                                                                else str(sides.cloud)))]
    parts: list[Content] = [facts(rows),
                            table(("side", "scans", "wall time", "registered", "pose error vs truth (mean)",
                                   "whole surface alone", "cloud"), [_side_row(run, side) for side in sides.sides],
                                  numeric=(1, 2, 5))]
    alternatives = [a for a in reg.get("alternatives", ()) if isinstance(a, dict)]
    if alternatives:
        parts += [tag("h3", "Other poses that fit as well"),
                  table(("turned from the reported pose", "moved at the centre", "fitness", "RMSE [mm]",
                         "shape difference [mm]"),
                        [(num(a.get("angle_deg"), ".2f", "°"), num(None if a.get("translation_m") is None
                                                                   else a["translation_m"] * 1e3, ".2f", "mm"),
                          f"{num(a.get('fitness'), '.3f')} / {num(a.get('fitness_reverse'), '.3f')}",
                          num(None if a.get("rmse_m") is None else a["rmse_m"] * 1e3, ".3f"),
                          num(None if a.get("shape_difference_m") is None else a["shape_difference_m"] * 1e3, ".2f"))
                         for a in alternatives], numeric=(0, 1, 3, 4))]
    parts.append(tag("p", "Side 2 is registered onto side 1 by shape alone (docs/two_sided.md): fitness is the share "
                          "of each side's points where the other could see them that have a partner; other poses that "
                          "fit as well make the pose ambiguous, and when they give another shape the sides are not "
                          "merged.", class_="meta"))
    return section("sides", "Two sides", *parts)


def evaluations(run: RunFolder) -> Html:
    rows = [(link(e.report, run.folder, e.name), e.reference, num(e.points), num(e.mean_mm, "+.4f"),
             num(e.std_mm, ".4f"), num(e.rms_mm, ".4f"), ", ".join(f"{k}: {pct(v)}" for k, v in e.within.items()),
             pct(e.coverage, 2), pct(e.coverage_visible, 2), num(e.tolerance_mm, "g"))
            for e in run.evaluations]
    return section("evaluation", "Evaluation against the reference",
                   table(("reconstruction", "reference", "points", "mean [mm]", "std [mm]", "RMS [mm]",
                          "within", "coverage", "coverage (visible)", "tolerance [mm]"), rows,
                         numeric=(2, 3, 4, 5, 7, 8, 9)))


def iterations(run: RunFolder) -> Html:
    a = run.autoscan
    parts: list[Content] = []
    if a is not None and a.views:
        by_iteration: dict[int, list[str]] = {}
        for v in a.views:
            by_iteration.setdefault(v.iteration, []).append(v.status)
        rows = [(str(k), str(s.count("completed")), str(s.count("infeasible")))
                for k, s in sorted(by_iteration.items())]
        parts.append(table(("iteration", "scanned", "infeasible views"), rows, numeric=(0, 1, 2)))
    if run.pictures:
        parts.append(tag("div", [figure(p, run.folder, p.stem.replace("_", " "), width=360) for p in run.pictures],
                         class_="gallery"))
        parts.append(tag("p", "Partial cloud, its ellipsoid and the views: infeasible red, completed green, planned "
                              "blue, the next one yellow.", class_="meta"))
    else:
        parts.append(note("no iteration pictures (--no-pictures, or the run stopped before the first iteration)"))
    return section("iterations", "View planning iterations", *parts)


def files(run: RunFolder) -> Html:
    def rows(items):
        return [(link(f.path, run.folder, str(f.path.relative_to(run.folder))), f.what, size(f.bytes))
                for f in items]

    parts: list[Content] = []
    if run.plys:
        parts.append(table(("PLY file", "what", "size"), rows(run.plys), numeric=(2,)))
    else:
        parts.append(note("no PLY files in this folder"))
    if run.reports:
        parts.append(table(("report", "what", "size"), rows(run.reports), numeric=(2,)))
    return section("files", "Files", *parts)


def body(run: RunFolder, assets: Assets) -> tuple[list[tuple[str, str]], list[Html]]:
    """The navigation entries and the sections of the page, in order."""
    parts = [("summary", "Summary", summary(run)), ("mesh", "Mesh", mesh(run, assets)),
             ("figures", "Figures", figures(run, assets))]
    if run.two_sides is not None:
        parts.append(("sides", "Two sides", two_sides(run, run.two_sides)))
    if run.script_run is not None:
        parts.append(("commands", "Commands", commands(run.script_run)))
    parts.append(("scans", "Scans", scans(run, assets)))
    if run.registration is not None or run.scans:
        parts.append(("registration", "Registration", registration(run)))
    if run.evaluations:
        parts.append(("evaluation", "Evaluation", evaluations(run)))
    if run.kind is RunKind.AUTOSCAN:
        parts.append(("iterations", "Iterations", iterations(run)))
    parts.append(("files", "Files", files(run)))
    return [(i, t) for i, t, _ in parts], [s for _, _, s in parts]

