"""Hostile and mistaken scripts and options, as a new user and an attacker would write them.

Every case runs the CLI in-process in its own temporary tree::

    tmp/scripts/   the script (and what it may read: ok.yaml, part.stl)
    tmp/outside/   a secret and a victim file that no script may read or write
    tmp/out/       the output folder (for ``recon run``)

and asserts: the documented exit code; for errors exactly one line on stderr that names
file:line (or the option) and what is wrong; no traceback; no Python-level file access
outside the allowed places (an audit hook records every open, rename, copy and mkdir);
the secret never appears in the output and the victim file is unchanged.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import pytest

from recon_cli.cli import main
from recon_cli.paths import ROOT

SECRET = "SENTINEL-7c1e0b"
HEAD = '<?xml version="1.0"?>\n'
X = 'xmlns:xacro="http://www.ros.org/wiki/xacro"'

# ------------------------------------------------------------------ file-access recorder
_RECORD: list[tuple[str, str, bool]] | None = None
_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC


def _audit(event: str, args) -> None:
    if _RECORD is None:
        return
    if event == "open":
        path, mode, flags = args
        if isinstance(path, int) or path is None:
            return
        write = bool(mode and any(c in str(mode) for c in "wax+")) or bool(flags and flags & _WRITE_FLAGS)
        _RECORD.append((event, os.fsdecode(path), write))
    elif event in ("os.rename", "os.replace", "shutil.copyfile", "os.symlink", "os.link"):
        _RECORD.append((event, os.fsdecode(args[1]), True))
    elif event in ("os.mkdir", "os.remove", "os.rmdir", "shutil.rmtree", "os.truncate", "os.chmod"):
        dir_fd = args[-1] if event in ("os.mkdir", "os.remove", "os.rmdir", "os.chmod") else None
        if not isinstance(args[0], int) and dir_fd is None:  # names relative to a dir_fd: inside a
            # tree that shutil.rmtree walks, whose root is recorded itself
            _RECORD.append((event, os.fsdecode(args[0]), True))


sys.addaudithook(_audit)


def _under(path: Path, roots) -> bool:
    return any(path == r or path.is_relative_to(r) for r in roots)


def _check_access(records, tree: dict[str, Path]) -> None:
    tmp = Path(tempfile.gettempdir()).resolve()
    python = {Path(p).resolve() for p in (sys.prefix, sys.base_prefix, *sys.path) if p and Path(p).is_dir()}
    python = {p for p in python if not _under(p, [tmp])}
    read_ok = [*python, ROOT.resolve(), tree["scripts"], tree["out"], Path("/dev"), Path("/proc"), Path("/sys"),
               Path("/usr"), Path("/etc/ld.so.cache")]
    write_ok = [tree["out"]]
    for event, raw, write in records:
        p = Path(raw) if Path(raw).is_absolute() else Path.cwd() / raw
        p = Path(os.path.normpath(p))
        real = p.resolve() if p.exists() else p
        assert not _under(real, [tree["outside"]]) and not _under(p, [tree["outside"]]), (event, raw)
        # recon's scratch copies of a script, and the probe files of tempfile.gettempdir()
        scratch = real.parent == tmp or (_under(real, [tmp]) and real.relative_to(tmp).parts[0].startswith("recon-"))
        if write:
            assert scratch or _under(real, write_ok), f"wrote {raw} ({event})"
        else:
            assert scratch or _under(real, read_ok), f"read {raw} ({event})"


@pytest.fixture
def tree(tmp_path):
    t = {name: (tmp_path / name) for name in ("scripts", "outside", "out")}
    t["scripts"].mkdir()
    t["outside"].mkdir()
    (t["outside"] / "secret.yaml").write_text(f"secret: {SECRET}\n")
    (t["outside"] / "secret.txt").write_text(SECRET + "\n")
    (t["outside"] / "victim.ply").write_text("VICTIM\n")
    (t["scripts"] / "ok.yaml").write_text("radius: 0.6\ntheta: 40\n")
    return {k: v.resolve() for k, v in t.items()}


def run_case(tree, capsys, text: str | None, args: list[str], name: str = "s.xml"):
    """Write the script, run ``recon ARGS`` (``{script}``, ``{out}``, ``{outside}`` filled
    in) with file access recorded; returns (exit code, stdout, stderr)."""
    global _RECORD
    script = tree["scripts"] / name
    fill = {"script": str(script), "out": str(tree["out"]), "outside": str(tree["outside"])}
    if text is not None:
        script.write_text(HEAD + text.replace("@OUTSIDE@", str(tree["outside"])))
    capsys.readouterr()
    _RECORD = []
    try:
        code = main([a.format(**fill) for a in args])
    finally:
        records, _RECORD = _RECORD, None
    out, err = capsys.readouterr()
    _check_access(records, tree)
    assert "Traceback" not in out + err
    assert SECRET not in out + err
    assert (tree["outside"] / "victim.ply").read_text() == "VICTIM\n"
    if tree["out"].exists():
        for p in tree["out"].rglob("*"):
            if p.is_file() and not p.is_symlink() and p.stat().st_size < 5_000_000:
                assert SECRET.encode() not in p.read_bytes(), p
    return code, out, err


def assert_error(code, err, expected_code: int, *words: str) -> None:
    lines = err.strip().splitlines()
    assert code == expected_code, err
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], (w, lines[0])


def recon(body: str, cell: str = '<cell/>') -> str:
    return f'<recon name="t" {X}>\n  {cell}\n  {body}\n</recon>\n'


V = ["validate", "{script}"]
MOVE = '<move focus="0 0 0.8" radius="0.6" theta="40" phi="0"/>'

# (id, script, args, exit code, words every error line must hold)
CASES = [
    # --- xacro may not read files or the environment
    ("load_yaml absolute", recon('<scan name="${xacro.load_yaml(\'@OUTSIDE@/secret.yaml\')}"/>'), V, 1,
     ["s.xml:4", "xacro.load_yaml", "relative path"]),
    ("load_yaml escaping", recon('<scan name="${xacro.load_yaml(\'../outside/secret.yaml\')}"/>'), V, 1,
     ["s.xml:4", "xacro.load_yaml"]),
    ("load_yaml deprecated name", recon('<scan name="${load_yaml(\'@OUTSIDE@/secret.yaml\')}"/>'), V, 1,
     ["s.xml:4", "load_yaml"]),
    ("env", recon('<scan name="$(env HOME)"/>'), V, 1, ["s.xml:4", "$(env", "environment"]),
    ("optenv", recon('<scan name="$(optenv PATH)"/>'), V, 1, ["s.xml:4", "$(optenv", "environment"]),
    ("optenv default", recon('<scan name="$(optenv NO_SUCH_VAR fallback)"/>'), V, 1, ["s.xml:4", "$(optenv"]),
    ("find", recon('<scan name="$(find xacro)"/>'), V, 1, ["s.xml:4", "$(find"]),
    ("cwd", recon('<scan name="$(cwd)"/>'), V, 1, ["s.xml:4", "$(cwd)"]),
    ("dirname", recon('<scan name="$(dirname)"/>'), V, 1, ["s.xml:4", "$(dirname)"]),
    ("eval import", recon('<scan name="$(eval __import__)"/>'), V, 1, ["s.xml:4", "not allowed"]),
    ("import", recon('<scan name="${__import__(\'os\').system(\'true\')}"/>'), V, 1, ["s.xml:4", "'__import__'"]),
    ("dunder attribute", recon('<scan name="${(1).__class__}"/>'), V, 1, ["s.xml:4", "'__class__'"]),
    ("str.format", recon('<scan name="${\'x\'.format(1)}"/>'), V, 1, ["s.xml:4", "attribute access .format"]),
    ("abs_filename", recon('<scan name="${xacro.abs_filename(\'x\')}"/>'), V, 1, ["s.xml:4", "abs_filename"]),
    ("python.type", recon('<scan name="${python.type(1)}"/>'), V, 1, ["s.xml:4", "type()"]),
    ("map", recon('<scan name="${list(map(str, [1]))}"/>'), V, 1, ["s.xml:4", "map()"]),
    ("lambda", recon('<scan name="${(lambda: 1)()}"/>'), V, 1, ["s.xml:4", "lambda"]),
    ("comprehension", recon('<scan name="${[x for x in range(3)]}"/>'), V, 1, ["s.xml:4", "comprehensions"]),
    ("message", recon('<scan name="${xacro.message(\'hi\')}"/>'), V, 1, ["s.xml:4", "message"]),
    # --- bounded work
    ("power bomb", recon('<scan name="${9**9**9}"/>'), V, 1, ["s.xml:4", "2**63"]),
    ("shift bomb", recon('<scan name="${1 &lt;&lt; 100000}"/>'), V, 1, ["s.xml:4", "2**63"]),
    ("string bomb", recon('<scan name="${\'a\' * 10**9}"/>'), V, 1, ["s.xml:4", "100000"]),
    ("range bomb", recon('<scan name="${sum(range(10**12))}"/>'), V, 1, ["s.xml:4", "range", "100000"]),
    ("round bomb", recon('<scan name="${round(5, -10**9)}"/>'), V, 1, ["s.xml:4", "round()"]),
    ("percent format", recon('<scan name="${\'%s\' % 1}"/>'), V, 1, ["s.xml:4", "%-formatting"]),
    ("property doubling", recon('<xacro:property name="p0" value="' + "x" * 100 + '"/>\n  '
                                + "\n  ".join(f'<xacro:property name="p{k}" value="${{p{k - 1}}}${{p{k - 1}}}"/>'
                                              for k in range(1, 15)) + '\n  <scan name="${p14}"/>'), V, 1,
     ["s.xml:19", "limit"]),
    ("macro recursion", recon('<xacro:macro name="m">\n    <xacro:m/>\n  </xacro:macro>\n  <xacro:m/>'), V, 1,
     ["s.xml:5", "nest deeper than the limit of 100", "called at s.xml:7"]),
    ("macro bomb", recon("\n  ".join(
        f'<xacro:macro name="m{k}">' + f"<xacro:m{k - 1}/>" * 10 + "</xacro:macro>" for k in range(1, 6))
        .replace("<xacro:m0/>", "<scan/>") + "\n  <xacro:m5/>"), V, 1, ["10000 elements", "called at s.xml:9"]),
    ("ring count", recon('<ring focus="0 0 0.8" radius="0.6" theta="60" count="100000000"/>'), V, 1,
     ["s.xml:4", "count", "3600"]),
    ("include absolute", recon('<xacro:include filename="@OUTSIDE@/secret.txt"/>'), V, 1,
     ["s.xml:4", "plain relative path"]),
    ("include escaping", recon('<xacro:include filename="../outside/secret.txt"/>'), V, 1,
     ["s.xml:4", "not found"]),
    ("include substitution", recon('<xacro:include filename="$(env HOME)/x.xml"/>'), V, 1,
     ["s.xml:4", "plain relative path"]),
    ("external entity", '<!DOCTYPE r [<!ENTITY x SYSTEM "file://@OUTSIDE@/secret.txt">]><recon name="&x;"/>', V, 1,
     ["s.xml:2", "external entity"]),
    ("macro error names the call", recon('<xacro:macro name="m" params="a">\n    <scan name="${a + 1}"/>\n'
                                         '  </xacro:macro>\n  <xacro:m a="x"/>'), V, 1,
     ["s.xml:5", "called at s.xml:7", "a + 1"]),
    ("unknown macro", recon('<xacro:nosuch/>'), V, 1, ["s.xml:4", "unknown macro"]),
    # --- values that cannot be right
    ("radius 1e308", recon('<move focus="0 0 0.8" radius="1e308" theta="40" phi="0"/>'), V, 1,
     ["s.xml:4", "radius", "1e308"]),
    ("infinite coordinate", recon('<move focus="0 0 INF" radius="0.6" theta="40" phi="0"/>'), V, 1, ["s.xml:4"]),
    ("NaN radius", recon('<move focus="0 0 0.8" radius="NaN" theta="40" phi="0"/>'), V, 1, ["s.xml:4", "radius"]),
    ("degrees in radians", recon('<move focus="0 0 0.8" radius="0.6" theta="60" phi="0" unit="rad"/>'), V, 1,
     ["s.xml:4", "theta 60 rad", "1.0472"]),
    ("thesis theta in degrees", '<script name="t">\n  <move reference="world"><sphere xyz="0 0 0.8" radius="0.6"/>'
     '<coordinates phi="0" theta="60"/></move>\n  <scan name="a"/>\n</script>\n', V, 1,
     ["s.xml:3", "theta 60 rad", "radians"]),
    ("joints count", recon('<joints values="0 0 0 0 0 0 0 0 0"/>', '<cell kind="ceiling"/>'), V, 1,
     ["s.xml:4", "9 values", "7 joints"]),
    ("joints outside soft limits", recon('<joints values="0 0 0 0 0 175 0 0 0" unit="deg"/>'), V, 1,
     ["s.xml:4", "arm_joint_4", "soft limits"]),
    ("duplicate scan names", recon(f'{MOVE}\n  <scan name="front"/>\n  {MOVE}\n  <scan name="front"/>'), V, 1,
     ["s.xml:7", "'front'", "s.xml:5"]),
    ("register before scan", recon("<register/>"), V, 1, ["s.xml:4", "<register> before any scan"]),
    ("export mesh before reconstruct", recon(f'{MOVE}<scan/>\n  <register/>\n  <export mesh="m.ply"/>'), V, 1,
     ["s.xml:6", "<reconstruct/>"]),
    ("evaluate before register", recon(f'{MOVE}<scan/>\n  <evaluate/>'), V, 1, ["s.xml:5", "<evaluate>"]),
    ("wait of years", recon('<wait seconds="1e9"/>'), V, 1, ["s.xml:4", "seconds"]),
    ("setup after move", recon(f'{MOVE}\n  <object name="bottle"/>'), V, 1, ["s.xml:5", "after the first move"]),
    ("unknown fragment", '<script name="t">\n  <downsample fragment="ghost" voxel_size="0.001"/>\n</script>\n', V, 1,
     ["s.xml:3", "'ghost'"]),
    ("multiway of one", '<script name="t">\n  <move reference="world"><sphere xyz="0 0 0.8" radius="0.6"/>'
     '<coordinates phi="0" theta="1"/></move>\n  <scan name="a"/>\n  <multiway threshold="0.01"/>\n</script>\n',
     V, 1, ["s.xml:5", "two fragments"]),
    # --- what a script reads and writes
    ("object outside", recon('<object name="@OUTSIDE@/victim.ply"/>'), V, 1, ["s.xml:4", "outside the script's"]),
    ("object escaping", recon('<object name="../outside/victim.ply"/>'), V, 1, ["s.xml:4", "outside the script's"]),
    ("unknown object", recon('<object name="teapot"/>'), V, 1, ["s.xml:4", "unknown object 'teapot'"]),
    ("reference outside", recon(f'{MOVE}<scan/>\n  <register/>\n  <evaluate reference="@OUTSIDE@/victim.ply"/>'),
     V, 1, ["s.xml:6", "outside the script's"]),
    ("thesis load outside", '<script name="t">\n  <load name="a" type="point_cloud" '
     'path_point_cloud="@OUTSIDE@/victim.ply"/>\n</script>\n', V, 1, ["s.xml:3", "outside the script's"]),
    ("export absolute", recon(f'{MOVE}<scan/>\n  <register/>\n  <export cloud="@OUTSIDE@/victim.ply"/>'), V, 1,
     ["s.xml:6", "outside the output folder"]),
    ("export escaping", recon(f'{MOVE}<scan/>\n  <register/>\n  <export cloud="../outside/victim.ply"/>'), V, 1,
     ["s.xml:6", "outside the output folder"]),
    ("thesis export escaping", '<script name="t">\n  <export fragment="a" path="../../x.ply"/>\n</script>\n', V, 1,
     ["s.xml:3", "outside the output folder"]),
    # --- command line
    ("negative seed", recon(MOVE), ["run", "{script}", "--seed", "-5", "--out", "{out}"], 2, ["--seed"]),
    ("seed too large", recon(MOVE), ["run", "{script}", "--seed", str(2**40), "--out", "{out}"], 2, ["--seed"]),
    ("missing script", None, ["validate", "@OUTSIDE@/../scripts/nope.xml"], 1, ["nope.xml", "does not exist"]),
    ("unknown backend", recon(MOVE), ["run", "{script}", "--backend", "robotz", "--out", "{out}"], 2,
     ["--backend", "'robotz' is not one of 'sim', 'hardware'"]),
]


@pytest.mark.parametrize("text, args, code, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_refused(tree, capsys, text, args, code, words):
    got, _, err = run_case(tree, capsys, text, args)
    assert_error(got, err, code, *words)


def test_corpus_size():
    assert len(CASES) + 8 >= 40  # the parametrized cases and the tests below


def test_allowed_yaml_beside_the_script(tree, capsys):
    text = recon('<xacro:property name="v" value="${xacro.load_yaml(\'ok.yaml\')}"/>\n'
                 '  <move focus="0 0 0.8" radius="${v.radius}" theta="${v[\'theta\']}" phi="0"/>')
    code, out, err = run_case(tree, capsys, text, V)
    assert code == 0, err
    assert "r = 0.6 m, theta 40.0°" in out


def test_script_text_is_printed_literally(tree, capsys):
    text = ('<recon name="[/oops] :x: [bold]b[/bold]">\n  <cell/>\n  <object name="bottle"/>\n  ' + MOVE
            + '\n  <scan name="[red]x[/red] :smile:"/>\n</recon>\n')
    code, out, err = run_case(tree, capsys, text, V)
    assert code == 0, err
    assert "'[/oops] :x: [bold]b[/bold]'" in out and "scan [red]x[/red] :smile:" in out


def test_oversized_script(tree, capsys):
    text = recon("<!--" + "x" * 5_100_000 + "-->")
    code, _, err = run_case(tree, capsys, text, V)
    assert_error(code, err, 1, "s.xml", "too large", "5 MB")


def test_run_refuses_a_non_empty_out(tree, capsys):
    tree["out"].mkdir()
    (tree["out"] / "x.ply").symlink_to(tree["outside"] / "victim.ply")
    text = recon(f'<object name="bottle"/>\n  {MOVE}<scan/>\n  <register/>\n  <export cloud="x.ply"/>')
    code, _, err = run_case(tree, capsys, text, ["run", "{script}", "--out", "{out}"])
    assert_error(code, err, 1, "not empty", "--append")


def test_append_refuses_links_in_out(tree, capsys):
    tree["out"].mkdir()
    (tree["out"] / "x.ply").symlink_to(tree["outside"] / "victim.ply")
    text = recon(f'<object name="bottle"/>\n  {MOVE}<scan/>\n  <register/>\n  <export cloud="x.ply"/>')
    code, _, err = run_case(tree, capsys, text, ["run", "{script}", "--out", "{out}", "--append", "--dry-run"])
    assert_error(code, err, 1, "holds a link", "x.ply")


def test_out_that_is_a_file(tree, capsys):
    tree["out"].write_text("")
    code, _, err = run_case(tree, capsys, recon(MOVE), ["run", "{script}", "--out", "{out}"])
    assert_error(code, err, 1, "is a file")


def test_export_through_a_link_made_during_the_run_is_refused(tree, tmp_path):
    """The write check itself (also for links that appear after the start)."""
    from recon_cli.errors import FileError
    from recon_cli.outputs import inside

    tree["out"].mkdir()
    (tree["out"] / "x.ply").symlink_to(tree["outside"] / "victim.ply")
    (tree["out"] / "sub").symlink_to(tree["outside"])
    for name in ("x.ply", "sub/y.ply", "../outside/victim.ply", str(tree["outside"] / "victim.ply")):
        with pytest.raises(FileError):
            inside(tree["out"], name)
    assert inside(tree["out"], "new/z.ply") == tree["out"] / "new" / "z.ply"


def test_expansion_time_limit(tree, capsys, monkeypatch):
    from recon_cli.expansion import sandbox

    monkeypatch.setattr(sandbox, "LIMITS", sandbox.Limits(max_seconds=0.0))
    code, _, err = run_case(tree, capsys, recon(MOVE), V)
    assert_error(code, err, 1, "longer than the limit of 0 s")


def test_errors_carry_their_data(tree):
    from recon_cli.errors import JointLimitError, LimitError
    from recon_cli.scripts.checks import check_script
    from recon_cli.scripts.loader import load_script

    p = tree["scripts"] / "j.xml"
    p.write_text(HEAD + recon('<joints values="0 0 0 0 0 175 0 0 0" unit="deg"/>'))
    with pytest.raises(JointLimitError) as exc:
        check_script(load_script(p))
    e = exc.value
    assert (e.joint, e.value, e.unit, e.source) == ("arm_joint_4", 175.0, "deg", "j.xml:4")
    assert e.lower == pytest.approx(-110.0) and e.upper == pytest.approx(110.0)
    p.write_text(HEAD + recon('<scan name="${9**9**9}"/>'))
    with pytest.raises(LimitError) as exc:
        load_script(p)
    assert exc.value.limit == "max_int_bits" and exc.value.bound == 63
