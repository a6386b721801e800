"""Every image read through the one reader: hostile and careless files (headers claiming
gigapixels, truncated or corrupt data, the wrong kind of depth image) are refused with one
line before anything large is decoded, within bounded memory and time, through the
reader and through the CLI; fuzzed files never give anything but an image or that line."""

from __future__ import annotations

import os
import shutil
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.errors import FileError, MetadataError
from recon_cli.inputs import images
from recon_cli.inputs.images import (
    MAX_DECODED_BYTES,
    MAX_IMAGE_FILE_BYTES,
    MAX_IMAGE_PIXELS,
    MAX_JPEG_SCANS,
    MAX_JPEG_SEGMENTS,
    read_color,
    read_depth,
    read_image,
)

from .measure import run_cli, run_python

ROOT = Path(__file__).resolve().parents[2]
RNG = np.random.default_rng(7)
COLOUR = (RNG.random((12, 16, 3)) * 255).astype(np.uint8)
DEPTH = (RNG.random((12, 16)) * 60000).astype(np.uint16)


def _encode(ext: str, image: np.ndarray, params=()) -> bytes:
    ok, buf = cv2.imencode(ext, image, list(params))
    assert ok
    return buf.tobytes()


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_claiming(width: int, height: int, depth: int = 8, colour: int = 2) -> bytes:
    """A valid PNG structure whose IHDR claims ``width`` x ``height``, with a few bytes of data."""
    ihdr = struct.pack(">IIBBBBB", width, height, depth, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(b"\0" * 64))
            + _chunk(b"IEND", b""))


def jpeg_claiming(width: int, height: int) -> bytes:
    data = bytearray(_encode(".jpg", COLOUR))
    sof = data.find(b"\xff\xc0")
    data[sof + 5:sof + 9] = struct.pack(">HH", height, width)
    return bytes(data)


def jpeg_of_scans(n: int) -> bytes:
    """A JPEG's header followed by ``n`` (empty) scans and its end marker."""
    data = _encode(".jpg", COLOUR)
    sos = data.find(b"\xff\xda")
    length = struct.unpack(">H", data[sos + 2:sos + 4])[0]
    scan = data[sos:sos + 2 + length] + b"\x00"
    return data[:sos] + scan * n + b"\xff\xd9"


def jpeg_stuffed(megabytes: int, end: bool = True) -> bytes:
    """A small JPEG whose scan is followed by ``megabytes`` of stuffed 0xFF 0x00 pairs."""
    data = _encode(".jpg", COLOUR)
    return data[:-2] + b"\xff\x00" * (megabytes * 2**19) + (b"\xff\xd9" if end else b"")


def jpeg_with_comments(n: int) -> bytes:
    data = _encode(".jpg", COLOUR)
    return data[:2] + b"\xff\xfe\x00\x02" * n + data[2:]


def tiff_claiming(width: int, height: int, samples: int = 1, bits: int = 8) -> bytes:
    entries = [(256, 4, 1, width), (257, 4, 1, height), (258, 3, 1, bits), (277, 3, 1, samples)]
    ifd = struct.pack("<H", len(entries)) + b"".join(struct.pack("<HHII", *e) for e in entries) + b"\0\0\0\0"
    return b"II*\x00" + struct.pack("<I", 8) + ifd + b"\0" * 16


def bmp_claiming(width: int, height: int) -> bytes:
    info = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 24, 0, 0, 2835, 2835, 0, 0)
    return b"BM" + struct.pack("<IHHI", 14 + 40 + 16, 0, 0, 54) + info + b"\0" * 16


