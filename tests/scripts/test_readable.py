"""What a script may read: one rule (``recon_cli.expansion.readable.readable``) for every path
attribute, applied by ``recon validate``, by ``recon run`` before anything is written, and
again by the command itself when it runs.

The tree and the file-access recorder are those of test_hardening: ``tmp/outside/`` holds a
secret that no script may read, by ``..``, by an absolute path or through a link.
"""

from __future__ import annotations

import json
import shutil
from types import SimpleNamespace

import pytest
import yaml

from recon_cli.cli import main
from recon_cli.errors import ScriptError
from recon_cli.paths import ROBOT_DIR, SCRIPTS_DIR
from recon_cli.scripts import commands as C
from recon_cli.scripts.handlers import handler_for
from recon_cli.scripts.loader import load_script
from recon_cli.scripts.state import CommandReport
from tests.scripts import test_hardening as H
from tests.scripts.test_hardening import MOVE, V, X, assert_error, recon, run_case

tree = H.tree  # the fixture: scripts/, outside/, out/

RUN = ["run", "{script}", "--out", "{out}"]

# every path attribute a script can carry that names a file to read: (id, script with
# NAME where the path goes, the line of the element)
ATTRIBUTES = [
    ("cell realism", recon('<object name="bottle"/>', '<cell realism="NAME"/>'), 3),
    ("object mesh", recon('<object name="NAME"/>'), 4),
    ("evaluate reference", recon(f'{MOVE}<scan/>\n  <register/>\n  <evaluate reference="NAME"/>'), 6),
    ("thesis load point cloud", '<script name="t">\n  <load name="a" type="point_cloud" path_point_cloud="NAME"/>'
     '\n</script>\n', 3),
    ("thesis load colour", '<script name="t">\n  <load name="a" path_color="NAME" path_depth="d.png"/>\n</script>\n',
     3),
    ("thesis load depth", '<script name="t">\n  <load name="a" path_color="c.png" path_depth="NAME"/>\n</script>\n',
     3),
    ("xacro:include", recon('<xacro:include filename="NAME"/>'), 4),
    ("xacro.load_yaml", recon('<scan name="${xacro.load_yaml(\'NAME\')}"/>'), 4),
]
# ways out: (id, the path as written, words of the refusal)
HOSTILE = [
    ("dotdot", "../outside/secret.yaml", "leads outside the script's folder and scripts_xml/"),
    ("absolute", "@OUTSIDE@/secret.yaml", "outside the script's folder and scripts_xml/"),
    ("link", "link.yaml", "is a link that leads outside the script's folder"),
    ("linked folder", "linkdir/secret.yaml", "is a link that leads outside the script's folder"),
    ("dotdot after a link", "deep/../secret.yaml", "is a link that leads outside the script's folder"),
]


def _prepare(tree) -> None:
    """Beside the script: harmless files the other attributes name, links out of the folder."""
    s = tree["scripts"]
    (s / "c.png").write_bytes(b"png")
    (s / "d.png").write_bytes(b"png")
    (s / "link.yaml").symlink_to(tree["outside"] / "secret.yaml")
    (s / "linkdir").symlink_to(tree["outside"], target_is_directory=True)
    # deep/../secret.yaml is scripts/secret.yaml as written, outside/deeper/secret.yaml resolved
    (tree["outside"] / "deeper" / "sub").mkdir(parents=True)
    shutil.copy(tree["outside"] / "secret.yaml", tree["outside"] / "deeper" / "secret.yaml")
    (s / "deep").symlink_to(tree["outside"] / "deeper" / "sub", target_is_directory=True)


@pytest.mark.parametrize("text, line", [a[1:] for a in ATTRIBUTES], ids=[a[0] for a in ATTRIBUTES])
@pytest.mark.parametrize("name, words", [h[1:] for h in HOSTILE], ids=[h[0] for h in HOSTILE])
@pytest.mark.parametrize("args", [V, RUN], ids=["validate", "run"])
def test_hostile_path_is_refused(tree, capsys, text, line, name, words, args):
    _prepare(tree)
    code, out, err = run_case(tree, capsys, text.replace("NAME", name), args)
    assert_error(code, err, 1, f"s.xml:{line}:", words)
    assert not tree["out"].exists()  # refused before the output folder is made


def _handler_state(script: C.Script):
    return SimpleNamespace(script=script, options=SimpleNamespace(realism=None, object_name=None),
                           skipped_in_dry_run=lambda report: False, reconstruction={"cloud": "cloud.ply"})


