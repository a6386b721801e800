"""Every hand-eye transform the docs show (``hand_eye:`` of a station file, or
``flange_T_camera:``) loads as a station file's hand_eye: copied from the docs, it works."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from recon_cli.backends.station_file import load_station

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^(```|~~~)[^\n]*\n(.*?)^\1[ \t]*$", re.M | re.S)
KEYS = ("hand_eye", "flange_T_camera")


def _found(value, where: str, out: list) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            if k in KEYS and isinstance(v, list):
                out.append((f"{where}: {k}", v))
            else:
                _found(v, where, out)
    elif isinstance(value, list):
        for v in value:
            _found(v, where, out)


def _examples() -> list[tuple[str, list]]:
    out: list[tuple[str, list]] = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for block in FENCE.finditer(text):
            body = block.group(2)
            if not any(re.search(rf"(?m)^\s*{k}\s*:", body) for k in KEYS):
                continue
            line = text.count("\n", 0, block.start()) + 1
            where = f"{doc.relative_to(ROOT)}:{line}"
            try:
                data = yaml.safe_load(body)
            except yaml.YAMLError as exc:
                pytest.fail(f"{where}: a block with a hand-eye transform is not YAML ({exc})")
            _found(data, where, out)
    return out


EXAMPLES = _examples()


def test_the_docs_show_a_hand_eye_transform():
    assert any("hardware.md" in where for where, _ in EXAMPLES), "docs/hardware.md shows no hand_eye example"


@pytest.mark.parametrize(("where", "rows"), EXAMPLES, ids=[w for w, _ in EXAMPLES])
def test_every_hand_eye_example_of_the_docs_loads(tmp_path, where, rows):
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump({"format": 1, "hand_eye": rows, "robot": {"adapter": "sim"},
                                    "camera": {"adapter": "sim"}}))
    station = load_station(path)  # refuses a transform that is not rigid to 1e-6
    assert station is not None, where
