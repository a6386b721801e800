"""Fuzzing of the two remaining readers of user files: XML automation scripts (load and
static checks, as ``recon validate`` does) and the ADS section of a station file. Whatever
the input, the answer is a loaded result or the project's one-line error, never another
exception."""

from __future__ import annotations

import dataclasses

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from recon_cli.errors import ReconError

_fuzz = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                         HealthCheck.function_scoped_fixture])

SCRIPT = """<?xml version="1.0"?>
<recon name="fuzz" on_failure="skip" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:property name="focus" value="0 0 0.8"/>
  <xacro:macro name="ring" params="theta n">
    <xacro:scan_ring focus="${focus}" radius="0.6" theta="${theta}" count="${n}" phi_start="0"/>
  </xacro:macro>
  <xacro:include filename="macros.xml"/>
  <cell kind="gantry" resolution="0.25"/>
  <object name="bottle"/>
  <planner time="5"/>
  <move focus="${focus}" radius="0.6" theta="60" phi="0"/>
  <scan name="front"/>
  <xacro:ring theta="50" n="3"/>
  <home/>
  <xacro:reconstruct_and_export name="bottle" voxel="0.002" depth="7"/>
  <evaluate/>
</recon>
"""
PIECES = ["<", ">", "/>", "</recon>", '"', "${", "}", "${r*1e300}", "${[0]*99999}", "&amp;", "&lol;",
          "<!DOCTYPE x>",
          "xacro:", "theta=\"nan\"", "count=\"999999\"", "radius=\"-1\"",
          "<xacro:include filename=\"/etc/passwd\"/>",
          "<xacro:ring theta=\"50\" n=\"${n}\"/>", "\x00", "é", "\n", " ", "0", "1e999", "<scan/>",
          "<wait seconds=\"1e9\"/>"]


def _validate(path):
    import shutil

    from recon_cli.paths import SCRIPTS_DIR
    from recon_cli.scripts.checks import check_script

    shutil.copy(SCRIPTS_DIR / "macros.xml", path.parent / "macros.xml")
    from recon_cli.scripts.loader import load_script

    check_script(load_script(path))


@st.composite
def _mutated_script(draw) -> str:
    text = SCRIPT
    for _ in range(draw(st.integers(1, 4))):
        at = draw(st.integers(0, len(text)))
        if draw(st.booleans()):
            text = text[:at] + draw(st.sampled_from(PIECES)) + text[at:]
        else:
            end = min(len(text), at + draw(st.integers(1, 12)))
            text = text[:at] + text[end:]
    return text


def test_the_unmutated_script_is_valid(tmp_path):
    path = tmp_path / "s.xml"
    path.write_text(SCRIPT)
    _validate(path)


@_fuzz
@given(text=_mutated_script())
def test_fuzz_scripts(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("script") / "s.xml"
    path.write_bytes(text.encode("utf-8", "surrogatepass"))
    try:
        _validate(path)
    except ReconError as exc:
        assert "\n" not in exc.one_line()


def _ads_fields() -> list[str]:
    from recon_cli.backends.hardware.ads import AdsConfig

    return [f.name for f in dataclasses.fields(AdsConfig)] + ["bogus"]


_values = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                    st.text(max_size=20), st.lists(st.one_of(st.floats(allow_nan=True), st.integers(-5, 5),
                                                             st.text(max_size=5)), max_size=12),
                    st.dictionaries(st.text(max_size=8), st.text(max_size=8), max_size=3))


@_fuzz
@given(mapping=st.dictionaries(st.sampled_from(_ads_fields()), _values, max_size=6))
def test_fuzz_ads_sections(mapping):
    from recon_cli.backends.hardware.ads import AdsConfig

    try:
        AdsConfig.from_mapping(mapping, "station.yaml: robot.ads")
    except ReconError as exc:
        assert "\n" not in exc.one_line()
