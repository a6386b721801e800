"""recon batch: batch files, pass criteria, JUnit output, timeouts, retries, resume, Dask.

The end-to-end tests run a batch of four small jobs (the smoke script, a capture at a tenth
of the image size, a validation with a bound that cannot hold, a capture with a 1 s
timeout) on the local pool and on a Dask LocalCluster, and a batch that is killed and
resumed.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from recon_cli.batch import job as job_module
from recon_cli.batch.expectations import Measured, judge
from recon_cli.batch.job import run_job
from recon_cli.batch.reports import junit_xml, markdown
from recon_cli.batch.result import Attempt, BatchResult, JobResult, JobStatus
from recon_cli.batch.spec import (
    CommandOption,
    Expectations,
    JobKind,
    JobSpec,
    Overrides,
    load_batch,
    load_batch_file,
)
from recon_cli.cli import main
from recon_cli.cli.batch_commands import AppCommands
from recon_cli.errors import ReconError

ROOT = Path(__file__).resolve().parents[1]
COMMANDS = AppCommands()  # the options of recon's commands, as recon batch hands them in

FOUR = """\
name: four
defaults: {timeout_s: 300, retries: 0}
jobs:
  - name: smoke
    run: smoke.xml
    options: {seed: 0}
    expect: {min_coverage_pct: 10, max_std_mm: 2.0, max_planning_failures: 0}
  - name: capture
    capture: {object: bottle, resolution: 0.1, noise: false}
    expect: {max_planning_failures: 0}
  - name: impossible          # an expectation that cannot hold
    validate: smoke.xml
    expect: {max_wall_time_s: 0.001}
  - name: slow                # exceeds its timeout
    capture: {object: bottle, resolution: 0.1}
    timeout_s: 1
"""


def write(tmp_path: Path, text: str, name: str = "batch.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.fixture(autouse=True)
def _environment(monkeypatch):
    monkeypatch.setenv("MUJOCO_GL", "egl")
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS", raising=False)


# ----------------------------------------------------------------------------- the batch file
def test_matrix_expands_with_names_options_and_exclusions(tmp_path):
    path = write(tmp_path, """\
defaults:
  expect: {max_wall_time_s: 100, min_coverage_pct: 50}
  options: {resolution: 0.2}
jobs:
  - name: scan-{object}-s{seed}
    autoscan: {scans: 4, pictures: false}
    matrix: {object: [bottle, mug], seed: [0, 1]}
    exclude: [{object: mug, seed: 1}]
  - capture: {views: eq-4.1}
    matrix: {seed: [3]}
  - run: smoke.xml
