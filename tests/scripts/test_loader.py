"""Loading scripts: every shipped script validates, errors name the line the user wrote,
hostile XML is refused without harm, the thesis dialect is recognized."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from recon_cli.cli import main
from recon_cli.errors import FileError, ScriptError
from recon_cli.paths import SCRIPTS_DIR
from recon_cli.scripts import commands as C
from recon_cli.scripts.checks import check_script
from recon_cli.scripts.loader import load_script

SHIPPED = sorted(SCRIPTS_DIR.glob("*.xml"))
HEAD = '<?xml version="1.0"?>\n'


def _write(tmp_path: Path, text: str, name: str = "s.xml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize("path", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_scripts_validate(path, capsys):
    assert main(["validate", str(path)]) == 0
    assert "valid" in capsys.readouterr().out


def test_eq_4_1_is_24_views_and_scans():
    s = load_script(SCRIPTS_DIR / "eq_4_1_drill.xml")
    moves = [c for c in s.commands if isinstance(c, C.MoveView)]
    assert len(moves) == 24 and sum(isinstance(c, C.Scan) for c in s.commands) == 24
    for i, m in enumerate(moves, start=1):  # eq. 4.1
        assert math.isclose(math.degrees(m.view.phi), 30.0 * ((i - 1) % 12), abs_tol=1e-9)
        assert math.isclose(math.degrees(m.view.theta), 70.0 if i <= 12 else 50.0)
        assert m.view.focus == (0.0, 0.0, 0.78) and m.view.radius == 0.6
    assert str(moves[0].source) == "macros.xml:14"  # made by the eq_4_1 macro


def test_thesis_dialect_is_recognized_and_compiled():
    s = load_script(SCRIPTS_DIR / "thesis_dialect_example.xml")
    assert s.dialect == "thesis"
    kinds = {type(c).__name__ for c in s.commands}
    assert {"MoveView", "FragmentScan", "PairRegister", "Multiway", "AddFragment", "Downsample",
            "ExportFragment", "Display"} <= kinds
    first = next(c for c in s.commands if isinstance(c, C.MoveView))
    assert math.isclose(first.view.theta, 1.0472) and first.view.radius == 0.6  # radians as written


def test_thesis_pose_move_and_transform(tmp_path):
    p = _write(tmp_path, HEAD + """<script name="t">
  <move reference="marker"><position xyz="0.2 0.1 0.6"/><orientation xyzw="1 0 0 0"/></move>
  <transform fragment="a" forward="false"><translation xyz="0 0 0.1"/><rotation xyzw="0 0 0 1"/></transform>
  <wait duration="1.5"/><load name="x" type="point_cloud" path_point_cloud="x.ply"/>
</script>""")
    s = load_script(p)
    move, tf = s.commands[0], s.commands[1]
    assert isinstance(move, C.MovePose) and move.frame == "marker" and move.orientation == (1.0, 0.0, 0.0, 0.0)
    assert tf.matrix[2][3] == pytest.approx(-0.1)  # forward="false": the inverse


@pytest.mark.parametrize("body, where, words", [
    ('<move focus="0 0 0.78" radius="-1" theta="70" phi="0"/>', "s.xml:3", "radius"),
    ('<move focus="0 0" radius="0.6" theta="70" phi="0"/>', "s.xml:3", "focus"),
    ('<fly to="moon"/>', "s.xml:3", "fly"),
    ('<planner name="Teleport"/>', "s.xml:3", "unknown planner"),
    ('<box center="0 0 0.8"/>', "s.xml:3", "both center and size"),
    ('<ring focus="0 0 0.8" radius="0.6" theta="70" count="0"/>', "s.xml:3", "count"),
])
def test_errors_name_the_line(tmp_path, body, where, words):
    p = _write(tmp_path, HEAD + '<recon name="t">\n  ' + body + "\n</recon>\n")
    with pytest.raises(ScriptError) as exc:
        load_script(p)
    assert exc.value.one_line().startswith(where) and words in exc.value.one_line()


def test_error_in_a_macro_body_points_into_the_macro(tmp_path):
    p = _write(tmp_path, HEAD + """<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="view" params="r">
    <move focus="0 0 0.78" radius="${r}" theta="70" phi="0"/>
  </xacro:macro>
  <xacro:view r="0.6"/>
  <xacro:view r="-0.5"/>
</recon>""")
    with pytest.raises(ScriptError, match=r"^s\.xml:4: .*radius"):  # the <move> in the macro
        load_script(p)


def test_error_in_an_included_library_names_that_file(tmp_path):
    _write(tmp_path, HEAD + """<recon name="lib" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="bad">
    <wait seconds="-1"/>
  </xacro:macro>
</recon>""", "lib.xml")
    p = _write(tmp_path, HEAD + """<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:include filename="lib.xml"/>
  <xacro:bad/>
</recon>""")
    with pytest.raises(ScriptError, match=r"^lib\.xml:4: .*seconds"):
        load_script(p)


def test_syntax_error_and_missing_file(tmp_path):
    with pytest.raises(ScriptError, match=r"s\.xml:4:\d+: not well-formed"):
        load_script(_write(tmp_path, HEAD + '<recon name="t">\n  <scan>\n</recon>\n'))
    with pytest.raises(FileError, match="does not exist"):
        load_script(tmp_path / "nope.xml")


def test_setup_after_the_first_move_is_refused(tmp_path):
    p = _write(tmp_path, HEAD + """<recon name="t">
  <move focus="0 0 0.78" radius="0.6" theta="70" phi="0"/>
  <cell kind="ceiling"/>
</recon>""")
    with pytest.raises(ScriptError, match=r"s\.xml:4: <cell> after the first move or scan \(s\.xml:3\)"):
        check_script(load_script(p))


@pytest.mark.parametrize("text, words", [
    # billion laughs
    ('<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
     '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]><recon name="&c;"/>', "DOCTYPE"),
    # external entity (XXE)
    ('<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]><recon name="&x;"/>', "entity"),
    # xacro expression trying to reach Python
    ('<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro">'
     '<scan name="${__import__(\'os\').system(\'touch /tmp/pwned\')}"/></recon>', "not allowed"),
    ('<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro">'
     '<scan name="${open(\'/etc/passwd\').read()}"/></recon>', "xacro"),
    # includes outside the script folder and scripts_xml/
    ('<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:include filename="/etc/passwd"/>'
     '</recon>', "plain relative path"),
    ('<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro">'
     '<xacro:include filename="../../../../etc/hostname"/></recon>', "not found"),
    ('<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro">'
     '<xacro:include filename="$(env HOME)/x.xml"/></recon>', "plain relative path"),
    # unbounded recursion through a macro calling itself
    ('<recon name="t" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:macro name="m"><xacro:m/>'
     '</xacro:macro><xacro:m/></recon>', "xacro"),
    # another root
    ('<robot name="r"/>', "unknown root"),
])
def test_hostile_xml_is_refused(tmp_path, text, words):
    p = _write(tmp_path, HEAD + text)
    with pytest.raises(ScriptError) as exc:
        load_script(p)
    assert words in exc.value.one_line()
    assert "\n" not in exc.value.one_line()
    assert not Path("/tmp/pwned").exists()


def test_validate_cli_error_is_one_line(tmp_path, capsys):
    p = _write(tmp_path, HEAD + '<recon name="t">\n  <wait seconds="soon"/>\n</recon>\n')
    assert main(["validate", str(p)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "s.xml:3" in err and "Traceback" not in err
