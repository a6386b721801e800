"""Every YAML input (station, realism, camera, batch files) through the one reader: hostile
and careless files are refused with one line naming file:line, before anything is built,
within bounded memory and time; fuzzed documents never give anything but that line."""

from __future__ import annotations

import textwrap
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.backends.station_file import load_station
from recon_cli.batch.spec import load_batch_file
from recon_cli.calibration.camera_file import load_camera_file
from recon_cli.cli.batch_commands import AppCommands
from recon_cli.errors import FileError, InputError, ReconError
from recon_cli.inputs.schema import KINDS, check, load_schema, range_rows
from recon_cli.inputs.yamlfile import LIMITS, parse_yaml, read_yaml
from recon_cli.realism import parse_profile
from tests.inputs.measure import run_cli

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = AppCommands()  # the options of recon's commands, as recon batch hands them in
SIM_STATION = "format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n"
BOMB = textwrap.dedent("""\
    a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]
    b: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]
    c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]
    d: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]
    e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]
    f: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]
    g: &g [*f, *f, *f, *f, *f, *f, *f, *f, *f]
    h: &h [*g, *g, *g, *g, *g, *g, *g, *g, *g]
    i: &i [*h, *h, *h, *h, *h, *h, *h, *h, *h]
    """)


# ----------------------------------------------------------------------------- the reader itself
@pytest.mark.parametrize("text, message", [
    (BOMB, "f.yaml:2: an alias (*name) is not accepted"),
    ("a: !!python/object/apply:os.system ['true']\n", "f.yaml:1: a tag (!name or !!type) is not accepted"),
    ("a: !custom 3\n", "f.yaml:1: a tag (!name or !!type) is not accepted"),
    ("a: !!binary aGVsbG8=\n", "f.yaml:1: a tag (!name or !!type) is not accepted"),
    ("a: 1\nb: 2\na: 3\n", "f.yaml:3: key a appears twice in one mapping (also line 1)"),
    ("'x y': 1\n'x y': 3\n", "f.yaml:2: a key appears twice in one mapping (also line 1)"),
    ("a: .nan\n", "f.yaml:1: a = nan is not a finite number"),
    ("a:\n  - 1\n  - -.inf\n", "f.yaml:3: a[1] = -inf is not a finite number"),
    ("a: 1.0e999\n", "f.yaml:1: a = inf is not a finite number"),
    ("a: " + "9" * 5000 + "\n", "f.yaml:1: an integer of 5000 digits"),
    ("? [1, 2]\n: 3\n", "f.yaml:1: a key must be a name"),
    ("a: {x: 1}\nb:\n  <<: {y: 2}\n", "f.yaml:3: merge key << is not accepted"),
    ("a: " + "[" * 100 + "]" * 100 + "\n", "f.yaml:1: nested more than 32 levels deep"),
    ("a: '" + "x" * 20_000 + "'\n", "f.yaml:1: a value of 20,000 characters"),
    ("a: [1, 2\n", "f.yaml:2: not valid YAML"),
    ("~: 3\n", "f.yaml:1: a key is empty or not a name"),
])
def test_the_reader_refuses_with_file_and_line(text, message):
    with pytest.raises(InputError) as info:
        parse_yaml(text, "f.yaml")
    line = info.value.one_line()
    assert message in line and "\n" not in line


@pytest.mark.parametrize("text, message, secret", [
    ("hand_eye:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, .nan]\n", "f.yaml:3: hand_eye[1][3] = nan is not a finite number",
     ".nan"),
    ("hand_eye:\n  translation: [1e999, 0, 0]\n", "f.yaml:2: hand_eye.translation[0] = inf is not a finite number",
     "1e999"),
    (".nan\n", "f.yaml:1: the file's value = nan is not a finite number", ".nan"),
    ("a: !secret_tag 3\n", "f.yaml:1: a tag", "secret_tag"),
    ("a: &secret_anchor 1\nb: *secret_anchor\n", "f.yaml:2: an alias", "secret_anchor"),
    ("secret_key_1: 1\nsecret_key_1: 2\n", "f.yaml:2: key secret_key_1 appears twice", "root"),
    ("'root:x:0:0:root': 1\n'root:x:0:0:root': 2\n", "f.yaml:2: a key appears twice", "root"),
    ('a: "secret\\qvalue"\n', "f.yaml:1: not valid YAML (found unknown escape character)", "secret"),
    ("a: [secret_value, 2\n", "not valid YAML", "secret_value"),
])
def test_a_refusal_names_the_key_path_and_quotes_nothing(text, message, secret):
    """A non-finite number is named by its key path; a tag, an anchor, a key that is not a
    plain name and the parser's view of the text are not repeated."""
    with pytest.raises(InputError) as info:
        parse_yaml(text, "f.yaml")
    line = info.value.one_line()
    assert message in line and line.startswith("f.yaml:") and secret not in line, line


