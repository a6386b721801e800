"""Fuzzing of a hand-eye data set's index, mapping and pose files: whatever a careless or
hostile user writes, reading the mapping, the data set and every view's robot pose gives a
data set or the project's one-line error, never another exception, and no message shows a
word of a file outside the data set folder or of a text file inside it."""

from __future__ import annotations

import itertools
import json
import tempfile
from pathlib import Path

import cv2
import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.calibration.dataset import (
    CameraNumbers,
    DatasetSpec,
    dataset_views,
    read_dataset,
    read_mapping,
)
from recon_cli.errors import ReconError
from recon_cli.perception.charuco import BoardSpec

_fuzz = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SECRET = "secret_word_of_an_outside_file"
PRIVATE = "private_words_of_a_text_file"
BOARD = BoardSpec(5, 7, 0.04, 0.03, "DICT_6X6_250")

KEYS = ["data", "image", "pose", "x", "y", "z", "qx", "qy", "qz", "qw", "O_T_EE", "matrix", "joints", "roll",
        "pitch", "yaw", "position", "orientation", "t", "q", "intrinsics", "fx", "fy", "cx", "cy", "distortion",
        "target_finder", "type", "rows", "cols", "chessboard_dim", "aruco_marker_dim", "dictionary",
        "static_camera"]
MAPPING_KEYS = ["board", "images", "poses", "index", "pose_format", "position", "quaternion", "quaternion_order",
                "rpy", "matrix", "matrix_order", "joints", "length_unit", "angle_unit", "camera", "setup",
                "image_column", "format"]
PATHS = ["images/0.png", "images/1.png", "poses/0.yaml", "poses/1.json", "notes.yaml", "images/link.png",
         "poses/link.yaml", "../outside/secret.yaml", "../outside/secret.png", "images/../../outside/secret.yaml",
         "{outside}/secret.yaml", "/etc/passwd", "~/secret.yaml", "", " ", "\x00", "a" * 5000, "images",
         "cal_data.yaml", "log.csv", "CharucoGridTargetFinder", "xyz-quat", "matrix", "joints", "mm", "deg",
         "column", "wxyz", "eye-to-hand", "DICT_6X6_250", "x", "O_T_EE", "position.x"]
TEXT_PIECES = ["\n", ": ", "- ", "[", "]", "{", "}", "'", '"', "&a ", "*a", "!!python/object:os.system ", ".nan",
               "-.inf", "1e999", "0", "-1", "1e308", "data:", "image: ", "pose: ", "O_T_EE: ", "x: ", "board: ",
               "../outside/secret.yaml", "/etc/passwd", "\x00", "é", ",", "NaN", "Infinity"]

_scalars = (st.none() | st.booleans() | st.integers(-10**40, 10**40) | st.floats()
            | st.sampled_from(PATHS))
_values = st.recursive(_scalars, lambda children: st.lists(children, max_size=6)
                       | st.dictionaries(st.sampled_from(KEYS), children, max_size=8), max_leaves=24)
_number = st.floats(-2, 2) | st.sampled_from([0.0, 1.0, 612.0, 1e6, 7.0])
_pose = (st.fixed_dictionaries({"x": _number, "y": _number, "z": _number, "qx": st.just(0.0), "qy": st.just(0.0),
                                "qz": _number, "qw": st.just(1.0)})
         | st.builds(lambda t, k: {"O_T_EE": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, *t, k]}, st.lists(_number, min_size=3,
                                                                                                   max_size=3),
                     st.sampled_from([1, 0])))
_values = _pose | _values
_mapping = st.dictionaries(st.sampled_from(MAPPING_KEYS), _scalars | st.lists(st.sampled_from(PATHS), max_size=17)
                           | st.dictionaries(st.sampled_from(["fx", "fy", "cx", "cy", "distortion", "squares_x",
                                                              "squares_y", "square_length", "marker_length",
                                                              "dictionary"]), _scalars, max_size=6), max_size=5)
_index = st.builds(lambda pairs, extra: {"data": pairs, **extra},
                   st.lists(st.dictionaries(st.sampled_from(["image", "pose"]), _values, max_size=2)
                            | st.fixed_dictionaries({"image": st.sampled_from(PATHS), "pose": st.sampled_from(PATHS)
                                                     | _values}), max_size=6),
                   st.dictionaries(st.sampled_from(["intrinsics", "target_finder", "static_camera"]), _values,
                                   max_size=3)) | _values


