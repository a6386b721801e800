"""``recon bench inputs``: the campaign makes its cases from recon's own files, runs each in
its own process and judges it from outside (a case that runs code or echoes a secret fails)."""

from __future__ import annotations

import json

import numpy as np

from recon_cli.bench import inputs as B


def test_a_small_campaign_refuses_or_accepts_every_case(tmp_path):
    """Behaviour, not speed: the time bound is wide (the 20 s bound is the campaign's, on a
    machine that runs nothing else)."""
    result = B.run_campaign(tmp_path, 2, 0, 1, ("cell description", "mesh"), seconds_bound=600.0)
    data = json.loads((tmp_path / "bench_inputs.json").read_text())
    assert set(data["counts"]) == {"cell description", "mesh"}
    assert all(c.cases == 2 and c.failed == 0 for c in result.counts.values()), result.failures
    assert not (tmp_path / "cases").exists()


def test_a_case_that_runs_code_or_echoes_a_secret_fails(tmp_path):
    """The judge: a command that writes the marker, or prints a secret, is a failure."""
    root = tmp_path / "r"
    B._secrets(root)
    B._OUTSIDE_LISTING[str(root)] = B._listing(root / "outside")
    folder = root / "case"
    folder.mkdir()
    script = folder / "s.xml"
    script.write_text("x")
    # `recon validate` of a missing file is a refusal; pointing it at the secret echoes nothing
    ok = B._run_one(B.Case("t", 0, folder, ("validate", str(folder / "missing.xml"))), root, 600.0)
    assert ok.verdict == "refused" and ok.reason == ""
    (root / "outside" / "new.txt").write_text("written")
    wrote = B._run_one(B.Case("t", 1, folder, ("validate", str(folder / "missing.xml"))), root, 600.0)
    assert wrote.verdict == "fail" and wrote.reason == "wrote outside its folder"


def test_mutations_are_seeded():
    a = B._mutate("abcdefghij" * 5, B.YAML_PIECES, np.random.default_rng(3))
    b = B._mutate("abcdefghij" * 5, B.YAML_PIECES, np.random.default_rng(3))
    assert a == b and a != "abcdefghij" * 5


def test_a_case_is_charged_its_own_memory_not_its_parents(tmp_path):
    """A child started by vfork and exec inherits its parent's high-water mark in ru_maxrss:
    run from a process holding 1.2 GB, a refusal that takes 100 MB must still be judged by
    its own peak."""
    root = tmp_path / "r"
    B._secrets(root)
    B._OUTSIDE_LISTING[str(root)] = B._listing(root / "outside")
    folder = root / "case"
    folder.mkdir()
    held = bytearray(1_200_000_000)
    held[::4096] = b"x" * len(held[::4096])  # resident, not only reserved
    outcome = B._run_one(B.Case("t", 0, folder, ("validate", str(folder / "missing.xml"))), root, 600.0)
    del held
    assert outcome.verdict == "refused" and outcome.reason == "", outcome
    assert 10e6 < outcome.peak_bytes < 500e6, outcome.peak_bytes
