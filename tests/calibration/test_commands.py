"""The calibrate commands: a user's mistake is one line, exit code 1 (2 for a value an option does not take)."""

from __future__ import annotations

import pytest

from recon_cli.cli import main


def _run(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out + err


def test_help_lists_both_commands(capsys):
    code, out = _run(capsys, "calibrate", "--help")
    assert code == 0 and "handeye" in out and "intrinsics" in out
    code, out = _run(capsys, "calibrate", "handeye", "--help")
    assert code == 0 and "calibrateRobotWorldHandEye" in out and "--station" in out


@pytest.mark.parametrize(("argv", "code", "message"), [
    (("handeye", "--scan-store", "{tmp}"), 1, "holds no scan_NNNN folders"),
    (("handeye", "--method", "kabsch", "--scan-store", "{tmp}"), 2,
     "Invalid value for '--method': 'kabsch' is not one of 'tsai', 'park'"),
    (("handeye", "--scan-store", "{tmp}/none"), 1, "does not exist"),
    (("intrinsics", "{tmp}", "--board-spec", "5,7,0.04,0.02,DICT_9X9"), 1, "unknown ArUco dictionary 'DICT_9X9'"),
    (("intrinsics", "{tmp}", "--board-spec", "5,7,0.04"), 1,
     "--board-spec '5,7,0.04': is not one of charuco:COLSxROWS,SQUARE,MARKER,DICTIONARY"),
    (("intrinsics", "{tmp}"), 1, "holds no images"),
    (("intrinsics", "{tmp}", "--model", "fisheye"), 2, "Invalid value for '--model': 'fisheye' is not one of "),
])
def test_command_errors_are_one_line(tmp_path, capsys, argv, code, message):
    got, out = _run(capsys, "calibrate", *[a.format(tmp=tmp_path) for a in argv], "--out", tmp_path / "o")
    assert got == code and message in out, out
    assert len(out.strip().splitlines()) == 1