def test_numbers_read_as_numbers_and_dates_as_text():
    doc = parse_yaml("a: 1e-3\nb: -2E+2\nc: 2001-12-14\nd: 1_000\ne: '1e3'\n", "f.yaml")
    assert doc == {"a": 0.001, "b": -200.0, "c": "2001-12-14", "d": 1000, "e": "1e3"}
    assert doc.lines == {"a": 1, "b": 2, "c": 3, "d": 4, "e": 5}


def test_size_is_checked_before_the_file_is_read(tmp_path):
    big = tmp_path / "station.yaml"
    with big.open("w") as f:  # 12 MB of valid YAML
        f.write(SIM_STATION)
        for i in range(350_000):
            f.write(f"# padding line {i:09d} .........\n")
    t0 = time.monotonic()
    with pytest.raises(FileError, match=r"station file .* has 12,\d{3},\d{3} bytes, more than a station file may"):
        load_station(big)
    assert time.monotonic() - t0 < 1.0
    with pytest.raises(FileError, match="is not UTF-8 text"):
        (tmp_path / "bin.yaml").write_bytes(b"a: \xff\xfe\n")
        read_yaml(tmp_path / "bin.yaml")
    with pytest.raises(FileError, match="is not a file"):
        read_yaml(tmp_path)


# ----------------------------------------------------------------------------- one schema per kind
def _write(tmp_path: Path, text: str, name: str = "f.yaml") -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.mark.parametrize("text, message", [
    (SIM_STATION + BOMB, "an alias (*name) is not accepted"),
    (SIM_STATION + "speed: 3\n", ":4: speed is not a known key"),
    ("format: 1\nrobot: {adapter: sim}\ncamera:\n  adapter: replay\n  replay:\n    source: x\n"
     "    intrinsics: {fx: 1.0e12, fy: 500, cx: 320, cy: 240}\n",
     ":7: camera.replay.intrinsics.fx = 1e+12 px is outside [1, 100000] px"),
    ("format: 1\nrobot: {adapter: sim}\ncamera:\n  adapter: realsense\n  realsense: {fps: .nan}\n",
     ":5: camera.realsense.fps = nan is not a finite number"),
    ("format: 1\nrobot: {adapter: sim}\ncamera:\n  adapter: realsense\n  realsense: {width: '640'}\n",
     ":5: camera.realsense.width is a text of 3 characters, not a whole number"),
    ("format: 1\nhand_eye:\n  - [-1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n"
     "robot: {adapter: sim}\ncamera: {adapter: sim}\n", ":2: the hand-eye transform flange_T_camera is not a rigid"),
    ("format: 1\ncell: {table_lift: 7}\nrobot: {adapter: sim}\ncamera: {adapter: sim}\n",
     ":2: cell.table_lift = 7 m is outside [0, 0.65] m"),
    ("format: 1\nrobot: {adapter: sim}\ncamera: {adapter: sim, sim: {resolution: 1.0e-300}}\n",
     "camera.sim.resolution = 1e-300 is outside [0.05, 1]"),
])
def test_station_files(tmp_path, text, message):
    path = _write(tmp_path, text, "station.yaml")
    with pytest.raises(InputError) as info:
        load_station(path)
    line = info.value.one_line()
    assert message in line and str(path) in line and "\n" not in line


