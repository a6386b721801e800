"""Image reads (colour photos, depth images, scan store PNGs) with the header checked before
anything is decoded.

A read goes: the file is a regular file of at most :data:`MAX_IMAGE_FILE_BYTES`; its bytes
are one of the formats recon reads (PNG, JPEG, TIFF, BMP, PNM), recognised by their
signature, not the file name; the width and height its header declares are at most
:data:`MAX_IMAGE_PIXELS` pixels and the decoded array at most :data:`MAX_DECODED_BYTES`;
a JPEG has at most :data:`MAX_JPEG_SCANS` scans and :data:`MAX_JPEG_SEGMENTS` marker
segments and ends with its end marker. Only then
does OpenCV decode the same bytes, and the result is checked to be what the caller needs
(a depth image 16-bit single channel, a colour image 8-bit three channels). Every refusal
is a :class:`~recon_cli.errors.FileError` of one line.

OpenCV has its own pixel limit (``OPENCV_IO_MAX_IMAGE_PIXELS``, 2^30 unless set), read
once when its library loads, so it cannot be lowered reliably from here; the header check
is what enforces recon's limit, for every format OpenCV is allowed to see: bytes of any
other format (WebP, GIF, JPEG 2000, OpenEXR, HDR, ...) never reach a decoder. The
libraries' own diagnostics (libpng's, libjpeg's, OpenCV's warnings) are kept off the
terminal; a failed decode names the library's reason in its one line.
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import numpy as np

from recon_cli.errors import FileError
from recon_cli.inputs import files

MAX_IMAGE_FILE_BYTES = 256 * 2**20
"""Largest image file read: 256 MiB (a 24 MP photo is about 10 MB as JPEG, 70 MB as 8-bit
TIFF; a 2064 x 1544 16-bit depth PNG about 6 MB)."""

MAX_IMAGE_PIXELS = 50_000_000
"""Largest width x height a header may declare: 50 megapixels (2064 x 1544 depth cameras,
24 MP photos of the ChArUco board, with room to spare)."""

MAX_DECODED_BYTES = 400_000_000
"""Largest decoded array: 400 MB, a 50 MP image of four 16-bit channels."""

MAX_JPEG_SCANS = 100
"""Most scans a JPEG may have (a progressive JPEG has about 10; each scan is a pass over
the whole image, so thousands of tiny scans take minutes to decode)."""

MAX_JPEG_SEGMENTS = 1000
"""Most marker segments of a JPEG (tables, metadata, scans: a few dozen in a camera's
JPEG, a few hundred with a large ICC profile or XMP packet)."""

FORMATS = ("png", "jpeg", "tiff", "bmp", "pnm")
FORMAT_NAMES = {"png": "PNG", "jpeg": "JPEG", "tiff": "TIFF", "bmp": "BMP", "pnm": "PNM (PGM/PPM/PBM)"}

_IMREAD_UNCHANGED = -1
_IMREAD_COLOR = 1


@dataclass(frozen=True)
class Header:
    """What an image's header declares: format, size, channels and bytes per sample of the
    decoded array (an upper bound where the decoder may expand, e.g. a palette)."""

    format: str
    width: int
    height: int
    channels: int
    sample_bytes: int

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def decoded_bytes(self) -> int:
        return self.pixels * self.channels * self.sample_bytes


@dataclass(frozen=True)
class Kind:
    """What a caller needs back: OpenCV's read flag, the accepted dtypes and channels."""

    name: str
    flags: int
    dtypes: tuple[str, ...]
    channels: int
    text: str  # "8-bit colour", "16-bit grey", ...


COLOR = Kind("color", _IMREAD_COLOR, ("uint8",), 3, "8-bit colour")
DEPTH = Kind("depth", _IMREAD_UNCHANGED, ("uint16",), 1, "16-bit grey")
DEPTH_OR_METRES = Kind("depth_or_metres", _IMREAD_UNCHANGED, ("uint16", "float32"), 1,
                       "16-bit grey or 32-bit float grey")
