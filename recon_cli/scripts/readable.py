"""Which files an automation script may read: one rule for every path a script names
(includes, ``xacro.load_yaml``, realism profiles, object and reference meshes, loaded
images and clouds), applied by the loader, the static checks and the commands alike."""

from __future__ import annotations

import os
from pathlib import Path

from recon_cli.errors import ScriptError
from recon_cli.paths import SCRIPTS_DIR

__all__ = ["readable", "readable_roots"]


def readable_roots(script_dir: Path) -> tuple[Path, ...]:
    """The folders a script may read from: its own folder (with its subfolders) and
    scripts_xml/, as real paths."""
    return tuple(dict.fromkeys((Path(script_dir).resolve(), SCRIPTS_DIR.resolve())))


def _real(path: Path) -> Path | None:
    try:
        return path.resolve()
    except (OSError, RuntimeError, ValueError):  # a link loop, a name too long, a NUL
        return None


def readable(name: str, script_dir: Path, source: object | None, what: str, *, beside: Path | None = None) -> Path:
    """The real path of a file a script names to read, or a ScriptError ``source: ...``.

    The rule: ``name`` is a relative path, looked up beside the file that names it
    (``beside``, default the script's folder) and then in scripts_xml/; the first lookup
    that finds a regular file counts, and only if its real path (every link resolved) lies
    inside the script's folder or scripts_xml/. Absolute paths, ``..`` out of those folders
    and links that lead out of them are refused; nothing else is looked at."""
    at, where = (f"{source}: ", str(source)) if source else ("", None)
    text = str(name)
    roots = readable_roots(script_dir)
    hint = "scripts read files only from their own folder and scripts_xml/; copy the file beside the script"
    if not text or Path(text).is_absolute() or text.startswith("~"):
        raise ScriptError(f"{at}{what} {text!r} is outside the script's folder and scripts_xml/: scripts name the "
                          "files they read by a plain relative path", hint=hint, source=where)
    not_a_file = missing = through_link = False
    for base in dict.fromkeys((Path(beside or script_dir).resolve(), SCRIPTS_DIR.resolve())):
        written = base / text
        real = _real(written)
        if real is None:  # a link loop, or a name the file system refuses
            not_a_file = True
            continue
        if not any(real.is_relative_to(r) for r in roots):
            through_link |= any(Path(os.path.normpath(written)).is_relative_to(r) for r in roots)
            continue
        try:
            if real.is_file():
                return real
            exists = real.exists() or real.is_symlink()  # a link loop left unresolved
        except OSError:
            exists = True
        not_a_file |= exists
        missing |= not exists
    if not_a_file:
        raise ScriptError(f"{at}{what} {text!r} is not a regular file", hint="name a file", source=where)
    if through_link:
        raise ScriptError(f"{at}{what} {text!r} is a link that leads outside the script's folder and scripts_xml/",
                          hint=hint + " instead of linking to it", source=where)
    if missing:
        raise ScriptError(f"{at}{what} {text!r} does not exist beside the script or in scripts_xml/",
                          hint="check the file name", source=where)
    raise ScriptError(f"{at}{what} {text!r} leads outside the script's folder and scripts_xml/ (not found inside "
                      "them)", hint=hint + " and give a plain relative path", source=where)