""")
    spec = load_batch_file(path, COMMANDS)
    names = [j.name for j in spec.jobs]
    assert names == ["scan-bottle-s0", "scan-bottle-s1", "scan-mug-s0", "capture-seed=3", "smoke"]
    first = spec.jobs[0]
    assert first.kind is JobKind.AUTOSCAN
    assert first.args == ("--resolution", "0.2", "--scans", "4", "--no-pictures", "--object", "bottle", "--seed", "0")
    assert first.expect == Expectations(min_coverage_pct=50, max_wall_time_s=100)
    capture = spec.jobs[3]
    assert capture.views == 24 and "--resolution" in capture.args
    assert capture.expect == Expectations(max_wall_time_s=100)  # a capture measures no coverage
    smoke = spec.jobs[4]
    assert smoke.args == (str(ROOT / "scripts_xml" / "smoke.xml"),)  # a shipped script by name
    assert "--resolution" not in smoke.args  # recon run has no such option
    cmd = smoke.command(tmp_path / "out")
    assert cmd[1:4] == ["-m", "recon_cli", "run"] and cmd[-2:] == ["--out", str(tmp_path / "out")]


@pytest.mark.parametrize("text, needle", [
    ("jobs:\n  - autoscan: {scans: 4, resoluton: 0.2}\n",
     ":2 jobs[0].autoscan.resoluton: recon autoscan has no option"),
    ("jobs:\n  - autoscan: {resolution: 5}\n", ":2 jobs[0].autoscan.resolution: Invalid value for '--resolution'"),
    ("jobs:\n  - capture: {}\n    expect:\n      min_coverage_pct: 5\n",
     ":4 jobs[0].expect.min_coverage_pct: a capture job does not measure this"),
    ("jobs:\n  - run: nothere.xml\n", ":2 jobs[0].run: script nothere.xml not found"),
    ("jobs:\n  - run: smoke.xml\n    options: {out: x}\n", ":3 jobs[0].options.out: option 'out' cannot be set"),
    ("jobs:\n  - run: smoke.xml\n    expect: {max_std_mm: -1}\n",
     ":3: jobs[0].expect.max_std_mm = -1 mm is outside [0, 1000] mm"),
    ("jobs:\n  - run: smoke.xml\n    expect: {max_std: 1}\n", ":3: jobs[0].expect.max_std is not a known key"),
    ("jobs:\n  - run: smoke.xml\n    matrix: {foo: [a]}\n", ":3 jobs[0].matrix.foo: 'foo' is no option of recon run"),
    ("jobs:\n  - run: smoke.xml\n  - run: smoke.xml\n", "job name 'smoke' is used twice"),
    ("jobs:\n  - run: smoke.xml\n    autoscan: {}\n", "a job names exactly one command"),
    ("jobs:\n  - run: smoke.xml\n    timeout_s: 0\n", ":3: jobs[0].timeout_s = 0 s is outside [1, 604800] s"),
    ("jobs: [\n", "not valid YAML"),
    ("jobs: []\n", ":1: jobs has 0 items, 1 to 10000 expected"),
    ("jobz: []\n", ":1: jobz is not a known key"),
    ("jobs:\n  - run: smoke.xml\n    timeout_s: 1.0e-300\n",
     ":3: jobs[0].timeout_s = 1e-300 s is outside [1, 604800] s"),
    ("jobs:\n  - run: smoke.xml\n    env: {PYTHONPATH: .}\n",
     ":3 jobs[0].env.PYTHONPATH: a job may not set PYTHONPATH"),
    ("jobs:\n  - run: smoke.xml\n    env: {LD_PRELOAD: ./x.so}\n", "a job may not set LD_PRELOAD"),
    ("defaults:\n  env: {PATH: .}\njobs:\n  - run: smoke.xml\n", ":2 defaults.env.PATH: a job may not set PATH"),
    ("jobs:\n  - run: smoke.xml\n    name: j{a}{b}{c}\n    matrix: {a: [%s], b: [%s], c: [%s]}\n"
     % ((",".join(map(str, range(1000))),) * 3), ":4 jobs[0].matrix: expands to 1,000,000,000 combinations"),
])
def test_batch_file_errors_are_one_line_with_file_line_and_key(tmp_path, text, needle):
    path = write(tmp_path, text)
    with pytest.raises(ReconError) as info:
        load_batch_file(path, COMMANDS)
    message = info.value.one_line()
    assert needle in message and str(path) in message and "\n" not in message


class _TwoOptions:
    """Commands with one number option and one switch; the number must be below 10."""

    def __init__(self) -> None:
        self.checked: list[tuple[JobKind, tuple[str, ...]]] = []

    def options(self, kind):
        return {"level": CommandOption("level", "--level", None, False),
                "fast": CommandOption("fast", "--fast", "--slow", True)}

    def check(self, kind, args):
        self.checked.append((kind, args))
        if "--level" in args and float(args[args.index("--level") + 1]) >= 10:
            return "Invalid value for '--level': must be below 10"
        return None


def test_a_batch_checks_its_jobs_against_the_commands_it_is_given(tmp_path):
    commands = _TwoOptions()
    spec = load_batch_file(write(tmp_path, "jobs:\n  - autoscan: {level: 3, fast: false}\n"
                                           "  - run: smoke.xml\n    options: {level: 4}\n"), commands)
    assert spec.jobs[0].args == ("--level", "3", "--slow") and spec.jobs[1].args[1:] == ("--level", "4")
    assert (JobKind.RUN, ("SCRIPT.xml", "--level", "4")) in commands.checked  # a script job's argument first
    with pytest.raises(ReconError) as info:
        load_batch_file(write(tmp_path, "jobs:\n  - autoscan: {level: 12}\n", "bad.yaml"), commands)
    assert info.value.one_line().startswith(f"{tmp_path / 'bad.yaml'}:2 jobs[0].autoscan.level: Invalid value")
    with pytest.raises(ReconError) as info:
        load_batch_file(write(tmp_path, "jobs:\n  - autoscan: {resolution: 0.2}\n", "typo.yaml"), commands)
    assert "recon autoscan has no option 'resolution'" in info.value.one_line()
    assert "choose one of: level, fast" in info.value.one_line()


def test_scripts_and_globs_on_the_command_line(tmp_path, capsys):
    code = main(["batch", str(ROOT / "scripts_xml" / "smoke*.xml"), str(ROOT / "scripts_xml" / "eq_4_1_drill.xml"),
                 "--list", "--timeout", "60"])
    out = capsys.readouterr().out
    assert code == 0
    assert "smoke: recon run" in out and "eq_4_1_drill: recon run" in out and "timeout 60 s" in out
    assert main(["batch", str(tmp_path / "none*.xml"), "--list"]) == 1
    assert "matches no file" in capsys.readouterr().err


# ----------------------------------------------------------------------------- verdicts
def test_checks_name_the_measured_value_and_the_bound():
    checks = judge(Expectations(min_coverage_pct=60, max_std_mm=0.3, max_planning_failures=0),
                   Measured(coverage=39.8, std=0.1, planning_failures=2))
    text = [c.describe() for c in checks]
    assert text == ["coverage 39.8 % < 60 %", "std 0.1 mm <= 0.3 mm", "planning failures 2 > 0"]
    assert [c.passed for c in checks] == [False, True, False]
    (missing,) = judge(Expectations(max_pose_error_mm=1), Measured())
    assert not missing.passed and missing.describe() == "pose error not measured (expected <= 1 mm)"


def _job(tmp_path, retries=1, **kw) -> JobSpec:
    return JobSpec("j", JobKind.VALIDATE, (str(ROOT / "scripts_xml" / "smoke.xml"),), tmp_path, 60.0, retries, **kw)


@pytest.mark.parametrize("codes, attempts, status", [
    ([-9, 0], 2, JobStatus.PASSED),  # killed (OOM killer): retried, then it passes
    ([143, -11], 2, JobStatus.ERROR),  # preempted, then a crash: retries used up
    ([3], 1, JobStatus.FAILED),  # the job's own failure: not retried
    ([1], 1, JobStatus.FAILED),
])
def test_only_infrastructure_failures_are_retried(tmp_path, monkeypatch, codes, attempts, status):
    calls = []

    def fake(job, out, log, number):
        code = codes[len(calls)]
        calls.append(code)
        return Attempt(code, 0.5, infrastructure=job_module._classify(code, log))

    monkeypatch.setattr(job_module, "_attempt", fake)
    result = run_job(_job(tmp_path), tmp_path / "job")
    assert len(result.attempts) == attempts == len(calls)
    assert result.status is status


def test_timeouts_are_not_retried(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(job_module, "_attempt", lambda *a: calls.append(1) or Attempt(-15, 60.0, timed_out=True))
    result = run_job(_job(tmp_path, retries=3), tmp_path / "job")
    assert len(calls) == 1 and result.status is JobStatus.TIMEOUT and "timed out after 60 s" in result.reason


def test_exit_codes_that_say_nothing_about_the_job(tmp_path):
    log = tmp_path / "log.txt"
    log.write_text("Traceback ...\nMemoryError\n")
    assert "SIGKILL" in job_module._classify(-9, log)
    assert "SIGKILL" in job_module._classify(137, log)
    assert "SIGTERM" in job_module._classify(143, log)
    assert job_module._classify(1, log) == "out of memory"
    log.write_text("error: bad script\n")
    assert job_module._classify(1, log) is None and job_module._classify(3, log) is None


def test_junit_and_markdown_of_results(tmp_path):
    def result(name, status, reason="", checks=()):
        return JobResult(name, "run", status, reason, 0, 1.5, (Attempt(0, 1.5),), Measured(coverage=42.0), checks,
                         str(tmp_path / name), ("recon", "run", "x.xml"), "log <&> line\x01", "host", 0.0)

    checks = judge(Expectations(min_coverage_pct=60), Measured(coverage=42.0))
    batch = BatchResult("b", tmp_path, (result("ok", JobStatus.PASSED),
                                        result("low", JobStatus.FAILED, checks[0].describe(), checks),
                                        result("slow", JobStatus.TIMEOUT, "timed out after 1 s"),
                                        result("lost", JobStatus.ERROR, "killed by SIGKILL (2 attempts)")),
                        ("later",), 10.0, "local pool, 1 worker", 1, 0.0, interrupted="SIGINT")
    root = ET.fromstring(ET.tostring(junit_xml(batch).getroot()))
    suite = root.find("testsuite")
    counts = tuple(suite.get(k) for k in ("tests", "failures", "errors", "skipped"))
    assert counts == ("5", "2", "1", "1")
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert cases["low"].find("failure").get("message") == "coverage 42 % < 60 %"
    assert cases["slow"].find("failure").get("type") == "timeout"
    assert cases["lost"].find("error") is not None and cases["later"].find("skipped") is not None
    assert "log <&> line?" in cases["ok"].find("system-out").text
    md = markdown(batch)
    assert "| low | ❌ failed | 1.5 s | coverage 42.00 % | coverage 42 % < 60 % |" in md


def test_dask_missing_is_one_line_with_the_install_hint(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    path = write(tmp_path, "jobs:\n  - validate: smoke.xml\n")
    code = main(["batch", str(path), "--cluster", "local", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1 and "pip install 'recon-scan[cluster]'" in err and len(err.strip().splitlines()) == 1
    code = main(["batch", str(path), "--cluster", "local", "--scheduler", "tcp://x:1", "--out", str(tmp_path / "o2")])
    assert code == 1 and "exclude each other" in capsys.readouterr().err


# ----------------------------------------------------------------------------- end to end
def _check_four(out: Path) -> dict[str, ET.Element]:
    root = ET.parse(out / "junit.xml").getroot()
    suite = root.find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("4", "2", "0")
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    failures = {name: c.find("failure") for name, c in cases.items() if c.find("failure") is not None}
    assert set(failures) == {"impossible", "slow"}
    assert failures["impossible"].get("type") == "expectation"
    assert "wall time" in failures["impossible"].get("message") and "> 0.001 s" in failures["impossible"].get("message")
    assert failures["slow"].get("type") == "timeout" and "timed out after 1 s" in failures["slow"].get("message")
    assert "$ recon capture" in cases["slow"].find("system-out").text  # the log tail
    # the other jobs' outputs are complete
    report = json.loads((out / "jobs" / "smoke" / "output" / "run_report.json").read_text())
    assert report["status"] == "done" and report["scans"] == 3
    assert (out / "jobs" / "smoke" / "output" / "reconstruction" / "mesh.ply").is_file()
    scan = out / "jobs" / "capture" / "output" / "scan_0000"
    assert (scan / "scan.json").is_file() and (scan / "depth.png").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"passed": 2, "failed": 1, "timeout": 1, "error": 0, "not_run": 0}
    assert summary["exit_code"] == 3
    index = (out / "index.html").read_text()  # links the pages of the jobs that wrote one
    assert 'href="jobs/smoke/output/report.html"' in index and 'href="jobs/capture/output/report.html"' in index
    assert (out / "jobs" / "smoke" / "output" / "report.html").is_file()
    return failures


def test_four_jobs_on_the_local_pool(tmp_path, capsys):
    path = write(tmp_path, FOUR)
    code = main(["batch", str(path), "--out", str(tmp_path / "out"), "--workers", "2",
                 "--junit", str(tmp_path / "ci" / "junit.xml")])
    out = capsys.readouterr().out
    assert code == 3, out
    _check_four(tmp_path / "out")
    assert (tmp_path / "ci" / "junit.xml").read_text() == (tmp_path / "out" / "junit.xml").read_text()
    assert "2 passed, 1 failed, 1 timed out" in out


def test_four_jobs_on_a_dask_local_cluster(tmp_path, capsys):
    distributed = pytest.importorskip("distributed",
                                      reason="Dask is an optional extra: pip install 'recon-scan[cluster]'")
    path = write(tmp_path, FOUR)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        code = main(["batch", str(path), "--out", str(tmp_path / "out"), "--scheduler", cluster.scheduler_address])
    out = capsys.readouterr().out
    assert code == 3, out
    _check_four(tmp_path / "out")
    assert "Dask scheduler tcp://" in out
    hosts = {r["host"] for r in json.loads((tmp_path / "out" / "summary.json").read_text())["jobs"]}
    assert hosts and "" not in hosts  # results came back from the workers


def _ours(marker: str) -> list[int]:
    """Pids of processes whose command line names ``marker`` (the test's folder)."""
    pids = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if marker in (p / "cmdline").read_bytes().decode(errors="replace"):
                    pids.append(int(p.name))
            except OSError:
                pass
    return [p for p in pids if p != os.getpid()]


def test_a_killed_batch_resumes_without_redoing_finished_jobs(tmp_path):
    path = write(tmp_path, """\
jobs:
  - {name: first, validate: smoke.xml}
  - {name: second, autoscan: {scans: 2, resolution: 0.1, pictures: false}}
  - {name: third, validate: smoke.xml}
""")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "recon_cli", "batch", str(path), "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    first = out / "jobs" / "first" / "result.json"
    deadline = time.monotonic() + 120
    while not first.is_file() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert first.is_file(), "the first job did not finish"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    before = first.read_text(), first.stat().st_mtime_ns, (out / "jobs" / "first" / "log.txt").stat().st_mtime_ns
    # the job the batch was running ends with it (SIGTERM from the kernel)
    deadline = time.monotonic() + 30
    while _ours(str(out)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _ours(str(out)), "a job outlived its killed batch"
    report = out / "jobs" / "second" / "output" / "autoscan_report.json"  # stopped, not finished
    assert not report.is_file() or json.loads(report.read_text())["interrupted"]
    assert not (out / "jobs" / "third" / "result.json").exists()

    code = main(["batch", str(path), "--out", str(out), "--resume"])
    assert code == 0
    after = first.read_text(), first.stat().st_mtime_ns, (out / "jobs" / "first" / "log.txt").stat().st_mtime_ns
    assert after == before  # not run again
    summary = json.loads((out / "summary.json").read_text())
    assert {j["name"]: j["resumed"] for j in summary["jobs"]} == {"first": True, "second": False, "third": False}
    assert json.loads(report.read_text())["scans"] == 2
    # without --resume a used folder is refused; a changed job is run again on --resume
    assert main(["batch", str(path), "--out", str(out)]) == 1
    path.write_text(path.read_text().replace("{name: third, validate: smoke.xml}",
                                             "{name: third, validate: eq_4_1_drill.xml}"))
    assert main(["batch", str(path), "--out", str(out), "--resume"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {j["name"]: j["resumed"] for j in summary["jobs"]} == {"first": True, "second": True, "third": False}


def test_sigterm_stops_the_batch_and_its_jobs(tmp_path):
    path = write(tmp_path, """\
jobs:
  - {name: first, validate: smoke.xml}
  - {name: second, autoscan: {scans: 2, resolution: 0.1, pictures: false}}
  - {name: third, validate: smoke.xml}
""")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "recon_cli", "batch", str(path), "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 120
    while not (out / "jobs" / "first" / "result.json").is_file() and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    text, _ = proc.communicate(timeout=60)
    assert proc.returncode == 143, text
    assert "interrupted by SIGTERM" in text and not _ours(str(out))
    suite = ET.parse(out / "junit.xml").getroot().find("testsuite")
    assert suite.get("tests") == "3" and int(suite.get("skipped")) >= 1


def test_overrides_replace_the_defaults_not_a_jobs_own(tmp_path):
    path = write(tmp_path, "defaults: {timeout_s: 100}\njobs:\n  - {name: a, validate: smoke.xml}\n"
                           "  - {name: b, validate: smoke.xml, timeout_s: 5}\n")
    spec = load_batch([str(path)], COMMANDS, Overrides(timeout_s=50, retries=0))
    assert [(j.timeout_s, j.retries) for j in spec.jobs] == [(50, 0), (5, 0)]


def test_the_example_of_the_docs_and_the_shipped_batches_load(tmp_path):
    import re

    text = (ROOT / "docs" / "batch.md").read_text()
    example = re.search(r"```yaml\n(.*?)```", text, re.S).group(1)
    spec = load_batch_file(write(tmp_path, example), COMMANDS)
    names = [j.name for j in spec.jobs]
    assert len(names) == 4 + 11 + 2 and "eq41-thesis-seed1" in names and "auto-mug-2" not in names
    assert dict(spec.jobs[0].env) == {"OMP_NUM_THREADS": "1"}
    shipped = load_batch_file(ROOT / "batches" / "shipped.yaml", COMMANDS)
    assert len(shipped.jobs) == 12
    assert {j.kind for j in load_batch_file(ROOT / "batches" / "ci.yaml", COMMANDS).jobs} == {
        JobKind.RUN, JobKind.VALIDATE, JobKind.AUTOSCAN}