@pytest.mark.parametrize("text, message", [
    ("kinematics:\n  joint_stiffness: {arm_joint_2: 1.0e-300}\n",
     ":2: kinematics.joint_stiffness.arm_joint_2 = 1e-300 N m/rad or N/m is outside [10, 1e+10]"),
    ("camera:\n  actual: {fx: 1.0e12, fy: 1700, cx: 800, cy: 600}\n", ":2: camera.actual.fx = 1e+12 px is outside"),
    ("depth: {quantization_mm: .inf}\n", ":1: depth.quantization_mm = inf is not a finite number"),
    (BOMB, "an alias (*name) is not accepted"),
    ("image: !!python/name:os.system\n", "a tag (!name or !!type) is not accepted"),
])
def test_realism_profiles(text, message):
    with pytest.raises(InputError) as info:
        parse_profile(text, "p.yaml")
    assert message in info.value.one_line()


@pytest.mark.parametrize("text, message", [
    ("format: 1\ncamera: {width: 640, height: 480, fx: 1.0e12, fy: 500, cx: 320, cy: 240}\n",
     ":2: camera.fx = 1e+12 px is outside [1, 100000] px"),
    ("format: 1\ncamera: {width: 640, height: 480, fx: 500, fy: 500, cx: 320, cy: 240, distortion: [1, .nan, 0, 0]}\n",
     "camera.distortion[1] = nan is not a finite number"),
    ("format: 2\ncamera: {width: 640, height: 480, fx: 500, fy: 500, cx: 320, cy: 240}\n", ":1: format = 2 is not 1"),
    ("camera: {width: 640.5, height: 480, fx: 500, fy: 500, cx: 320, cy: 240}\n",
     ":1: camera.width = 640.5 is not a whole number"),
])
def test_camera_files(tmp_path, text, message):
    with pytest.raises(InputError) as info:
        load_camera_file(_write(tmp_path, text, "intrinsics.yaml"))
    assert message in info.value.one_line()


def test_batch_matrix_is_counted_before_it_is_expanded(tmp_path):
    values = ", ".join(map(str, range(1000)))
    path = _write(tmp_path, f"jobs:\n  - run: smoke.xml\n    name: j{{a}}{{b}}{{c}}\n"
                            f"    matrix: {{a: [{values}], b: [{values}], c: [{values}]}}\n", "batch.yaml")
    t0 = time.monotonic()
    with pytest.raises(InputError, match=r"batch.yaml:4 jobs\[0\].matrix: expands to 1,000,000,000 combinations"):
        load_batch_file(path, COMMANDS)
    assert time.monotonic() - t0 < 5.0
    many = "".join(f"  - validate: smoke.xml\n    name: v{i}{{a}}\n    matrix: {{a: [{values}]}}\n" for i in range(12))
    with pytest.raises(InputError, match="the batch has more than 10,000 jobs"):
        load_batch_file(_write(tmp_path, "jobs:\n" + many, "many.yaml"), COMMANDS)


@pytest.mark.parametrize("name", ["PYTHONPATH", "PYTHONSTARTUP", "LD_PRELOAD", "LD_LIBRARY_PATH", "PATH",
                                  "DYLD_INSERT_LIBRARIES", "GCONV_PATH", "pythonpath"])
def test_batch_jobs_cannot_set_loader_variables(tmp_path, name):
    path = _write(tmp_path, f"jobs:\n  - run: smoke.xml\n    env: {{{name}: .}}\n", "batch.yaml")
    with pytest.raises(InputError, match=f"a job may not set {name}"):
        load_batch_file(path, COMMANDS)


def test_batch_jobs_may_set_their_own_variables(tmp_path):
    path = _write(tmp_path, "jobs:\n  - run: smoke.xml\n    env: {RECON_PROGRESS: '0', OMP_NUM_THREADS: 1}\n", "b.yaml")
    assert dict(load_batch_file(path, COMMANDS).jobs[0].env) == {"RECON_PROGRESS": "0", "OMP_NUM_THREADS": "1"}


def test_shipped_files_match_their_schemas():
    from recon_cli.realism import load_profile

    for name in ("ideal", "thesis"):
        load_profile(name)
    for path in (ROOT / "batches").glob("*.yaml"):
        check(read_yaml(path), "batch", path)


