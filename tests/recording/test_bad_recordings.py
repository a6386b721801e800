"""``recon view --summary`` of a recording.rrd that rerun cannot read (random bytes, cut
short, damaged) or that is no regular file: one line naming the file, no traceback and
none of rerun's warnings or log lines."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import pytest

pytest.importorskip("rerun", reason="recordings need the viz extra (pip install 'recon-scan[viz]')")

from recon_cli.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> bytes:
    """The bytes of a small real recording: a log line and a mesh."""
    import open3d as o3d

    from recon_cli.recording import open_recorder

    folder = tmp_path_factory.mktemp("rec")
    with open_recorder(folder, "tiny") as rec:
        rec.note("start")
        rec.mesh("reconstruction/mesh", o3d.geometry.TriangleMesh.create_sphere(0.05, 40))
    return (folder / "recording.rrd").read_bytes()


def _flipped(data: bytes) -> bytes:
    damaged = bytearray(data)
    for k in range(12, 52):  # the header of the first message
        damaged[k] ^= 0xFF
    return bytes(damaged)


def _summary(capfd, target: Path) -> tuple[int, str, str]:
    capfd.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(["view", str(target), "--summary"])
    out, err = capfd.readouterr()
    assert not caught, [str(w.message) for w in caught]
    return code, out, err


def test_a_small_recording_reads(tmp_path, capfd, recording):
    (tmp_path / "recording.rrd").write_bytes(recording)
    code, out, err = _summary(capfd, tmp_path)
    assert code == 0 and err == "" and out.startswith("recording.rrd: 0 scans") and "mesh" in out, (out, err)


@pytest.mark.parametrize("damage, reason", [
    (lambda data: os.urandom(20_000), 'Not an RRD file: expected FourCC header "RRF2"'),
    (lambda data: data[: len(data) * 2 // 3], "exceeds file size"),
    (_flipped, "trailing bytes in rrd stream"),
], ids=["random bytes", "truncated", "flipped bytes"])
def test_a_damaged_recording_is_one_line(tmp_path, capfd, recording, damage, reason):
    path = tmp_path / "recording.rrd"
    path.write_bytes(damage(recording))
    code, out, err = _summary(capfd, tmp_path)
    assert code == 1 and out == "" and err.count("\n") == 1, (out, err)
    assert err.startswith(f"error: {path} is not a readable rerun recording (") and reason in err, err
    assert "Traceback" not in err and "Warning" not in err and "ERROR" not in err


def test_a_recording_that_is_not_a_regular_file(tmp_path, capfd):
    os.mkfifo(tmp_path / "recording.rrd")  # never opened: reading a FIFO would block
    for target in (tmp_path, tmp_path / "recording.rrd"):
        code, out, err = _summary(capfd, target)
        assert code == 1 and err == f"error: {tmp_path / 'recording.rrd'} is not a regular file; give the " \
                                    "recording.rrd a run wrote with --record (recon run, autoscan, capture, " \
                                    "register)\n", err