@pytest.mark.parametrize("text, line", [a[1:] for a in ATTRIBUTES[:6]], ids=[a[0] for a in ATTRIBUTES[:6]])
@pytest.mark.parametrize("name", [h[1] for h in HOSTILE[:4]], ids=[h[0] for h in HOSTILE[:4]])
def test_the_command_refuses_again_when_it_runs(tree, text, line, name):
    """The static check is not the only guard: each command that reads a file applies the
    same rule when it runs (here without the check before it)."""
    _prepare(tree)
    path = tree["scripts"] / "s.xml"
    path.write_text(H.HEAD + text.replace("NAME", name.replace("@OUTSIDE@", str(tree["outside"]))))
    script = load_script(path)
    cmd = next(c for c in script.commands if isinstance(c, (C.SetCell, C.SetObject, C.Evaluate, C.LoadFragment))
               and str(c.source) == f"s.xml:{line}")
    H._RECORD = []
    try:
        with pytest.raises(ScriptError) as exc:
            handler_for(cmd)(_handler_state(script), cmd, CommandReport(str(cmd.source), cmd.describe()))
    finally:
        records, H._RECORD = H._RECORD, None
    H._check_access(records, tree)
    assert exc.value.one_line().startswith(f"s.xml:{line}: ")
    assert "outside the script's folder" in exc.value.one_line()
    assert exc.value.source == f"s.xml:{line}"


def _profile(tree, name: str = "p.yaml"):
    target = tree["scripts"] / name
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(ROBOT_DIR / "realism" / "thesis.yaml", target)
    return target


@pytest.mark.parametrize("name", ["p.yaml", "profiles/p.yaml", "alias.yaml"])
def test_realism_profile_beside_the_script_validates(tree, capsys, name):
    _profile(tree)
    _profile(tree, "profiles/p.yaml")
    (tree["scripts"] / "alias.yaml").symlink_to(tree["scripts"] / "p.yaml")  # a link that stays inside
    code, out, err = run_case(tree, capsys, recon('<object name="bottle"/>', f'<cell realism="{name}"/>'), V)
    assert code == 0, err
    assert f"realism {name}" in out


def test_realism_profile_beside_the_script_is_used(tree, capsys):
    """The run reads the profile beside the script (not from the working directory) and
    records it in config.yaml and session.json."""
    profile = _profile(tree)
    text = recon(f'<object name="bottle"/>\n  {MOVE}', '<cell realism="p.yaml" resolution="0.1"/>')
    (tree["scripts"] / "s.xml").write_text(H.HEAD + text)
    assert main(["run", str(tree["scripts"] / "s.xml"), "--out", str(tree["out"])]) == 0, capsys.readouterr().err
    config = yaml.safe_load((tree["out"] / "config.yaml").read_text())
    assert config["realism"]["source"] == str(profile) and config["realism"]["name"] == "thesis"
    session = json.loads((tree["out"] / "scans" / "session.json").read_text())
    assert session["realism"]["source"] == str(profile) and not session["realism"]["ideal"]


@pytest.mark.parametrize("realism, words", [
    ("thesiss", ["s.xml:3", "unknown realism profile 'thesiss'", "ideal, thesis"]),
    ("missing.yaml", ["s.xml:3", "realism profile 'missing.yaml' does not exist beside the script"]),
    ("bad.yaml", ["s.xml:3", "bad.yaml"]),
    ("loop.yaml", ["s.xml:3", "'loop.yaml' is not a regular file"]),
    ("profiles/", ["s.xml:3", "'profiles/' is not a regular file"]),
])
def test_realism_mistakes_are_found_by_validate(tree, capsys, realism, words):
    (tree["scripts"] / "bad.yaml").write_text("format: 1\nkinematics: 5\n")
    (tree["scripts"] / "loop.yaml").symlink_to(tree["scripts"] / "loop.yaml")
    (tree["scripts"] / "profiles").mkdir()
    for args in (V, RUN):
        code, _, err = run_case(tree, capsys, recon('<object name="bottle"/>', f'<cell realism="{realism}"/>'), args)
        assert_error(code, err, 1, *words)


def test_include_from_a_subfolder_may_reach_the_script_folder(tree, capsys):
    """Relative names are looked up beside the file that names them; what counts is that
    the file is inside the script's folder (or scripts_xml/)."""
    (tree["scripts"] / "lib").mkdir()
    (tree["scripts"] / "lib" / "a.xml").write_text(
        f'<recon name="a" {X}>\n  <xacro:include filename="../b.xml"/>\n</recon>\n')
    (tree["scripts"] / "b.xml").write_text(
        f'<recon name="b" {X}>\n  <xacro:macro name="look">{MOVE}</xacro:macro>\n</recon>\n')
    text = recon('<xacro:include filename="lib/a.xml"/>\n  <xacro:look/>')
    code, out, err = run_case(tree, capsys, text, V)
    assert code == 0, err
    assert "b.xml:2" in out


@pytest.mark.parametrize("name", sorted(p.name for p in SCRIPTS_DIR.glob("*.xml")))
def test_shipped_scripts_validate(capsys, name):
    assert main(["validate", f"scripts_xml/{name}"]) == 0, capsys.readouterr().err
