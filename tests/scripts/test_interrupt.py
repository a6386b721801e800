"""`recon run` stopped from outside: Ctrl-C (SIGINT), SIGTERM and SIGKILL keep every
completed scan; after SIGINT/SIGTERM the report says that the run was interrupted, where and
what was kept, and the exit code says so too."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from recon_cli.reconstruction.pipeline import RegisterOptions, run_register
from recon_cli.reconstruction.scan_store import ScanStore, read_scan

SCRIPT = """<?xml version="1.0"?>
<recon name="long ring">
  <cell resolution="0.2"/>
  <object name="bottle"/>
  <box/>
  <ring focus="0 0 0.8" radius="0.6" theta="60" count="30"/>
  <register/>
</recon>
"""


def _start(tmp_path):
    script = tmp_path / "ring.xml"
    script.write_text(SCRIPT)
    out = tmp_path / "run"
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    proc = subprocess.Popen([sys.executable, "-m", "recon_cli", "run", str(script), "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            # signals as in a terminal: a suite started in the background runs with
                            # SIGINT ignored, which children would inherit
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 240
    while time.time() < deadline and len(ScanStore(out / "scans")) < 2 and proc.poll() is None:
        time.sleep(0.1)
    return proc, out


def _registers(out, tmp_path, n):
    scans = ScanStore(out / "scans")
    for i in scans.indices():  # every scan folder is complete
        read_scan(out / "scans" / f"scan_{i:04d}")
    result = run_register(out / "scans", tmp_path / "rec", RegisterOptions(mesh=False, local=False))
    assert len(result.used) == n


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_stop_signal_keeps_scans_and_says_why(tmp_path, sig, code):
    proc, out = _start(tmp_path)
    proc.send_signal(sig)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == code, (stdout, stderr)
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("interrupted: interrupted by " + sig.name), stderr
    assert "Traceback" not in stdout + stderr
    n = len(ScanStore(out / "scans"))
    assert 2 <= n < 30 and f"{n} completed scan(s) kept" in lines[0]
    report = json.loads((out / "run_report.json").read_text())
    assert report["status"] == "interrupted" and report["exit_code"] == code
    assert report["aborted"].startswith(f"interrupted by {sig.name}")
    assert report["interrupted"]["signal"] == sig.name and report["interrupted"]["scans_kept"] == n
    assert report["interrupted"]["command"].startswith("ring.xml:")
    assert any(c["status"] == "interrupted" for c in report["commands"])
    assert "status interrupted" in (out / "report.html").read_text()
    _registers(out, tmp_path, n)


def test_sigkill_keeps_completed_scans(tmp_path):
    proc, out = _start(tmp_path)
    time.sleep(0.7)  # somewhere in a move or a scan
    proc.kill()
    proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL
    n = len(ScanStore(out / "scans"))
    assert n >= 2
    _registers(out, tmp_path, n)
