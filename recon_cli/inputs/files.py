"""The guard every reader of a user's file starts with: a regular file of at most a given
number of bytes.

:func:`checked_size` stats the file: it must exist, be a regular file (not a FIFO, a
device or a folder, which could block or never end), be non-empty where the caller asks,
and be within the limit, all before it is opened. :func:`read_limited` then opens it
without blocking, checks again on the open file that it is a regular file (a FIFO put in
its place meanwhile is refused, not waited on) and reads at most the limit and one byte
(the file may grow between the stat and the read). Given the folder the file belongs to
(``root``), both first refuse a file that is, or lies behind, a link leading out of that
folder (:func:`link_out_of`), before anything is opened.

Each caller words its own refusals: it passes a function that turns a :class:`Refusal`
into the exception to raise (a FileError, a MetadataError, ...).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from recon_cli.errors import FileError

MISSING = "missing"
"""The path does not exist (at the stat)."""
UNREADABLE = "unreadable"
"""The stat, the open or the read failed (``error``; ``opened``: after the stat)."""
NOT_REGULAR = "not regular"
"""Not a regular file (``mode``), at the stat or on the open file."""
EMPTY = "empty"
"""0 bytes, when the caller refuses empty files."""
TOO_LARGE = "too large"
"""More bytes (``size``) than the limit, at the stat."""
GREW = "grew"
"""More bytes than the limit were read."""
OUTSIDE = "outside"
"""The file is, or lies behind, a link (``link``) leading out of the folder it belongs to
(``root``)."""


@dataclass(frozen=True)
class Refusal:
    """Why a file is refused: ``reason`` (one of the constants above) and what goes with it."""

    reason: str
    path: Path
    limit: int
    size: int = 0
    mode: int = 0
    error: OSError | None = None
    opened: bool = False
    root: Path | None = None
    link: Path | None = None


Refuse = Callable[[Refusal], Exception]
"""The caller's wording: a refusal -> the exception to raise."""


def version_stamp(path: Path) -> tuple[int, int]:
    """(modification time [ns], size) of a file, for caches keyed by a file's version; (0, 0)
    when it cannot be stat'ed (the reader then names the problem)."""
    try:
        st = os.stat(path)
    except OSError:
        return (0, 0)
    return (st.st_mtime_ns, st.st_size)


def link_out_of(path: Path, root: Path) -> Path | None:
    """The first link on the way from the folder ``root`` to ``path`` (``path`` itself
    included) that leads out of ``root`` (its real path outside ``root``'s), or ``path`` when
    it lies outside ``root`` without a link (``..``); None when everything stays inside (or a
    loop of links stops the way: nothing can be opened through it). ``root`` itself may be
    reached through a link: what is in it counts."""
    root, path = Path(root), Path(path)
    try:
        real_root = root.resolve()
    except (OSError, RuntimeError):
        return path
    try:
        rel: Path | None = path.relative_to(root)
    except ValueError:
        rel = None
    if rel is None:  # not written below root: only its real path can tell
        try:
            real = path.resolve()
        except (OSError, RuntimeError):
            return path
        return None if real == real_root or real.is_relative_to(real_root) else path
    probe = root
    for part in rel.parts:
        probe = probe / part
        try:
            if probe.is_symlink() or part == "..":
                real = probe.resolve()
                if not (real == real_root or real.is_relative_to(real_root)):
                    return probe
        except (OSError, RuntimeError):  # a loop of links: nothing is reached through it (the stat says so)
            return None
    return None


def checked_size(path: Path, limit: int, refuse: Refuse, *, empty: bool = True, root: Path | None = None) -> int:
    """The size of ``path``, a regular file of at most ``limit`` bytes (and not empty
    unless ``empty``), from its stat, or ``refuse``'s exception; with ``root``, first
    refused when it is or lies behind a link leading out of that folder."""
    if root is not None and (link := link_out_of(path, root)) is not None:
        raise refuse(Refusal(OUTSIDE, path, limit, root=Path(root), link=link))
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise refuse(Refusal(MISSING, path, limit)) from None
    except OSError as exc:
        raise refuse(Refusal(UNREADABLE, path, limit, error=exc)) from None
    if not stat.S_ISREG(st.st_mode):
        raise refuse(Refusal(NOT_REGULAR, path, limit, mode=st.st_mode))
    if not empty and st.st_size == 0:
        raise refuse(Refusal(EMPTY, path, limit))
    if st.st_size > limit:
        raise refuse(Refusal(TOO_LARGE, path, limit, size=st.st_size))
    return st.st_size


def read_limited(path: Path, limit: int, refuse: Refuse, *, empty: bool = True, root: Path | None = None) -> bytes:
    """The bytes of ``path``, a regular file of at most ``limit`` bytes (and not empty
    unless ``empty``; with ``root``, not a link leading out of that folder), checked before
    it is opened and opened without blocking, or ``refuse``'s exception."""
    checked_size(path, limit, refuse, empty=empty, root=root)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
        with os.fdopen(fd, "rb") as f:
            mode = os.fstat(f.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise refuse(Refusal(NOT_REGULAR, path, limit, mode=mode))
            data = f.read(limit + 1)
    except OSError as exc:
        raise refuse(Refusal(UNREADABLE, path, limit, error=exc, opened=True)) from None
    if len(data) > limit:
        raise refuse(Refusal(GREW, path, limit))
    return data


def file_errors(path: Path, what: str, hint: str, too_large: Callable[[int], tuple[str, str]]) -> Refuse:
    """The refusals of a user's data file as FileErrors ``PATH: WHAT is ...``; ``too_large``
    gives the message tail and the hint for a file of the given size."""

    def refuse(r: Refusal) -> FileError:
        if r.reason == MISSING:
            return FileError(f"{path}: {what} does not exist", hint="check the path")
        if r.reason == UNREADABLE and r.error is not None:
            return FileError(f"{path}: {what} cannot be read ({r.error.strerror})", hint=hint)
        if r.reason == NOT_REGULAR:
            return FileError(f"{path}: {what} is not a regular file", hint=hint)
        if r.reason == EMPTY:
            return FileError(f"{path}: {what} is empty (0 bytes)", hint=hint)
        if r.reason == OUTSIDE:
            return FileError(outside_text(r, what), hint=OUTSIDE_HINT)
        tail, large_hint = too_large(r.size)
        if r.reason == TOO_LARGE:
            return FileError(f"{path}: {what} is {tail}", hint=large_hint)
        return FileError(f"{path}: {what} grew past the limit while it was read", hint=large_hint)

    return refuse


OUTSIDE_HINT = "copy the file into the folder instead of linking it, or remove the link"


def outside_text(r: Refusal, what: str) -> str:
    """``PATH: WHAT is a link leading out of ROOT`` (or lies behind one): the link's name, never
    where it leads."""
    if r.link is None or r.link == r.path:
        how = "is a link leading out of" if r.path.is_symlink() else "lies outside"
        return f"{r.path}: {what} {how} {r.root}"
    return f"{r.path}: {what} lies behind the link {r.link}, which leads out of {r.root}"