KINDS = {k.name: k for k in (COLOR, DEPTH, DEPTH_OR_METRES)}


class _Bad(Exception):
    """A header that does not hold what its format needs (internal; becomes a FileError)."""


# --------------------------------------------------------------------- header probes
def _u16be(d: bytes, i: int) -> int:
    return struct.unpack_from(">H", d, i)[0]


def _png(d: bytes) -> Header:
    if len(d) < 33 or d[12:16] != b"IHDR" or struct.unpack_from(">I", d, 8)[0] != 13:
        raise _Bad("its first chunk is not a complete IHDR header")
    w, h, depth, colour = struct.unpack_from(">IIBB", d, 16)
    if depth not in (1, 2, 4, 8, 16) or colour not in (0, 2, 3, 4, 6):
        raise _Bad(f"its IHDR header has bit depth {depth} and colour type {colour}, which PNG does not define")
    channels = {0: 1, 2: 3, 3: 4, 4: 4, 6: 4}[colour]  # palette and grey+alpha expand to 3-4 channels
    return Header("png", w, h, channels, 2 if depth == 16 else 1)


_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def _next_marker(a: np.ndarray, i: int, chunk: int = 4 * 2**20) -> int:
    """Where the marker after entropy-coded data starts: the first 0xFF at or after ``i``
    followed by neither a stuffed 0x00, a restart marker (0xD0-0xD7) nor another 0xFF;
    -1 when there is none. Vectorised: a file of nothing but stuffed bytes is no slower."""
    n = len(a)
    while i < n - 1:
        end = min(n - 1, i + chunk)
        nxt = a[i + 1:end + 1]
        hit = np.flatnonzero((a[i:end] == 0xFF) & (nxt != 0x00) & (nxt != 0xFF) & ((nxt < 0xD0) | (nxt > 0xD7)))
        if hit.size:
            return i + int(hit[0])
        i = end
    return -1


def _jpeg(d: bytes) -> Header:
    """Walk the JPEG's markers: one frame header (SOF), at most MAX_JPEG_SCANS scans, the
    end marker (EOI) present (a truncated JPEG would otherwise decode grey-filled)."""
    n = len(d)
    a = np.frombuffer(d, np.uint8)
    i = 2
    frame: tuple[int, int, int, int] | None = None
    scans = segments = 0
    while True:
        segments += 1
        if segments > MAX_JPEG_SEGMENTS:
            raise _Bad(f"it has more than {MAX_JPEG_SEGMENTS} marker segments")
        if i >= n:
            raise _Bad("it ends before its end marker (truncated)")
        if d[i] != 0xFF:
            raise _Bad(f"byte {i} is not a marker")
        while i < n and d[i] == 0xFF:  # fill bytes
            i += 1
        if i >= n:
            raise _Bad("it ends before its end marker (truncated)")
        m = d[i]
        i += 1
        if m == 0xD9:  # EOI
            break
        if m == 0x01 or 0xD0 <= m <= 0xD8:  # standalone markers
            if m == 0xD8:
                raise _Bad("it holds a second start-of-image marker")
            continue
        if i + 2 > n:
            raise _Bad("it ends inside a marker segment (truncated)")
        length = _u16be(d, i)
        if length < 2 or i + length > n:
            raise _Bad("a marker segment runs past the end of the file (truncated)")
        if m in _SOF:
            if frame is not None:
                raise _Bad("it holds two frame headers")
            if length < 8:
                raise _Bad("its frame header is too short")
            precision, height, width, comps = d[i + 2], _u16be(d, i + 3), _u16be(d, i + 5), d[i + 7]
            if height == 0:
                raise _Bad("its frame header declares the height later (DNL), which recon does not read")
            frame = (width, height, comps, precision)
        i += length
        if m == 0xDA:  # SOS: entropy-coded data follows, up to the next marker
            if frame is None:
                raise _Bad("a scan comes before the frame header")
            scans += 1
            if scans > MAX_JPEG_SCANS:
                raise _Bad(f"it has more than {MAX_JPEG_SCANS} scans")
            i = _next_marker(a, i)
            if i < 0:
                raise _Bad("it ends inside a scan (truncated)")
    if frame is None:
        raise _Bad("it has no frame header")
    if scans == 0:
        raise _Bad("it has no image data (no scan)")
    width, height, comps, precision = frame
    return Header("jpeg", width, height, max(comps, 1), 2 if precision > 8 else 1)