def _truncated(data: bytes) -> bytes:
    return data[: len(data) // 2]


def _corrupt_crc(data: bytes) -> bytes:
    bad = bytearray(data)
    idat = bad.find(b"IDAT")
    length = struct.unpack(">I", bad[idat - 4:idat])[0]
    bad[idat + 4 + length] ^= 0xFF  # the chunk's CRC
    return bytes(bad)


# (name, bytes, reader, expected part of the message)
HOSTILE = [
    ("png-60000x60000", png_claiming(60000, 60000), "colour", "declares 60000 x 60000 pixels (3600 megapixels)"),
    ("png-depth-60000x60000", png_claiming(60000, 60000, 16, 0), "depth", "declares 60000 x 60000 pixels"),
    ("jpeg-huge-sof", jpeg_claiming(65000, 65000), "colour", "declares 65000 x 65000 pixels"),
    ("jpeg-many-scans", jpeg_of_scans(MAX_JPEG_SCANS + 50), "colour", f"more than {MAX_JPEG_SCANS} scans"),
    ("jpeg-many-segments", jpeg_with_comments(MAX_JPEG_SEGMENTS), "colour",
     f"more than {MAX_JPEG_SEGMENTS} marker segments"),
    ("jpeg-stuffed-unterminated", jpeg_stuffed(8, end=False), "colour", "ends inside a scan (truncated)"),
    ("tiff-huge", tiff_claiming(60000, 60000), "colour", "declares 60000 x 60000 pixels"),
    ("tiff-decodes-too-large", tiff_claiming(6000, 6000, 4, 32), "depth_or_metres", "would decode to"),
    ("bmp-huge", bmp_claiming(60000, 60000), "colour", "declares 60000 x 60000 pixels"),
    ("pnm-huge", b"P5\n60000 60000\n255\n" + b"\0" * 64, "depth", "declares 60000 x 60000 pixels"),
    ("png-truncated", _truncated(_encode(".png", COLOUR)), "colour", "cannot be decoded (truncated or corrupt PNG"),
    ("png-crc", _corrupt_crc(_encode(".png", COLOUR)), "colour", "IDAT: CRC error"),
    ("jpeg-truncated", _truncated(_encode(".jpg", COLOUR)), "colour", "(truncated)"),
    ("depth-8-bit", _encode(".png", (DEPTH // 256).astype(np.uint8)), "depth",
     "depth image is uint8 with 1 channel, not 16-bit grey"),
    ("depth-3-channels", _encode(".png", np.dstack([DEPTH] * 3)), "depth",
     "depth image is uint16 with 3 channels, not 16-bit grey"),
    ("depth-jpeg", _encode(".jpg", COLOUR), "depth", "is uint8 with 3 channels, not 16-bit grey"),
    ("empty", b"", "colour", "is empty (0 bytes)"),
    ("text", b"not an image at all", "colour", "cannot be read as an image (it is not in an image format recon knows)"),
    ("gif", b"GIF89a" + b"\0" * 32, "colour", "it is a GIF"),
    ("openexr", b"\x76\x2f\x31\x01" + b"\0" * 32, "depth_or_metres", "it is an OpenEXR file"),
    ("png-bad-ihdr", png_claiming(4, 4, depth=7), "colour", "bit depth 7 and colour type 2"),
    ("png-zero-size", png_claiming(0, 0), "colour", "declares 0 x 0 pixels"),
]


def _read(kind: str, path: Path):
    return {"colour": read_color, "depth": read_depth,
            "depth_or_metres": lambda p: read_depth(p, metres=True)}[kind](path)


@pytest.mark.parametrize("name, data, kind, message", HOSTILE, ids=[h[0] for h in HOSTILE])
def test_hostile_images_are_one_line(tmp_path, name, data, kind, message):
    path = tmp_path / f"{name}.img"
    path.write_bytes(data)
    with pytest.raises(FileError) as info:
        _read(kind, path)
    line = info.value.one_line()
    assert message in line and str(path) in line and "\n" not in line, line


def test_files_that_are_not_regular_files_or_too_large(tmp_path):
    with pytest.raises(FileError, match="depth image does not exist"):
        read_depth(tmp_path / "missing.png")
    with pytest.raises(FileError, match="colour image is not a regular file"):
        read_color(tmp_path)
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    with pytest.raises(FileError, match="is not a regular file"):  # never opened: a FIFO would block
        read_color(fifo)
    big = tmp_path / "big.png"
    with big.open("wb") as f:  # sparse: no disk space
        f.write(png_claiming(10, 10))
        f.truncate(MAX_IMAGE_FILE_BYTES + 1)
    with pytest.raises(FileError, match=r"is 256.0 MiB, more than the 256.0 MiB recon reads"):
        read_color(big)


def test_a_store_accepts_png_only_and_a_caller_may_lower_the_pixel_limit(tmp_path):
    path = tmp_path / "c.png"
    path.write_bytes(_encode(".jpg", COLOUR))  # JPEG bytes under a .png name
    with pytest.raises(FileError, match=r"\(it is a JPEG image\); recon reads PNG here"):
        read_image(path, "color", "colour image", formats=("png",))
    assert read_color(path).shape == (12, 16, 3)  # any format by default, recognised by its bytes
    with pytest.raises(FileError, match="more than the 0.0001 megapixels"):
        read_color(path, max_pixels=100)


@pytest.mark.parametrize("ext", [".png", ".jpg", ".tif", ".bmp", ".ppm", ".pgm"])
def test_every_format_reads(tmp_path, ext):
    path = tmp_path / f"c{ext}"
    path.write_bytes(_encode(ext, COLOUR[..., 0] if ext == ".pgm" else COLOUR))
    image = read_color(path)
    assert image.shape == (12, 16, 3) and image.dtype == np.uint8
    if ext in (".png", ".tif", ".pgm"):
        path.write_bytes(_encode(ext, DEPTH))
        assert np.array_equal(read_depth(path), DEPTH)
    if ext == ".tif":
        path.write_bytes(_encode(ext, DEPTH.astype(np.float32) / 1000))
        assert read_depth(path, metres=True).dtype == np.float32
        with pytest.raises(FileError, match="float32 with 1 channel, not 16-bit grey"):
            read_depth(path)


def test_progressive_jpeg_and_library_noise_stays_off_the_terminal(tmp_path, capfd):
    path = tmp_path / "p.jpg"
    path.write_bytes(_encode(".jpg", COLOUR, (cv2.IMWRITE_JPEG_PROGRESSIVE, 1)))
    assert read_color(path).shape == (12, 16, 3)
    path.write_bytes(_corrupt_crc(_encode(".png", COLOUR)))
    with pytest.raises(FileError, match="libpng error: IDAT: CRC error"):
        read_color(path)
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out, err)


def test_the_limits_are_what_the_docs_say():
    rows = _table(ROOT / "docs" / "inputs.md", "Images")
    assert rows == {
        "file size (checked before reading)": f"{MAX_IMAGE_FILE_BYTES:,} bytes ({MAX_IMAGE_FILE_BYTES // 2**20} MiB)",
        "formats": ", ".join(images.FORMAT_NAMES[f] for f in images.FORMATS) + "; a scan store's images: PNG",
        "width x height the header declares (checked before decoding)": f"{MAX_IMAGE_PIXELS:,} pixels",
        "decoded array (width x height x channels x bytes per sample)": f"{MAX_DECODED_BYTES:,} bytes",
        "scans of a JPEG": f"{MAX_JPEG_SCANS}",
        "marker segments of a JPEG": f"{MAX_JPEG_SEGMENTS:,}",
    }


def _table(doc: Path, section: str) -> dict[str, str]:
    """The first | limit | value | table of a section of a Markdown page."""
    text = doc.read_text()
    body = text.split(f"\n## {section}\n", 1)[1].split("\n## ", 1)[0]
    lines = [ln for ln in body.splitlines() if ln.startswith("| ")]
    assert lines[0] == "| limit | value |" and lines[1] == "| --- | --- |"
    rows = {}
    for ln in lines[2:]:
        label, value = (c.strip() for c in ln.strip("|").split(" | ", 1))
        rows[label] = value
    return rows


# ----------------------------------------------------------------------------- measured, in a process of its own
_REFUSE_ALL = """
import sys, time
from pathlib import Path
from recon_cli.errors import FileError
from recon_cli.inputs.images import read_color, read_depth
for line in Path(sys.argv[1]).read_text().splitlines():
    kind, path = line.split(" ", 1)
    try:
        {"colour": read_color, "depth": read_depth,
         "depth_or_metres": lambda p: read_depth(p, metres=True)}[kind](path)
    except FileError:
        continue
    raise SystemExit(f"{path} was read")
_peak()
"""


def test_every_refusal_in_bounded_time_and_memory(tmp_path):
    listing = []
    for name, data, kind, _ in HOSTILE:
        (tmp_path / name).write_bytes(data)
        listing.append(f"{kind} {tmp_path / name}")
    (tmp_path / "list.txt").write_text("\n".join(listing))
    run = run_python(_REFUSE_ALL, [str(tmp_path / "list.txt")], tmp_path)
    assert run.code == 0 and run.err == "", run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)


# ----------------------------------------------------------------------------- through the CLI
@pytest.fixture(scope="module")
def store(tmp_path_factory):
    from recon_cli.config import DEFAULTS, SceneConfig, SensorConfig
    from recon_cli.thesis import eq_4_1_views
    from recon_cli.workflows.capture import CaptureOptions, run_capture

    out = tmp_path_factory.mktemp("store") / "s"
    config = DEFAULTS.replace(scene=SceneConfig("bottle"), sensor=SensorConfig(resolution=0.3), seed=4)
    result = run_capture(CaptureOptions(views=tuple(eq_4_1_views()[0:10:2]), out=out, config=config))
    assert len(result.scans) == 5
    return out


def test_register_skips_a_scan_whose_depth_claims_gigapixels(store, tmp_path, capsys):
    from recon_cli.cli import main
    from recon_cli.reconstruction.scan_store import read_scan

    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    (copy / "scan_0002" / "depth.png").write_bytes(png_claiming(60000, 60000, 16, 0))
    with pytest.raises(MetadataError, match="declares 60000 x 60000 pixels"):
        read_scan(copy / "scan_0002")
    code = main(["register", str(copy), "--out", str(tmp_path / "r"), "--depth", "6"])
    out, err = capsys.readouterr()
    assert code == 0 and "Traceback" not in out + err, out + err
    assert "4 of 5 scans registered (1 skipped)" in out
    skipped = [ln for ln in out.splitlines() if "scan_0002 skipped:" in ln]
    assert len(skipped) == 1 and "depth image declares 60000 x 60000 pixels" in skipped[0], out


def test_register_of_only_hostile_scans_is_one_line_in_bounded_time_and_memory(store, tmp_path):
    copy = tmp_path / "s"
    shutil.copytree(store, copy)
    for folder in copy.glob("scan_*"):
        (folder / "depth.png").write_bytes(png_claiming(60000, 60000, 16, 0))
    run = run_cli(["register", str(copy), "--out", str(tmp_path / "r")], tmp_path)
    assert run.code == 1 and run.err.count("\n") == 1 and "Traceback" not in run.err, run.err
    assert "none of the 5 scans" in run.err and "declares 60000 x 60000 pixels" in run.err, run.err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)
    assert not (tmp_path / "r").exists()


