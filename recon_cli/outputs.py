"""Writing into an output folder: nothing lands outside it, nothing is half-written.

* :func:`inside` turns a relative name from a script into a path inside the output folder
  and refuses names that leave it, directly (``..``, absolute paths) or through links
  already in the folder;
* :func:`refuse_links` checks a folder that is being reused (``recon run --append``) for
  links, so that no later write can follow one out of it;
* :func:`atomic_write` writes to a fresh temporary file beside the target (created
  exclusively, so never through a link) and renames it into place: a reader sees the old
  file or the new one, never a part, and a crash leaves no broken file.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

from recon_cli.errors import FileError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_MODE = 0o666 & ~_umask()  # what open() would give a new file


def _within(path: Path, root: Path) -> bool:
    return path == root or path.is_relative_to(root)


def inside(root: Path, name: str | Path, what: str = "output") -> Path:
    """``root / name``, refused unless it stays inside ``root`` after resolving links."""
    root = Path(root)
    real_root = root.resolve()
    rel = Path(name)
    if rel.is_absolute() or str(name).startswith("~"):
        raise FileError(f"{what} {name} is an absolute path", hint="give a path relative to the output folder")
    target = root / rel
    # every part that exists already must resolve inside the folder
    probe = root
    for part in rel.parts:
        probe = probe / part
        if probe.is_symlink() or probe.exists():
            real = probe.resolve()
            if not _within(real, real_root):
                raise FileError(f"{what} {name} would be written outside the output folder {root} "
                                f"({probe} leads to {real})",
                                hint="remove the link or choose an empty output folder")
        elif part == "..":
            raise FileError(f"{what} {name} leaves the output folder", hint="give a path inside the output folder")
    if not _within(target.resolve(), real_root):
        raise FileError(f"{what} {name} leaves the output folder {root}", hint="give a path inside the output folder")
    if target.is_symlink():
        raise FileError(f"{what} {target} is a link; recon does not write through links",
                        hint="remove the link or choose an empty output folder")
    return target


def refuse_links(root: Path) -> None:
    """Refuse a folder that holds a link (a later write could follow it out)."""
    root = Path(root)
    if root.is_symlink():
        return  # the folder itself may be reached through a link; what is inside counts
    for dirpath, dirnames, filenames in os.walk(root):
        for name in (*dirnames, *filenames):
            p = Path(dirpath) / name
            if p.is_symlink():
                raise FileError(f"output folder {root} holds a link {p} -> {os.readlink(p)}; recon does not write "
                                "through links", hint="remove the link or choose an empty output folder")


def atomic_write(path: Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` for a fresh temporary file beside ``path``, then rename it to
    ``path`` (replacing a file, never following a link)."""
    path = Path(path)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        write(tmp)
        os.chmod(tmp, _MODE)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return path


def atomic_write_text(path: Path, text: str) -> Path:
    return atomic_write(path, lambda tmp: tmp.write_text(text))
