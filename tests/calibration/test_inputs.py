"""What the calibrate commands read: a --board-spec the dictionary can fill, within sane sizes;
only files inside the image folder (no pattern out of it, no link leading out of it); and no
message ever shows what a file holds."""

from __future__ import annotations

import os
import time

import cv2
import numpy as np
import pytest

from recon_cli.calibration.intrinsics import SkippedImage
from recon_cli.cli import main
from recon_cli.errors import FileError, InputError
from recon_cli.workflows.calibrate import board_images, check_pattern

SECRET = b"root:x:0:0:root:/root:/bin/bash\n"


def _run(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out + err


def _png(path, value: int = 128):
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.full((16, 16, 3), value, np.uint8))
    return path


# --------------------------------------------------------------------- --board-spec
@pytest.mark.parametrize(("board", "message"), [
    ("99999,99999,0.04,0.02,DICT_6X6_250", "99999 x 99999 squares is outside 2 ... 100 per side"),
    ("2000,2000,0.04,0.02,DICT_6X6_250", "outside 2 ... 100 per side"),
    ("23,23,0.04,0.02,DICT_6X6_250", "23 x 23 squares hold 264 markers, more than the 250 of DICT_6X6_250"),
    ("45,45,0.01,0.005,DICT_4X4_1000", "hold 1012 markers, more than the 1000 of DICT_4X4_1000"),
    ("1,7,0.04,0.02,DICT_6X6_250", "1 x 7 squares is outside 2 ... 100 per side"),
    ("5,101,0.04,0.02,DICT_6X6_1000", "outside 2 ... 100 per side"),
    ("5,7,2,0.02,DICT_6X6_250", "is outside (0, 1] m"),
    ("5,7,0.04,0,DICT_6X6_250", "is outside (0, 1] m"),
    ("5,7,nan,0.02,DICT_6X6_250", "is outside (0, 1] m"),
    ("5,7,0.04,0.04,DICT_6X6_250", "the marker (0.04 m) must be smaller than the square (0.04 m)"),
    ("5,7,0.04,0.02,DICT_6X6_250,x", "is not one of charuco:COLSxROWS"),
])
@pytest.mark.parametrize("command", ["intrinsics", "handeye"])
def test_a_board_beyond_its_dictionary_or_sane_sizes_is_refused_at_once(tmp_path, capsys, board, message, command):
    source = ("--scan-store", tmp_path) if command == "handeye" else (tmp_path,)
    t0 = time.perf_counter()
    code, out = _run(capsys, "calibrate", command, *source, "--board-spec", board, "--out", tmp_path / "o")
    assert code == 1 and message in out and len(out.strip().splitlines()) == 1, out
    assert time.perf_counter() - t0 < 5.0
    assert not (tmp_path / "o").exists()


def test_boards_the_dictionary_fills_are_taken(tmp_path, capsys):
    from recon_cli.cli.calibrate import parse_board

    assert parse_board("5,7,0.04,0.02,DICT_6X6_250").squares_x == 5
    assert parse_board("22,22,0.04,0.02,DICT_6X6_250").squares_y == 22  # 242 markers of 250
    assert parse_board("2,100,0.01,0.005,DICT_4X4_1000").squares_y == 100


# --------------------------------------------------------------------- --pattern
@pytest.mark.parametrize(("pattern", "message"), [
    ("../small/*/*.png", "--pattern '../small/*/*.png' leaves the image folder"),
    ("sub/../../small/*.png", "leaves the image folder"),
    ("/etc/host*", "--pattern '/etc/host*' leaves the image folder"),
    ("~/x*.png", "leaves the image folder"),
    ("a**", "is not a glob of file names"),
    (".", "is not a glob of file names"),
    ("", "leaves the image folder"),
])
def test_a_pattern_stays_in_the_image_folder(tmp_path, capsys, pattern, message):
    folder = tmp_path / "images"
    _png(folder / "a.png")
    _png(tmp_path / "small" / "x" / "b.png")
    code, out = _run(capsys, "calibrate", "intrinsics", folder, "--pattern", pattern, "--out", tmp_path / "o")
    assert code == 1 and message in out and len(out.strip().splitlines()) == 1, out
    assert not (tmp_path / "o").exists()
    if pattern and pattern not in ("a**", "."):
        with pytest.raises(InputError, match="leaves the image folder"):
            check_pattern(pattern)


def test_patterns_inside_the_folder_are_taken(tmp_path):
    folder = tmp_path / "images"
    _png(folder / "a.png")
    _png(folder / "left" / "b.png")
    assert [n for n, _ in board_images(folder, "left/*.png")] == ["left/b.png"]
    assert [n for n, _ in board_images(folder, "**/*.png")] == ["a.png", "left/b.png"]
    assert [n for n, _ in board_images(folder)] == ["a.png"]


# --------------------------------------------------------------------- links and contents
def test_links_leading_out_of_the_folder_are_skipped_with_the_reason(tmp_path):
    folder = tmp_path / "images"
    _png(folder / "a.png")
    secret = tmp_path / "passwd"
    secret.write_bytes(SECRET)
    os.symlink(secret, folder / "d.png")
    os.symlink(_png(tmp_path / "elsewhere" / "e.png"), folder / "e.png")
    os.symlink(tmp_path / "elsewhere", folder / "sub")
    os.symlink(folder / "a.png", folder / "inside.png")  # a link that stays inside is read
    os.symlink(tmp_path / "gone.png", folder / "dangling.png")
    skipped: list[SkippedImage] = []
    images = board_images(folder, "*", skipped)
    assert [n for n, _ in images] == ["a.png", "inside.png"]
    assert [(s.name, s.reason) for s in skipped] == [("d.png", "not read: a link leading out of the folder"),
                                                     ("e.png", "not read: a link leading out of the folder")]
    skipped = []
    with pytest.raises(FileError, match=r"holds no images matching 'sub/\*.png' inside it \(1 is a link leading "
                                        r"out of it\)"):
        board_images(folder, "sub/*.png", skipped)
    assert [s.name for s in skipped] == ["sub/e.png"]


def test_the_command_names_a_link_out_and_never_shows_a_file(tmp_path, capsys):
    folder = tmp_path / "images"
    folder.mkdir()
    secret = tmp_path / "passwd"
    secret.write_bytes(SECRET)
    os.symlink(secret, folder / "d.png")
    code, out = _run(capsys, "calibrate", "intrinsics", folder, "--out", tmp_path / "o")
    assert code == 1 and "link leading out of it" in out and len(out.strip().splitlines()) == 1, out
    assert "root:x" not in out
    # the other images are used; the link is named among the images that were not
    _png(folder / "a.png")
    code, out = _run(capsys, "calibrate", "intrinsics", folder, "--out", tmp_path / "o2")
    assert code == 1 and "d.png: not read: a link leading out of the folder" in out, out
    assert "a.png: board not found (0 corners" in out and "root:x" not in out


def test_a_file_that_is_no_image_is_named_not_shown(tmp_path, capsys):
    folder = tmp_path / "images"
    folder.mkdir()
    (folder / "d.png").write_bytes(SECRET)
    code, out = _run(capsys, "calibrate", "intrinsics", folder, "--out", tmp_path / "o")
    assert code == 1 and "cannot be read as an image (it is not in an image format recon knows)" in out, out
    assert "root:x" not in out and "b'" not in out and len(out.strip().splitlines()) == 1
