"""The layers of recon_cli: a module imports only from its own layer or the layers below.

From the top: the entry module (``python -m recon_cli``), the command line (cli/), the
benchmarks (bench/), the workflows (workflows/), then the library (every other package and
module). Imports are read from the source (also those inside functions), so a lazy import
counts as much as one at the top of a file; and imports stand at the top of their module,
except those of heavy, optional or platform-specific libraries.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "recon_cli"

#: from the top down; every part of recon_cli not named here is the library, below them all
LAYERS = (("__main__",), ("cli",), ("bench",), ("workflows",))


def _parts() -> set[str]:
    """The top-level packages and modules of recon_cli (``cli``, ``batch``, ``errors``, ...)."""
    return {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"} | {
        p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}


def _module(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in ``path``; ``from a import b`` gives a and a.b."""
    module = _module(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            out += [(node.lineno, name)] + [(node.lineno, f"{name}.{a.name}") for a in node.names]
    return out


def _part(module: str, parts: set[str]) -> str | None:
    """The top-level part of recon_cli that ``module`` is in (None: outside recon_cli)."""
    pieces = module.split(".")
    if pieces[0] != "recon_cli" or len(pieces) < 2 or pieces[1] not in parts:
        return None
    return pieces[1]


def _arrows() -> list[tuple[str, str, str, int]]:
    """(importing part, imported part, file, line) of every import between two parts."""
    parts = _parts()
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        own = _part(_module(path), parts)
        for line, name in _imports(path):
            other = _part(name, parts)
            if own is not None and other is not None and other != own:
                out.append((own, other, str(path.relative_to(PACKAGE.parent)), line))
    return out


def _layer(part: str) -> int:
    return next((i for i, layer in enumerate(LAYERS) if part in layer), len(LAYERS))


def test_the_layers_name_parts_of_the_package():
    parts = _parts()
    assert {"cli", "bench", "workflows", "batch", "report", "thesis", "errors"} <= parts
    assert all(p in parts for layer in LAYERS for p in layer)


def test_the_batch_package_does_not_import_the_command_line():
    found = [(path, line, name) for path in sorted((PACKAGE / "batch").rglob("*.py"))
             for line, name in _imports(path)
             if name in ("recon_cli.cli", "recon_cli.__main__") or name.startswith("recon_cli.cli.")]
    assert found == []


def test_no_module_imports_a_higher_layer():
    upward = [f"{path}:{line} ({own} imports {other})" for own, other, path, line in _arrows()
              if _layer(other) < _layer(own)]
    assert upward == []


def test_the_parts_of_the_package_import_each_other_without_a_circle():
    graph: dict[str, set[str]] = {}
    for own, other, _, _ in _arrows():
        graph.setdefault(own, set()).add(other)
    state: dict[str, int] = {}  # 1: on the path, 2: done
    path: list[str] = []
    circles: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                circles.append(" -> ".join([*path[path.index(nxt):], nxt]))
            elif nxt not in state:
                visit(nxt)
        path.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert circles == []


#: libraries a function may import where it uses them: slow to import, optional extras, or
#: platform-specific; everything else is imported at the top of the module
LATE = frozenset({"open3d", "cv2", "matplotlib", "scipy", "xacro", "ompl", "toppra", "pinocchio", "mplib",
                  "pyads", "genicam", "harvesters", "pyrealsense2", "rerun", "rerun_cli", "pyarrow",
                  "distributed", "psutil", "fcntl", "vamp", "pylibfranka"})


def test_imports_stand_at_the_top_of_their_module():
    """The arrows between modules are where a reader looks for them: an import inside a
    function is only of a heavy, optional or platform-specific library."""
    inside = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.ImportFrom):
                    names = ["recon_cli" if node.level else (node.module or "")]
                elif isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                else:
                    continue
                late = [n for n in names if n.split(".")[0] not in LATE]
                if late:
                    inside.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {', '.join(late)}")
    assert not inside, "imports inside functions:\n" + "\n".join(sorted(set(inside)))