def test_every_schema_is_valid_and_every_number_is_bounded():
    import jsonschema

    for kind in KINDS:
        schema = load_schema(kind)
        jsonschema.validators.validator_for(schema).check_schema(schema)

        def walk(node, path):
            if isinstance(node, dict):
                if node.get("type") in ("number", "integer"):
                    assert any(k in node for k in ("minimum", "exclusiveMinimum")), f"{path} has no lower bound"
                    assert "maximum" in node or "exclusiveMaximum" in node, f"{path} has no upper bound"
                for k, v in node.items():
                    walk(v, f"{path}/{k}")
            elif isinstance(node, list):
                for i, v in enumerate(node):
                    walk(v, f"{path}/{i}")

        walk(schema, kind)


def test_docs_list_the_limits_of_every_yaml_kind():
    text = (ROOT / "docs" / "inputs.md").read_text()
    for kind in KINDS:
        for key, rng in range_rows(kind):
            assert f"| {kind} | `{key}` | {rng} |" in text, f"docs/inputs.md lacks {kind} {key} {rng}"
    for name, value in (("max_bytes", f"{LIMITS.max_bytes:,} bytes"), ("max_depth", f"{LIMITS.max_depth} levels"),
                        ("max_nodes", f"{LIMITS.max_nodes:,} values"), ("max_text", f"{LIMITS.max_text:,} characters"),
                        ("max_int_digits", f"{LIMITS.max_int_digits} digits")):
        assert value in text, f"docs/inputs.md does not state {name} = {value}"


# ----------------------------------------------------------------------------- through the CLI, measured
@pytest.mark.parametrize("kind", ["station", "realism", "batch"])
def test_hostile_files_through_the_cli_are_one_line_in_bounded_time_and_memory(tmp_path, kind):
    hostile = {"station": SIM_STATION + BOMB, "realism": BOMB, "batch": "jobs:\n  - run: smoke.xml\n" + BOMB}[kind]
    path = _write(tmp_path, hostile, f"{kind}.yaml")
    args = {"station": ["station", "check", str(path)],
            "realism": ["capture", "--realism", str(path), "--out", str(tmp_path / "out")],
            "batch": ["batch", str(path), "--list"]}[kind]
    run = run_cli(args, tmp_path)
    err = run.err
    assert run.code == 1 and err.count("\n") == 1 and "Traceback" not in err
    assert "an alias (*name) is not accepted" in err
    assert run.seconds < 20 and run.peak_gb < 1.0, (run.seconds, run.peak_gb)
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- fuzz
_fuzz = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
_scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                     st.text(max_size=12))


def _keys(kind: str) -> list[str]:
    names: set[str] = set()

    def walk(node):
        if isinstance(node, dict):
            names.update(node.get("properties", {}))
            for v in node.values():
                walk(v)
        elif isinstance(node, list):
            for v in node:
                walk(v)

    walk(load_schema(kind))
    return sorted(names) + ["bogus", "adapter"]


def _documents(kind: str):
    keys = st.sampled_from(_keys(kind))
    return st.recursive(_scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                          st.dictionaries(keys, inner, max_size=6)), max_leaves=30)


def _dump(doc) -> str:
    import yaml

    return yaml.safe_dump(doc, allow_unicode=True)


@_fuzz
@given(text=st.text(alphabet=st.sampled_from(list("ab:-[]{}&*!|>'\"#%@`?,\n .0123456789eE~<")), max_size=200))
def test_fuzz_reader_never_raises_anything_but_one_line(text):
    try:
        parse_yaml(text, "f.yaml")
    except InputError as exc:
        assert "\n" not in exc.one_line()


