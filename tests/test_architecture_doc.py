"""docs/architecture.md's package map names every package and module of recon_cli."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _map() -> str:
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text.split("## Packages and folders", 1)[1]
    return re.search(r"```\n(.*?)```", section, flags=re.S).group(1)


def test_the_package_map_names_every_package_and_module():
    words = set(re.findall(r"[\w.]+/?", _map()))
    package = ROOT / "recon_cli"
    missing = []
    for path in sorted(package.rglob("*.py")):
        if path.name == "__init__.py":
            name = path.parent.name + "/"
            if path.parent != package and name not in words:
                missing.append(str(path.parent.relative_to(ROOT)))
        elif path.name not in words and path.stem not in words:
            missing.append(str(path.relative_to(ROOT)))
    assert not missing, f"docs/architecture.md's package map does not name: {', '.join(missing)}"


def test_the_package_map_names_every_data_folder():
    words = set(re.findall(r"[\w.]+/?", _map()))
    for folder in ("robot", "schemas", "scripts_xml", "batches", "tests"):
        assert (ROOT / folder).is_dir() and f"{folder}/" in words
