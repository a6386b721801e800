"""The README and docs/ stay true to the code and to themselves.

- the README stays short (details live in docs/);
- every ``recon ...`` command line shown (fenced code blocks and inline code) names an
  existing command and only options that command has;
- docs/commands.md documents every command and every option of the app;
- every relative link points to an existing file inside the repository, and every anchor
  into a Markdown file to an existing heading (GitHub's slug rules);
- no development history (work sessions, issue numbers, phases) in the docs.
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

import pytest
import typer

from recon_cli.cli import app

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
COMMANDS_MD = ROOT / "docs" / "commands.md"
DOCS = [README, *sorted((ROOT / "docs").glob("*.md"))]
README_LIMIT = 12288  # [bytes]

FENCE = re.compile(r"^(```|~~~)[^\n]*\n.*?^\1[ \t]*$", re.M | re.S)
INLINE_CODE = re.compile(r"(`+)(.+?)\1", re.S)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
HEADING = re.compile(r"^(#{1,6})\s+(.+?)\s*#*\s*$", re.M)
COMMAND_START = re.compile(r"^(?:\$\s+)?(?:[A-Z_][A-Z0-9_]*=\S+\s+)*recon(?:\s|$)")
OPTION = re.compile(r"^--?[A-Za-z][\w-]*$")
HISTORY = [re.compile(p, re.I) for p in (r"\bsession \d", r"\bissue #?\d", r"\bphase \d")]


# ----------------------------------------------------------------------------- the app
@cache
def _tree() -> dict[tuple[str, ...], object]:
    """Every command and group of the app by its path, ("recon",) for the app itself."""
    out: dict[tuple[str, ...], object] = {}

    def walk(cmd, path: tuple[str, ...]) -> None:
        out[path] = cmd
        if _is_group(cmd):
            for name in cmd.list_commands(None):
                walk(cmd.get_command(None, name), (*path, name))

    walk(typer.main.get_command(app), ("recon",))
    return out


def _is_group(cmd) -> bool:
    return hasattr(cmd, "list_commands")


def _options(cmd) -> set[str]:
    names = {"--help"}
    for p in cmd.params:
        names.update(o for o in (*getattr(p, "opts", ()), *getattr(p, "secondary_opts", ()))
                     if o.startswith("-"))
    return names


# ----------------------------------------------------------------------------- the docs
def _text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _prose(text: str) -> str:
    """The text without fenced code blocks and with inline code replaced by a word."""
    return INLINE_CODE.sub("code", FENCE.sub("", text))


def _command_lines(text: str) -> list[str]:
    """``recon ...`` command lines of fenced code blocks and inline code spans."""
    lines = []
    for block in FENCE.finditer(text):
        lines += [ln.strip() for ln in block.group(0).splitlines()[1:-1]]
    for span in INLINE_CODE.finditer(FENCE.sub("", text)):
        lines.append(" ".join(span.group(2).split()))
    return [ln for ln in lines if COMMAND_START.match(ln)]


def _check_command_line(line: str) -> list[str]:
    """What is wrong with one command line (empty when it names a real command and options)."""
    tree = _tree()
    tokens = line.split("#", 1)[0].split()
    while tokens and tokens[0] != "recon":  # "$", VAR=value
        tokens.pop(0)
    path: tuple[str, ...] = ("recon",)
    rest = tokens[1:]
    # descend through the groups
    while _is_group(tree[path]) and rest and not rest[0].startswith("-"):
        word = rest[0].strip("[]()`,;:")
        word = word if word.strip(".…") == "" else word.rstrip(".")
        subcommands = {p[-1] for p in tree if len(p) == len(path) + 1 and p[:-1] == path}
        if "|" in word:  # "recon bench ik|sim|...": every alternative must exist
            missing = [w for w in word.split("|") if w not in subcommands]
            return [f"{line!r}: no command {' '.join(path)} {w}" for w in missing]
        if word in subcommands:
            path = (*path, word)
            rest = rest[1:]
            continue
        if word.strip(".…") == "" or word.isupper() or word.startswith("<"):  # a placeholder
            return []
        return [f"{line!r}: no command {' '.join(path)} {word} (choose: {', '.join(sorted(subcommands))})"]
    known = _options(tree[path])
    errors = []
    for token in rest:
        name = token.strip("[](){}`,;:").split("=", 1)[0]
        if "|" in name:  # "[--local|--global-only]"
            candidates = name.split("|")
        else:
            candidates = [name]
        for c in candidates:
            if OPTION.match(c) and c not in known:
                errors.append(f"{line!r}: {' '.join(path)} has no option {c}")
    return errors


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # links: their text
    text = text.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


@cache
def _anchors(path: Path) -> frozenset[str]:
    seen: dict[str, int] = {}
    out = set()
    for m in HEADING.finditer(FENCE.sub("", _text(path))):
        slug = _slug(m.group(2))
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return frozenset(out)


def _ids(paths):
    return [str(p.relative_to(ROOT)) for p in paths]


# ----------------------------------------------------------------------------- tests
def test_readme_is_short():
    size = len(README.read_bytes())
    assert size < README_LIMIT, f"README.md is {size} bytes; keep it under {README_LIMIT} (details go to docs/)"


def test_docs_exist():
    for name in ("commands", "architecture", "scripts", "benchmarks", "planning", "simulation", "cell"):
        assert (ROOT / "docs" / f"{name}.md").is_file(), f"docs/{name}.md is missing"


@pytest.mark.parametrize("doc", DOCS, ids=_ids(DOCS))
def test_command_lines_name_real_commands_and_options(doc: Path):
    lines = _command_lines(_text(doc))
    errors = [e for ln in lines for e in _check_command_line(ln)]
    assert not errors, "\n".join(errors)


def test_command_line_check_catches_mistakes():
    assert _check_command_line("recon register /tmp/scans --voxel 0.002") == []
    assert _check_command_line("$ MUJOCO_GL=egl recon bench ik --poses 50  # --nonsense") == []
    assert _check_command_line("recon bench ik|sim|planners") == []
    assert _check_command_line("recon run SCRIPT [--out DIR] [--backend sim|hardware]") == []
    assert _check_command_line("recon bench ...") == []
    assert _check_command_line("recon scan --out x")
    assert _check_command_line("recon bench imaginary")
    assert _check_command_line("recon register DIR --voxels 0.002")
    assert _check_command_line("recon ik --n 4")
    assert _check_command_line("recon bench ik --n 50")


def test_the_readme_shows_the_main_commands():
    firsts = set()
    for line in _command_lines(_text(README)):
        words = line.split("#", 1)[0].split()
        words = words[words.index("recon") + 1:]
        if words:
            firsts.add(words[0])
    for name in ("ik", "capture", "register", "run", "autoscan", "bench"):
        assert name in firsts, f"the README's tour shows no 'recon {name} ...'"


def test_commands_md_documents_every_command_and_option():
    text = _text(COMMANDS_MD)
    sections = {m.group(1): m.end() for m in re.finditer(r"(?m)^#{2,4} `(recon[^`]*)`\s*$", text)}
    errors = []
    for path, cmd in _tree().items():
        if _is_group(cmd):
            continue
        name = " ".join(path)
        if name not in sections:
            errors.append(f"docs/commands.md has no section '`{name}`'")
            continue
        start = sections[name]
        nxt = re.search(r"(?m)^#{2,4} ", text[start:])
        body = text[start: start + nxt.start()] if nxt else text[start:]
        for option in sorted(_options(cmd) - {"--help"}):
            if f"`{option}`" not in body:
                errors.append(f"docs/commands.md, `{name}`: option {option} is not documented")
        for p in cmd.params:
            if type(p).__name__.endswith("Argument") and f"`{p.name.upper()}`" not in body:
                errors.append(f"docs/commands.md, `{name}`: argument {p.name.upper()} is not documented")
    assert not errors, "\n".join(errors)


@pytest.mark.parametrize("doc", DOCS, ids=_ids(DOCS))
def test_relative_links_resolve(doc: Path):
    errors = []
    for target in LINK.findall(_prose(_text(doc))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (doc.parent / file_part).resolve() if file_part else doc
        if not dest.is_relative_to(ROOT):
            errors.append(f"{target}: points outside the repository (name shared folders in prose)")
            continue
        if not dest.exists():
            errors.append(f"{target}: no such file")
            continue
        if anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            errors.append(f"{target}: no heading '#{anchor}' in {dest.relative_to(ROOT)}")
    assert not errors, f"{doc.relative_to(ROOT)}:\n" + "\n".join(errors)


def test_slugs_follow_github():
    assert _slug("`recon bench ik`: IK benchmark") == "recon-bench-ik-ik-benchmark"
    assert _slug("Configuration, errors, outputs") == "configuration-errors-outputs"
    assert _slug("The script language (`schemas/recon_script.xsd`)") == "the-script-language-schemasrecon_scriptxsd"


@pytest.mark.parametrize("doc", DOCS, ids=_ids(DOCS))
def test_no_development_history(doc: Path):
    text = _text(doc)
    hits = [f"line {text.count(chr(10), 0, m.start()) + 1}: {m.group(0)!r}"
            for pattern in HISTORY for m in pattern.finditer(text)]
    assert not hits, f"{doc.relative_to(ROOT)} tells development history: " + ", ".join(hits)


def test_readme_states_the_script_limits_of_the_code():
    from recon_cli.expansion.expressions import LIMITS

    text = _text(README)
    expected = {
        "max_int_bits": f"±2^{LIMITS.max_int_bits}",
        "max_size": f"{LIMITS.max_size:,} characters or items",
        "max_text": f"{LIMITS.max_text:,} characters",
        "max_elements": f"{LIMITS.max_elements:,} / {LIMITS.max_macro_depth}",
        "max_seconds": f"| {LIMITS.max_seconds:g} s |",
        "max_file_bytes": f"{LIMITS.max_file_bytes // 1_000_000} MB each; at most {LIMITS.max_files} files",
        "max_commands": f"{LIMITS.max_commands:,}; a `<ring>` at most {LIMITS.max_ring_count} views",
    }
    missing = [f"{k}: {v!r}" for k, v in expected.items() if v not in text]
    assert not missing, "README.md's limits differ from recon_cli.expansion.expressions.LIMITS: " + ", ".join(missing)
