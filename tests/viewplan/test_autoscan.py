"""`recon autoscan` end to end (small images, few scans), both cells, the CLI, Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from recon_cli.cli import main
from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig, ViewPlanConfig
from recon_cli.reconstruction.pipeline import RegisterOptions, run_register
from recon_cli.reconstruction.scan_store import ScanStore
from recon_cli.robot.description import CellConfig, CellKind
from recon_cli.workflows.autoscan import Autoscan, AutoscanOptions


@pytest.mark.parametrize("kind", [CellKind.GANTRY, CellKind.CEILING])
def test_autoscan_small(tmp_path, kind):
    out = tmp_path / kind.value
    config = DEFAULTS.replace(cell=CellConfig(kind=kind), scene=SceneConfig("bottle"), seed=1,
                              sensor=SensorConfig(resolution=0.25), viewplan=ViewPlanConfig(n=5))
    r = Autoscan(AutoscanOptions(out, config, mesh=False)).run()
    assert r.scans == 5 and len(ScanStore(out)) == 5
    statuses = [v.status for v in r.views]
    assert statuses.count("completed") == 5
    assert r.coverage > 0.6 and abs(r.accuracy.mean_mm) < 1.0
    assert len(r.pictures) == 4 and all(p.exists() for p in r.pictures)
    report = json.loads(r.report.read_text())
    assert report["scans"] == 5 and report["planning_requests"] >= 4
    assert r.page == out / "report.html" and "iteration_04.png" in r.page.read_text()


def test_autoscan_cli_errors(tmp_path, capsys):
    assert main(["autoscan", "--n", "1", "--out", str(tmp_path / "a")]) != 0
    assert main(["autoscan", "--object", "teapot", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "teapot" in err and "Traceback" not in err


def test_interrupted_autoscan_keeps_its_scans(tmp_path):
    out = tmp_path / "run"
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    proc = subprocess.Popen([sys.executable, "-m", "recon_cli", "autoscan", "--n", "30", "--resolution", "0.2",
                             "--no-pictures", "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            # Ctrl-C as in a terminal: a test suite started in the background
                            # (`cmd &` in a script) runs with SIGINT ignored, which children inherit
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 240
    while time.time() < deadline and len(ScanStore(out)) < 3:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, (stdout, stderr)
    scans = len(ScanStore(out))
    assert 3 <= scans < 30
    assert "interrupted" in stdout + stderr
    assert json.loads((out / "autoscan_report.json").read_text())["interrupted"]
    assert "status interrupted" in (out / "report.html").read_text()
    result = run_register(out, tmp_path / "rec", RegisterOptions(mesh=False))
    assert len(result.used) == scans