def test_calibration_photo_claiming_gigapixels_is_one_line(tmp_path, capsys):
    from recon_cli.cli import main

    photos = tmp_path / "photos"
    photos.mkdir()
    (photos / "a.png").write_bytes(png_claiming(60000, 60000))
    assert main(["calibrate", "intrinsics", str(photos), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a.png: calibration image declares 60000 x 60000 pixels" in err, err


# ----------------------------------------------------------------------------- fuzz
_fuzz = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                          HealthCheck.function_scoped_fixture])
VALID = {"png": _encode(".png", COLOUR), "png16": _encode(".png", DEPTH), "jpeg": _encode(".jpg", COLOUR),
         "tiff": _encode(".tif", DEPTH), "bmp": _encode(".bmp", COLOUR), "pgm": _encode(".pgm", DEPTH)}


def _outcome(path: Path, data: bytes) -> None:
    """Each reader either returns what it promises or raises the one-line FileError."""
    path.write_bytes(data)
    for kind in ("colour", "depth", "depth_or_metres"):
        try:
            image = _read(kind, path)
        except FileError as exc:
            assert "\n" not in exc.one_line() and str(path) in exc.one_line()
            continue
        if kind == "colour":
            assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
        else:
            assert image.ndim == 2 and image.dtype in (np.uint16, np.float32)
        assert image.shape[0] * image.shape[1] <= MAX_IMAGE_PIXELS


@_fuzz
@given(data=st.binary(max_size=600))
def test_fuzz_random_bytes(tmp_path, data):
    _outcome(tmp_path / "f.img", data)


@_fuzz
@given(name=st.sampled_from(sorted(VALID)), flips=st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)),
                                                            min_size=1, max_size=6),
       head=st.booleans(), cut=st.one_of(st.none(), st.integers(0, 10**6)))
def test_fuzz_mutated_valid_images(tmp_path, name, flips, head, cut):
    data = bytearray(VALID[name])
    for at, value in flips:  # half of the examples flip bytes of the header
        data[at % (min(len(data), 64) if head else len(data))] = value
    if cut is not None:
        data = data[: cut % (len(data) + 1)]
    _outcome(tmp_path / "f.img", bytes(data))