@_fuzz
@given(doc=st.dictionaries(st.sampled_from(_keys("station")), _documents("station"), max_size=6))
def test_fuzz_station_files(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("s") / "station.yaml"
    path.write_text(_dump(doc))
    try:
        load_station(path)
    except ReconError as exc:
        assert "\n" not in exc.one_line()


@_fuzz
@given(doc=st.dictionaries(st.sampled_from(_keys("realism")), _documents("realism"), max_size=6))
def test_fuzz_realism_profiles(doc):
    try:
        parse_profile(_dump(doc), "p.yaml")
    except ReconError as exc:
        assert "\n" not in exc.one_line()


@_fuzz
@given(doc=st.dictionaries(st.sampled_from(_keys("camera")), _documents("camera"), max_size=4))
def test_fuzz_camera_files(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("c") / "intrinsics.yaml"
    path.write_text(_dump(doc))
    try:
        load_camera_file(path)
    except ReconError as exc:
        assert "\n" not in exc.one_line()


@_fuzz
@given(doc=st.dictionaries(st.sampled_from(_keys("batch")), _documents("batch"), max_size=4))
def test_fuzz_batch_files(tmp_path_factory, doc):
    path = tmp_path_factory.mktemp("b") / "batch.yaml"
    path.write_text(_dump(doc))
    try:
        load_batch_file(path, COMMANDS)
    except ReconError as exc:
        assert "\n" not in exc.one_line()


# mutated valid documents reach the builders behind the schemas
def _load_batch(path: Path):
    return load_batch_file(path, COMMANDS)


VALID = {
    "station": {"format": 1, "name": "cell", "cell": {"kind": "gantry", "safety_distance": 0.03, "table_lift": 0.0},
                "hand_eye": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.1], [0, 0, 0, 1]],
                "robot": {"adapter": "sim"},
                "camera": {"adapter": "replay", "replay": {"source": "x", "kind": "images", "depth_scale": 1000.0,
                                                            "intrinsics": {"fx": 500, "fy": 500, "cx": 320, "cy": 240},
                                                            "distortion": [0, 0, 0, 0], "loop": False}}},
    "realism": {"format": 1, "name": "p", "kinematics": {"joint_offset_std_deg": 0.01,
                                                          "joint_stiffness": {"arm_joint_2": 60000},
                                                          "base_error": {"translation_mm": 2, "rotation_deg": 0.1}},
                "camera": {"actual": {"fx": 1700, "fy": 1700, "cx": 800, "cy": 600, "width": 1600, "height": 1200,
                                      "distortion": [0.01, -0.1, 0, 0, 0.5]}},
                "depth": {"grazing_dropout_deg": [60, 80], "quantization_mm": 0.1}, "image": {"exposure": 1.2}},
    "camera": {"format": 1, "camera": {"width": 640, "height": 480, "fx": 500, "fy": 500, "cx": 320, "cy": 240,
                                       "distortion": [0, 0, 0, 0, 0]}},
    "batch": {"name": "b", "defaults": {"timeout_s": 60, "retries": 1, "expect": {"max_std_mm": 1}},
              "jobs": [{"validate": "smoke.xml", "name": "v{seed}", "matrix": {"seed": [0, 1]}},
                       {"autoscan": {"n": 4, "resolution": 0.2}, "expect": {"min_coverage_pct": 50}}]},
}


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


@st.composite
def _mutated(draw, kind):
    import copy

    doc = copy.deepcopy(VALID[kind])
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(doc) if p]
        path = draw(st.sampled_from(paths))
        parent = doc
        for part in path[:-1]:
            parent = parent[part]
        parent[path[-1]] = draw(st.one_of(_scalars, st.lists(_scalars, max_size=5),
                                          st.dictionaries(st.sampled_from(_keys(kind)), _scalars, max_size=3)))
    return doc


@_fuzz
@given(data=st.data())
@pytest.mark.parametrize("kind", ["station", "realism", "camera", "batch"])
def test_fuzz_mutated_valid_files(tmp_path_factory, kind, data):
    doc = data.draw(_mutated(kind))
    path = tmp_path_factory.mktemp(kind) / f"{kind}.yaml"
    path.write_text(_dump(doc))
    load = {"station": load_station, "realism": lambda p: parse_profile(p.read_text(), str(p)),
            "camera": load_camera_file, "batch": _load_batch}[kind]
    try:
        load(path)
    except ReconError as exc:
        assert "\n" not in exc.one_line()


def test_the_valid_documents_are_valid(tmp_path):
    for kind, doc in VALID.items():
        path = tmp_path / f"{kind}.yaml"
        path.write_text(_dump(doc))
        {"station": load_station, "realism": lambda p: parse_profile(p.read_text(), str(p)),
         "camera": load_camera_file, "batch": _load_batch}[kind](path)