def _tiff(d: bytes) -> Header:
    if d[2:4] in (b"+\x00", b"\x00+"):
        raise _Bad("it is a BigTIFF, which recon does not read")
    e = "<" if d[:2] == b"II" else ">"
    if len(d) < 8:
        raise _Bad("its header is incomplete")
    ifd = struct.unpack_from(e + "I", d, 4)[0]
    if ifd < 8 or ifd + 2 > len(d):
        raise _Bad("its first directory lies outside the file")
    count = struct.unpack_from(e + "H", d, ifd)[0]
    if ifd + 2 + 12 * count > len(d):
        raise _Bad("its first directory runs past the end of the file")
    tags: dict[int, tuple[int, int, int]] = {}
    for k in range(count):
        tag, typ, cnt = struct.unpack_from(e + "HHI", d, ifd + 2 + 12 * k)
        tags.setdefault(tag, (typ, cnt, ifd + 2 + 12 * k + 8))

    def values(tag: int) -> list[int]:
        if tag not in tags:
            return []
        typ, cnt, at = tags[tag]
        size = {3: 2, 4: 4}.get(typ)
        if size is None or cnt == 0 or cnt > 64:
            raise _Bad(f"its tag {tag} has type {typ} and {cnt} values")
        if size * cnt > 4:
            at = struct.unpack_from(e + "I", d, at)[0]
            if at + size * cnt > len(d):
                raise _Bad(f"the values of its tag {tag} lie outside the file")
        return list(struct.unpack_from(e + ("H" if size == 2 else "I") * cnt, d, at))

    width, height = values(256), values(257)
    if not width or not height:
        raise _Bad("its first directory has no image width or length")
    bits = values(258) or [1]
    spp = (values(277) or [1])[0]
    if not 1 <= spp <= 4:
        raise _Bad(f"it declares {spp} samples per pixel (1 to 4 are read)")
    sample = max(1, (max(bits) + 7) // 8)
    return Header("tiff", width[0], height[0], spp, sample)


def _bmp(d: bytes) -> Header:
    if len(d) < 26:
        raise _Bad("its header is incomplete")
    size = struct.unpack_from("<I", d, 14)[0]
    if size == 12:
        w, h, _, bits = struct.unpack_from("<HHHH", d, 18)
    elif 40 <= size <= 124 and len(d) >= 30:
        w, h, _, bits = struct.unpack_from("<iiHH", d, 18)
        h = abs(h)
    else:
        raise _Bad(f"its info header has {size} bytes, which BMP does not define")
    if bits not in (1, 4, 8, 16, 24, 32):
        raise _Bad(f"it declares {bits} bits per pixel")
    if w <= 0:
        raise _Bad(f"it declares a width of {w}")
    return Header("bmp", w, h, 4 if bits == 32 else 3, 1)


def _pnm(d: bytes) -> Header:
    kind = d[1] - ord("0")
    want = 2 if kind in (1, 4) else 3
    tokens: list[int] = []
    i, n = 2, min(len(d), 4096)
    while len(tokens) < want:
        while i < n and d[i] in b" \t\r\n\x0b\x0c":
            i += 1
        if i < n and d[i] == ord("#"):
            while i < n and d[i] not in b"\r\n":
                i += 1
            continue
        j = i
        while j < n and d[j] in b"0123456789":
            j += 1
        if j == i or j - i > 9:
            raise _Bad("its header does not hold width, height and maximum value as numbers")
        tokens.append(int(d[i:j]))
        i = j
    width, height = tokens[0], tokens[1]
    maxval = tokens[2] if want == 3 else 1
    if not 1 <= maxval <= 65535:
        raise _Bad(f"it declares a maximum value of {maxval}")
    return Header("pnm", width, height, 3 if kind in (3, 6) else 1, 2 if maxval > 255 else 1)


def _format_of(d: bytes) -> str | None:
    if d.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if d.startswith(b"\xff\xd8\xff"):
        return "jpeg"
    if d[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        return "tiff"
    if d.startswith(b"BM"):
        return "bmp"
    if len(d) >= 3 and d[0] == ord("P") and d[1] in b"123456" and d[2] in b" \t\r\n#":
        return "pnm"
    return None


_PROBES = {"png": _png, "jpeg": _jpeg, "tiff": _tiff, "bmp": _bmp, "pnm": _pnm}


def _describe(d: bytes) -> str:
    """What unreadable bytes are, as a clause ("it is a GIF"): a format named by its signature,
    never the bytes themselves (a message must not show what a file holds)."""
    if d.startswith(b"\x00\x00\x00") and d[4:8] == b"ftyp":
        return "it is an AVIF/HEIF file"
    for magic, name in ((b"RIFF", "a WebP/RIFF file"), (b"GIF8", "a GIF"), (b"\x76\x2f\x31\x01", "an OpenEXR file"),
                        (b"#?RADIANCE", "a Radiance HDR file"), (b"\x00\x00\x00\x0cjP", "a JPEG 2000 file"),
                        (b"\xff\x4f\xff\x51", "a JPEG 2000 codestream"), (b"Pf", "a PFM file"),
                        (b"PF", "a PFM file"), (b"P7", "a PAM file")):
        if d.startswith(magic):
            return f"it is {name}"
    return "it is not in an image format recon knows"


def image_header(data: bytes, formats: tuple[str, ...] = FORMATS) -> Header:
    """The header of an image's bytes, or ValueError saying why it is not one recon reads."""
    fmt = _format_of(data)
    if fmt is None or fmt not in formats:
        names = ", ".join(FORMAT_NAMES[f] for f in formats)
        clause = f"it is a {FORMAT_NAMES[fmt]} image" if fmt else _describe(data)
        raise ValueError(f"cannot be read as an image ({clause}); recon reads {names} here")
    try:
        header = _PROBES[fmt](data)
    except _Bad as exc:
        raise ValueError(f"is not a valid {FORMAT_NAMES[fmt]} image: {exc}") from None
    except (struct.error, IndexError):
        raise ValueError(f"is not a valid {FORMAT_NAMES[fmt]} image: its header is incomplete (truncated)") from None
    if header.width <= 0 or header.height <= 0:
        raise ValueError(f"declares {header.width} x {header.height} pixels")
    return header


# --------------------------------------------------------------------- decoding
_QUIET = threading.RLock()


@contextlib.contextmanager
def native_output_captured(fds: tuple[int, ...] = (2,), opencv: bool = True) -> Iterator[list[str]]:
    """Route the process's file descriptors ``fds`` (stderr: libpng, libjpeg and rply print
    their diagnostics there directly) into a temporary file while native code runs, and
    silence OpenCV's logging; yields a list that receives the captured text afterwards.
    Serialised by a lock: one redirection at a time."""
    with _QUIET, tempfile.TemporaryFile() as sink:
        captured: list[str] = []
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        saved = [os.dup(fd) for fd in fds]
        opencv_logging: ModuleType | None = None
        level = 0
        if opencv:
            import cv2

            opencv_logging = cv2.utils.logging
            level = opencv_logging.getLogLevel()
        try:
            for fd in fds:
                os.dup2(sink.fileno(), fd)
            if opencv_logging is not None:
                opencv_logging.setLogLevel(opencv_logging.LOG_LEVEL_SILENT)
            yield captured
        finally:
            if opencv_logging is not None:
                opencv_logging.setLogLevel(level)
            for fd, copy in zip(fds, saved, strict=True):
                os.dup2(copy, fd)
                os.close(copy)
            sink.seek(0)
            captured.append(sink.read(64 * 1024).decode("utf-8", "replace"))


def _library_reason(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1][:160] if lines else ""


def _size_text(n: int) -> str:
    return f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n} bytes"


def _mp(n: int) -> str:
    return f"{n / 1e6:.4g} megapixels"


def read_file_bytes(path: Path, what: str, limit: int, hint: str) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes, or a FileError."""

    refuse = files.file_errors(path, what, hint, lambda size: (
        f"{_size_text(size)}, more than the {_size_text(limit)} recon reads", hint))
    return files.read_limited(path, limit, refuse, empty=False)


def read_image(path: Path | str, kind: Kind | str, what: str, *, formats: tuple[str, ...] = FORMATS,
               max_pixels: int = MAX_IMAGE_PIXELS, hint: str | None = None) -> np.ndarray:
    """Decode an image file as ``kind`` (:data:`COLOR`: (H, W, 3) uint8 BGR; :data:`DEPTH`:
    (H, W) uint16; :data:`DEPTH_OR_METRES`: (H, W) uint16 or float32), checking size,
    format and the header's dimensions first. ``what`` names the image in messages
    ("depth image"); ``formats`` restricts the accepted formats."""
    import cv2

    path = Path(path)
    kind = KINDS[kind] if isinstance(kind, str) else kind
    fix = hint or "replace the file with a valid image"
    data = read_file_bytes(path, what, MAX_IMAGE_FILE_BYTES, fix)
    try:
        header = image_header(data, formats)
    except ValueError as exc:
        raise FileError(f"{path}: {what} {exc}", hint=fix) from None
    if header.pixels > max_pixels:
        raise FileError(f"{path}: {what} declares {header.width} x {header.height} pixels ({_mp(header.pixels)}), "
                        f"more than the {_mp(max_pixels)} recon reads",
                        hint=hint or f"use an image of at most {_mp(max_pixels)}")
    if header.decoded_bytes > MAX_DECODED_BYTES:
        raise FileError(f"{path}: {what} would decode to {_size_text(header.decoded_bytes)} ({header.width} x "
                        f"{header.height}, {header.channels} channels of {8 * header.sample_bytes} bits), more than "
                        f"the {_size_text(MAX_DECODED_BYTES)} recon decodes", hint=hint or "use a smaller image")
    buffer = np.frombuffer(data, np.uint8)
    with native_output_captured() as out:
        try:
            image = cv2.imdecode(buffer, kind.flags)
            error = None
        except cv2.error as exc:
            image, error = None, str(exc).strip().splitlines()[-1] if str(exc).strip() else "OpenCV error"
    if image is None:
        reason = error or _library_reason(out[0] if out else "")
        raise FileError(f"{path}: {what} cannot be decoded (truncated or corrupt "
                        f"{FORMAT_NAMES[header.format]}{': ' + reason if reason else ''})", hint=fix)
    channels = 1 if image.ndim == 2 else image.shape[2]
    if str(image.dtype) not in kind.dtypes or channels != kind.channels:
        raise FileError(f"{path}: {what} is {image.dtype} with {channels} channel{'s' if channels != 1 else ''}, "
                        f"not {kind.text}", hint=hint or f"store it as a {kind.text} image")
    return image


def read_color(path: Path | str, what: str = "colour image", **kw) -> np.ndarray:
    """(H, W, 3) uint8 BGR of an image file (see :func:`read_image`)."""
    return read_image(path, COLOR, what, **kw)


def read_depth(path: Path | str, what: str = "depth image", *, metres: bool = False, **kw) -> np.ndarray:
    """(H, W) uint16 of a depth image file; with ``metres`` a 32-bit float image is accepted
    too (see :func:`read_image`)."""
    return read_image(path, DEPTH_OR_METRES if metres else DEPTH, what, **kw)