def _text(draw, doc, json_file: bool) -> str:
    """A document as JSON or YAML (non-finite numbers included), now and then cut and spliced."""
    text = json.dumps(doc) if json_file else yaml.safe_dump(doc, allow_unicode=True)
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.sampled_from(TEXT_PIECES)) + text[at + draw(st.integers(0, 8)):]
    return text


@st.composite
def _dataset(draw) -> dict[str, str | None]:
    """The files of one data set: an index (YAML or JSON, or none), a mapping (or none), two
    pose files and a CSV file (or none); the source given to the reader."""
    files: dict[str, str | None] = {}
    index_name = draw(st.sampled_from(["cal_data.yaml", "index.json", None]))
    if index_name is not None:
        files[index_name] = _text(draw, draw(_index), index_name.endswith(".json"))
    files["mapping.yaml"] = _text(draw, draw(_mapping), False) if draw(st.booleans()) else None
    files["poses/0.yaml"] = _text(draw, draw(_values), False)
    files["poses/1.json"] = _text(draw, draw(_values), True)
    if draw(st.booleans()):
        rows = draw(st.lists(st.lists(st.sampled_from(PATHS + ["0.1", "nan", "1e999", "-inf", ""]), max_size=9),
                             max_size=5))
        header = draw(st.lists(st.sampled_from(["image", "x", "y", "z", "qx", "qy", "qz", "qw", "image", "name"]),
                               max_size=9))
        files["log.csv"] = "\n".join(",".join(r) for r in [header, *rows]) + "\n"
    files["source"] = draw(st.sampled_from([".", ".", index_name or ".", "log.csv" if "log.csv" in files else "."]))
    return files


_count = itertools.count()


def _folder(root: Path, files: dict[str, str | None]) -> tuple[Path, Path | None, Path]:
    """The data set folder beside a folder of secrets; links inside lead out of it."""
    outside = root / "outside"
    if not outside.exists():
        outside.mkdir()
        (outside / "secret.yaml").write_text(f"{SECRET}: 1\n")
        cv2.imwrite(str(outside / "secret.png"), np.full((16, 16, 3), 200, np.uint8))
    data = root / f"data{next(_count)}"
    (data / "images").mkdir(parents=True)
    (data / "poses").mkdir()
    for k in range(2):
        cv2.imwrite(str(data / "images" / f"{k}.png"), np.full((16, 16, 3), 255, np.uint8))
    (data / "images" / "link.png").symlink_to(outside / "secret.png")
    (data / "poses" / "link.yaml").symlink_to(outside / "secret.yaml")
    (data / "notes.yaml").write_text(f"{PRIVATE}\n")
    for name, text in files.items():
        if name != "source" and text is not None:
            (data / name).write_text(text.replace("{outside}", str(outside)), encoding="utf-8", errors="replace")
    mapping = data / "mapping.yaml" if files.get("mapping.yaml") is not None else None
    return data, mapping, data / str(files["source"])


class _Stop(Exception):
    """Raised once every pose is read (no image is decoded here)."""


@given(files=_dataset())
@_fuzz
def test_a_fuzzed_data_set_is_read_or_refused_in_one_line(files):
    with tempfile.TemporaryDirectory() as tmp:
        data, mapping, source = _folder(Path(tmp), files)
        messages: list[str] = []

        def poses_read(poses, skipped) -> None:
            messages.extend(s.reason for s in skipped)
            raise _Stop

        try:
            spec = read_mapping(mapping, data) if mapping is not None else DatasetSpec()
            dataset = read_dataset(source, spec)
            messages.extend(s.reason for s in dataset.skipped)
            dataset_views(dataset, spec.mapping, spec.board or BOARD, spec.camera or CameraNumbers(20, 20, 8, 8),
                          poses_read=poses_read)
        except _Stop:
            pass
        except ReconError as exc:
            messages.append(exc.one_line())
        for text in messages:
            assert "\n" not in text, text
            assert SECRET not in text and PRIVATE not in text and "root:x:" not in text, text
