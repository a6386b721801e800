"""The reports of a batch: JUnit XML (one testcase per job), a JSON summary, a Markdown
summary (for a CI job summary, e.g. ``$GITHUB_STEP_SUMMARY``) and an HTML index page that
links every job's report page (:mod:`recon_cli.batch.index_page`).

JUnit: a job that failed (exit code, expectation) or timed out is a ``<failure>`` whose
``message`` names the measured value and the bound; an infrastructure failure on every
attempt is an ``<error>``; a job that did not run (the batch was interrupted) is
``<skipped>``. The log tail is the testcase's ``<system-out>``.
"""

from __future__ import annotations

import re
import socket
import time
import xml.etree.ElementTree as ET
from pathlib import Path

from recon_cli.batch.index_page import write_index
from recon_cli.batch.result import BatchResult, JobResult, JobStatus, measured_text
from recon_cli.console import write_json
from recon_cli.outputs import atomic_write_text

_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")  # not allowed in XML 1.0


def _xml_text(text: str) -> str:
    return _CONTROL.sub("?", text)


def _details(r: JobResult) -> str:
    lines = [f"command: {' '.join(r.command)}", f"folder: {r.folder}", f"exit code: {r.exit_code}",
             f"wall time: {r.wall_s:.1f} s, attempts: {len(r.attempts)}"]
    lines += [f"{'ok  ' if c.passed else 'FAIL'} {c.describe()}" for c in r.checks]
    return "\n".join(lines)


def junit_xml(batch: BatchResult) -> ET.ElementTree[ET.Element]:
    """The JUnit XML of a batch."""
    counts = batch.counts
    failures = counts["failed"] + counts["timeout"]
    errors = counts["error"]
    tests = len(batch.jobs) + len(batch.pending)
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(batch.started))
    root = ET.Element("testsuites", name=f"recon batch {batch.name}", tests=str(tests), failures=str(failures),
                      errors=str(errors), skipped=str(len(batch.pending)), time=f"{batch.wall_s:.3f}")
    suite = ET.SubElement(root, "testsuite", name=batch.name, tests=str(tests), failures=str(failures),
                          errors=str(errors), skipped=str(len(batch.pending)), time=f"{batch.wall_s:.3f}",
                          timestamp=stamp, hostname=socket.gethostname())
    props = ET.SubElement(suite, "properties")
    ET.SubElement(props, "property", name="executor", value=batch.executor)
    ET.SubElement(props, "property", name="folder", value=str(batch.folder))
    for r in batch.jobs:
        case = ET.SubElement(suite, "testcase", classname=f"recon.batch.{batch.name}", name=r.name,
                             time=f"{r.wall_s:.3f}")
        if r.status is JobStatus.ERROR:
            el = ET.SubElement(case, "error", message=_xml_text(r.reason), type="infrastructure")
            el.text = _xml_text(_details(r))
        elif r.status in (JobStatus.FAILED, JobStatus.TIMEOUT):
            kind = "timeout" if r.status is JobStatus.TIMEOUT else (
                "expectation" if r.exit_code == 0 else "exit_code")
            el = ET.SubElement(case, "failure", message=_xml_text(r.reason), type=kind)
            el.text = _xml_text(_details(r))
        out = ET.SubElement(case, "system-out")
        out.text = _xml_text(_details(r) + ("\n--- log tail\n" + r.log_tail if r.log_tail else ""))
    for name in batch.pending:
        case = ET.SubElement(suite, "testcase", classname=f"recon.batch.{batch.name}", name=name, time="0")
        ET.SubElement(case, "skipped", message="not run: the batch was interrupted")
    ET.indent(root)
    return ET.ElementTree(root)


def summary(batch: BatchResult) -> dict:
    """The JSON summary."""
    return {"name": batch.name, "folder": str(batch.folder), "started": batch.started, "wall_s": batch.wall_s,
            "executor": batch.executor, "workers": batch.workers, "interrupted": batch.interrupted,
            "exit_code": batch.exit_code, "counts": {**batch.counts, "not_run": len(batch.pending)},
            "jobs": [r.to_dict() for r in batch.jobs], "not_run": list(batch.pending)}


_ICON = {JobStatus.PASSED: "✅ passed", JobStatus.FAILED: "❌ failed", JobStatus.TIMEOUT: "⏱ timeout",
         JobStatus.ERROR: "⚠ error"}


def _md(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown(batch: BatchResult) -> str:
    """The Markdown summary: counts, then one row per job."""
    c = batch.counts
    head = f"## recon batch `{batch.name}`: " + ("all passed" if batch.exit_code == 0 else "FAILED")
    lines = [head, "",
             f"{len(batch.jobs)} jobs: {c['passed']} passed, {c['failed']} failed, {c['timeout']} timed out, "
             f"{c['error']} errors" + (f", {len(batch.pending)} not run" if batch.pending else "")
             + f"; {batch.wall_s:.1f} s on {batch.executor}.", "",
             "| job | result | wall time | measured | reason |", "| --- | --- | ---: | --- | --- |"]
    for r in batch.jobs:
        note = " (resumed)" if r.resumed else ""
        lines.append(f"| {_md(r.name)} | {_ICON[r.status]}{note} | {r.wall_s:.1f} s | {_md(measured_text(r))} | "
                     f"{_md(r.reason) or '-'} |")
    for name in batch.pending:
        lines.append(f"| {_md(name)} | not run | - | - | the batch was interrupted |")
    return "\n".join(lines) + "\n"


def write_reports(batch: BatchResult, extra: dict[str, Path | None]) -> dict[str, Path]:
    """junit.xml, summary.json, summary.md and index.html in the batch folder, and copies
    where ``extra`` says (keys "junit", "json", "markdown")."""
    tree = junit_xml(batch)
    xml = ET.tostring(tree.getroot(), encoding="unicode", xml_declaration=True) + "\n"
    texts = {"junit": xml, "markdown": markdown(batch)}
    names = {"junit": "junit.xml", "json": "summary.json", "markdown": "summary.md"}
    written: dict[str, Path] = {}
    for key, name in names.items():
        copy = extra.get(key)
        targets = [batch.folder / name] + ([Path(copy)] if copy else [])
        for target in targets:
            target.parent.mkdir(parents=True, exist_ok=True)
            if key == "json":
                write_json(target, summary(batch))
            else:
                atomic_write_text(target, texts[key])
        written[key] = targets[-1]
    written["index"] = write_index(batch)
    return written
