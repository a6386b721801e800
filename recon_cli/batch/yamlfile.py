"""YAML read with the line of every key and item, so that a mistake in a batch file is
reported as ``file:line key: what is wrong``."""

from __future__ import annotations

from pathlib import Path

from recon_cli.errors import FileError, InputError

MAX_BYTES = 5_000_000  # a batch file is a few kB; refuse anything absurd before parsing it


class Map(dict):
    """A YAML mapping; ``lines[key]`` is the 1-based line of the key."""

    lines: dict


class Seq(list):
    """A YAML sequence; ``lines[i]`` is the 1-based line of item i."""

    lines: list


def _loader():
    import yaml

    class Loader(yaml.SafeLoader):
        def construct_mapping(self, node, deep=False):  # noqa: D102
            out = Map()
            out.lines = {}
            self.flatten_mapping(node)
            for key_node, value_node in node.value:
                key = self.construct_object(key_node, deep=True)
                if not isinstance(key, str | int | float | bool):
                    raise InputError(f"line {key_node.start_mark.line + 1}: a key must be a name")
                out[key] = self.construct_object(value_node, deep=True)
                out.lines[key] = key_node.start_mark.line + 1
            return out

        def construct_sequence(self, node, deep=False):  # noqa: D102
            out = Seq(self.construct_object(child, deep=True) for child in node.value)
            out.lines = [child.start_mark.line + 1 for child in node.value]
            return out

    Loader.add_constructor("tag:yaml.org,2002:map", Loader.construct_mapping)
    Loader.add_constructor("tag:yaml.org,2002:seq", Loader.construct_sequence)
    return Loader


def load_yaml(path: Path, what: str = "batch file"):
    """The document of a YAML file with line numbers (:class:`Map` / :class:`Seq`), or a
    one-line FileError / InputError."""
    import yaml

    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise FileError(f"{what} {path} is larger than {MAX_BYTES // 1_000_000} MB")
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise FileError(f"{what} {path} does not exist", hint="see docs/batch.md for the format") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FileError(f"cannot read the {what} {path} ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        return yaml.load(text, Loader=_loader())  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        raise InputError(f"{where}: not valid YAML ({getattr(exc, 'problem', None) or exc})") from None
    except InputError as exc:
        raise InputError(f"{path}:{exc.message}", hint=exc.hint) from None
