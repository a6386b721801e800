"""Which files a user's file may name to read: one rule, with the folders it may read from.

An automation script reads from its own folder and scripts_xml/ (:func:`script_rule`); a
cell file and its robot description read from the cell file's folder and recon's robot/
folder (:func:`cell_rule`). The rule is the same for every path such a file names
(includes, ``xacro.load_yaml``, meshes, sensor, board, drives and limits files, realism
profiles, loaded images and clouds), applied when the file is checked and when it is used:

``name`` is a relative path, looked up beside the file that names it and then (a path with
no ``..``) in the rule's shared folder; the first lookup that finds a regular file counts,
and only if its real path (every link resolved) lies inside one of the rule's folders.
Absolute paths (a cell file's: those outside its folders), ``..`` out of those folders and
links that lead out of them are refused before anything is read.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from recon_cli.errors import ScriptError
from recon_cli.paths import ROBOT_DIR, SCRIPTS_DIR

__all__ = ["ReadRule", "cell_rule", "readable", "readable_roots", "script_rule"]


@dataclass(frozen=True)
class ReadRule:
    """Where the files named by one user's file may come from.

    home: the folder of the file that names them (with its subfolders), a real path
    shared: a folder of recon's own files, searched after the naming file's folder
    owner: the file kind in messages ("script", "cell file")
    """

    home: Path
    shared: Path
    owner: str
    #: absolute paths allowed (inside the folders all the same)
    absolute: bool = False

    @property
    def roots(self) -> tuple[Path, ...]:
        """The folders files may be read from, as real paths."""
        return tuple(dict.fromkeys((self.home, self.shared)))

    @property
    def places(self) -> str:
        return f"the {self.owner}'s folder and {self.shared.name}/"

    @property
    def hint(self) -> str:
        return f"a {self.owner} reads files only from its own folder and {self.shared.name}/; copy the file beside it"


def script_rule(script_dir: Path) -> ReadRule:
    """The folders a script may read from: its own folder and scripts_xml/."""
    return ReadRule(Path(script_dir).resolve(), SCRIPTS_DIR.resolve(), "script")


def cell_rule(cell_file: Path) -> ReadRule:
    """The folders a cell file (and the robot description it names) may read from: the
    cell file's folder and recon's robot/ folder."""
    return ReadRule(Path(cell_file).resolve().parent, ROBOT_DIR.resolve(), "cell file", absolute=True)


def readable_roots(script_dir: Path) -> tuple[Path, ...]:
    """The folders a script may read from: its own folder (with its subfolders) and
    scripts_xml/, as real paths."""
    return script_rule(script_dir).roots


def _real(path: Path) -> Path | None:
    try:
        return path.resolve()
    except (OSError, RuntimeError, ValueError):  # a link loop, a name too long, a NUL
        return None


def readable(name: str, rule: ReadRule | Path, source: object | None, what: str, *, beside: Path | None = None) -> Path:
    """The real path of a file a user's file names to read, or a ScriptError ``source: ...``
    (``rule``: a :class:`ReadRule`, or a script's folder for :func:`script_rule`; ``beside``:
    the folder of the file that names it, default the rule's home)."""
    if not isinstance(rule, ReadRule):
        rule = script_rule(rule)
    at, where = (f"{source}: ", str(source)) if source else ("", None)
    text = str(name)
    roots = rule.roots
    absolute = Path(text).is_absolute() or text.startswith("~")
    if not text or "\x00" in text or (absolute and not (rule.absolute and Path(text).is_absolute())):
        raise ScriptError(f"{at}{what} {_shown(text)} is outside {rule.places}: a {rule.owner} names the files it "
                          "reads by a plain relative path", hint=rule.hint, source=where)
    bases = [Path(beside or rule.home).resolve()]
    if ".." not in Path(text).parts and not absolute:
        bases.append(rule.shared)
    not_a_file = missing = through_link = False
    for base in dict.fromkeys(bases):
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
        raise ScriptError(f"{at}{what} {_shown(text)} is not a regular file", hint="name a file", source=where)
    if through_link:
        raise ScriptError(f"{at}{what} {_shown(text)} is a link that leads outside {rule.places}",
                          hint=rule.hint + " instead of linking to it", source=where)
    if missing:
        raise ScriptError(f"{at}{what} {_shown(text)} does not exist beside the {rule.owner} or in "
                          f"{rule.shared.name}/", hint="check the file name", source=where)
    raise ScriptError(f"{at}{what} {_shown(text)} leads outside {rule.places} (not found inside them)",
                      hint=rule.hint + " and give a plain relative path", source=where)


def _shown(text: str) -> str:
    return repr(text if len(text) <= 120 else text[:117] + "...")
